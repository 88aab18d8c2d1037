"""Place-and-route (ikseries.pnr, ikseries.pnr_report, `ikseries report --pnr`) on tiny designs.

Every real run synthesises with YoWASP Yosys and places with YoWASP nextpnr: a few seconds each
once the tools are cached; the runs share module-scoped fixtures and two threads.
"""
from __future__ import annotations

import json
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor

import pytest
from amaranth import Elaboratable, Module, Signal
from amaranth.back import verilog as amaranth_verilog

from helpers import tiny_plan
from ikseries.cli import main
from ikseries.constraints.devices import PNR_DEVICES
from ikseries.hdl.export import leg_verilog
from ikseries.hdl.leg import LegCore
from ikseries.pnr import (HARNESS_TOP, DoesNotFitError, Port, _log_overflow, harness_verilog,
                          place_and_route, verilog_ports)
from ikseries.pnr_report import SECTION_TITLE, insert_section, render_markdown

ICE40, ECP5 = "ice40-up5k-sg48", "ecp5-25f-cabga381"
CLOCK = 48_000_000


class _WideAdder(Elaboratable):
    """A registered 24-bit adder: 24 + 24 + 25 data bits + clk + rst = 75 port bits, more than the
    sg48 package's 39 user I/O pins and fewer than the CABGA381's 197."""

    def __init__(self):
        self.a, self.b, self.y = Signal(24, name="a"), Signal(24, name="b"), Signal(25, name="y")

    def elaborate(self, platform):
        m = Module()
        ra, rb = Signal(24), Signal(24)
        m.d.sync += [ra.eq(self.a), rb.eq(self.b), self.y.eq(ra + rb)]
        return m


@pytest.fixture(scope="module")
def tiny_core():
    """LegCore of a degree-2 tiny plan: 5 multipliers (fits the UP5K's 8 DSPs), 23 port bits."""
    core = LegCore(tiny_plan(3, clamp=(0, 100), degree=2), 1000)
    return leg_verilog(core, "tiny_core"), core


@pytest.fixture(scope="module")
def wide_verilog():
    w = _WideAdder()
    return amaranth_verilog.convert(w, name="wide", ports=[w.a, w.b, w.y], emit_src=False)


@pytest.fixture(scope="module")
def runs(tiny_core, wide_verilog, tmp_path_factory):
    """(design, device) -> PnrResult, every device's harness chosen automatically."""
    wd = tmp_path_factory.mktemp("pnr")
    jobs = [("tiny", tiny_core[0], "tiny_core", d) for d in (ICE40, ECP5)] \
        + [("wide", wide_verilog, "wide", d) for d in (ICE40, ECP5)]
    with ThreadPoolExecutor(2) as ex:
        res = list(ex.map(lambda j: place_and_route(j[1], j[2], j[3], CLOCK, wd / f"{j[0]}-{j[3]}"), jobs))
    return {(j[0], j[3]): r for j, r in zip(jobs, res)}


# -- real runs --------------------------------------------------------------------------------------

@pytest.mark.parametrize("device", [ICE40, ECP5])
def test_tiny_core_fmax_and_counts(runs, device):
    r = runs["tiny", device]
    assert r.device == device and r.top == "tiny_core" and r.fits and not r.harness
    assert r.port_bits == 23 and r.harness_ffs == 0
    assert 20 < r.fmax_mhz < 500 and r.meets_clock == (r.fmax_mhz >= 48)
    u = r.utilisation
    assert u["DSP"]["used"] == 5                                  # one DSP per multiplier
    assert u["IO"] == {"used": 23, "available": PNR_DEVICES[device].user_io}
    assert u["BRAM"]["used"] == 0
    assert 100 < u["FF"]["used"] < 400                            # the pipeline registers
    assert u["LC"]["used"] >= u["LUT"]["used"] > 0 and u["carry"]["used"] > 0
    assert u["LC"]["used"] < u["LC"]["available"]
    cp = r.critical_path
    assert cp["delay_ns"] == pytest.approx(cp["logic_ns"] + cp["routing_ns"], abs=2e-3)
    assert 1e3 / cp["delay_ns"] == pytest.approx(r.fmax_mhz, rel=0.05)
    assert r.seconds["yosys"] > 0 and r.seconds["nextpnr"] > 0
    json.dumps(r.to_json())


def test_harness_chosen_by_port_bits(runs):
    on_ice, on_ecp = runs["wide", ICE40], runs["wide", ECP5]
    assert on_ice.port_bits == on_ecp.port_bits == 75
    assert on_ice.harness and not on_ecp.harness           # 75 > 39 pins, 75 <= 197 pins
    assert on_ice.utilisation["IO"]["used"] == 5            # clk rst din load dout
    assert on_ecp.utilisation["IO"]["used"] == 75
    assert on_ice.harness_ffs == 48 + 25
    # nothing of the core was optimised away: its registers are all there, plus the harness'
    assert on_ice.utilisation["FF"]["used"] >= 48 + 25 + on_ice.harness_ffs
    assert on_ice.utilisation["carry"]["used"] >= 24 and on_ice.fmax_mhz > 0


def test_deterministic(wide_verilog, runs, tmp_path):
    again = place_and_route(wide_verilog, "wide", ECP5, CLOCK, tmp_path)
    first = runs["wide", ECP5]
    assert again.fmax_mhz == first.fmax_mhz and again.utilisation == first.utilisation
    assert again.critical_path == first.critical_path


def test_too_many_dsps_fails_cleanly(tmp_path):
    core = LegCore(tiny_plan(3, clamp=(0, 100)), 1000)      # degree 4: 10 multipliers
    with pytest.raises(DoesNotFitError) as e:
        place_and_route(leg_verilog(core, "tiny4"), "tiny4", ICE40, CLOCK, tmp_path)
    assert str(e.value) == ("design 'tiny4' does not fit ice40-up5k-sg48: DSP 10 used of 8 available "
                            "(2 over) (Yosys cell counts vs device capacity)")
    assert e.value.overflow == {"DSP": (10, 8)}


def test_too_many_pins_without_harness(wide_verilog, tmp_path):
    with pytest.raises(DoesNotFitError, match=r"^design 'wide' does not fit ice40-up5k-sg48: IO 75 used of "
                       r"39 available \(36 over\) \(port bits vs package pins; use harness=True"):
        place_and_route(wide_verilog, "wide", ICE40, CLOCK, tmp_path, harness=False)
    assert not any(tmp_path.iterdir())                      # failed before writing anything


def test_nextpnr_utilisation_overflow_is_parsed():
    log = ("Info: Device utilisation:\nInfo: \t         ICESTORM_LC:     483/   5280     9%\n"
           "Info: \t               SB_IO:      23/     39    58%\n"
           "Info: \t        ICESTORM_DSP:      10/      8   125%\n"
           "ERROR: Unable to place cell 'x', no BELs remaining to implement cell type 'ICESTORM_DSP'\n")
    assert _log_overflow(log, PNR_DEVICES[ICE40]) == {"DSP": (10, 8)}
    assert _log_overflow("ERROR: something else\n", PNR_DEVICES[ICE40]) == {}


# -- parameters ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, message", [
    ({"device": "ice40-hx8k"}, "device must be one of ['ice40-up5k-sg48', 'ecp5-25f-cabga381'], not 'ice40-hx8k'"),
    ({"clock_hz": 0}, "clock_hz must be a positive integer (Hz), not 0"),
    ({"clock_hz": 48e6}, "clock_hz must be a positive integer (Hz), not 48000000.0"),
    ({"harness": "yes"}, "harness must be True, False or None (automatic), not 'yes'"),
    ({"seed": -1}, "seed must be an integer in [0, 2**31), not -1"),
    ({"top": "no such"}, "top must be a plain Verilog identifier, not 'no such'"),
    ({"top": "nope"}, "top must be a module of the Verilog ['wide'], not 'nope'"),
    ({"clock": "clock"}, "clock must be a port of module 'wide' ['b', 'clk', 'rst', 'y', 'a'], not 'clock'"),
])
def test_bad_parameters(wide_verilog, tmp_path, kwargs, message):
    args = {"verilog": wide_verilog, "top": "wide", "device": ICE40, "clock_hz": CLOCK, "workdir": tmp_path}
    args.update(kwargs)
    with pytest.raises(ValueError) as e:
        place_and_route(**args)
    assert str(e.value) == message
    assert not any(tmp_path.iterdir())


# -- ports and the harness ----------------------------------------------------------------------------

def test_verilog_ports_ansi_and_plain():
    v = ("// c\nmodule other(input x, output y); endmodule\n"
         "module top (\n  input wire clk, input [7:0] a, b,\n  output reg signed [3:0] y, // comment\n"
         "  output z\n);\nendmodule\n"
         "module plain(clk, d, q);\n  (* keep *) input clk;\n  input [2:5] d;\n  output q;\nendmodule\n")
    assert verilog_ports(v, "top") == [Port("clk", "input", 1), Port("a", "input", 8), Port("b", "input", 8),
                                       Port("y", "output", 4), Port("z", "output", 1)]
    assert verilog_ports(v, "plain") == [Port("clk", "input", 1), Port("d", "input", 4), Port("q", "output", 1)]


@pytest.mark.skipif(shutil.which("iverilog") is None, reason="needs Icarus Verilog")
def test_harness_drives_every_input_and_observes_every_output(tmp_path):
    """Shift a pattern in, load, shift out: dout returns f(inputs) for every core port bit."""
    core = ("module dut(clk, rst, a, v, y, w);\n  input clk; input rst; input [4:0] a; input v;\n"
            "  output reg [5:0] y; output w;\n  assign w = ^a ^ v;\n"
            "  always @(posedge clk) if (rst) y <= 0; else y <= {v, ~a};\nendmodule\n")
    ports = verilog_ports(core, "dut")
    harness = harness_verilog(ports, "dut")
    tb = f"""module tb;
  reg clk = 0, rst = 1, din = 0, load = 0; wire dout;
  {HARNESS_TOP} h(.clk(clk), .rst(rst), .din(din), .load(load), .dout(dout));
  always #1 clk = ~clk;
  reg [5:0] pattern = 6'b101101;   // in_sr = {{v, a}} after 6 shifts (a first in, so lowest bits last)
  integer i;
  initial begin
    @(negedge clk); rst = 0;
    for (i = 5; i >= 0; i = i - 1) begin din = pattern[i]; @(negedge clk); end
    load = 1; @(negedge clk);        // inputs hold; y registers {{v, ~a}}
    @(negedge clk); load = 0;        // out_sr holds {{w, y}}
    for (i = 0; i < 8; i = i + 1) begin $write("%b", dout); @(negedge clk); end
    $display(""); $finish;
  end
endmodule
"""
    (tmp_path / "all.v").write_text(core + harness + tb)
    subprocess.run(["iverilog", "-o", "sim", "all.v"], cwd=tmp_path, check=True)
    out = subprocess.run(["vvp", "-n", "sim"], cwd=tmp_path, capture_output=True, text=True, check=True).stdout
    # core_out = {w, y[5:0], i?}: outputs in port order (y then w) from bit 0 up; dout shifts the MSB first
    a, v = 0b01101, 1
    y = (v << 5) | (~a & 0b11111)
    w = (bin(a).count("1") + v) & 1
    core_out = y | (w << 6)
    assert out.split()[0] == format(core_out, "07b") + "0"


# -- rendering and the build-directory report ---------------------------------------------------------

def test_render_markdown(runs):
    res = {ICE40: {"fits": False, "error": "x", "overflow": {"DSP": [327, 8]}},
           ECP5: runs["tiny", ECP5].to_json()}
    md = render_markdown(res, 9)
    lines = md.splitlines()
    assert lines[0].startswith("| device | Fmax MHz | LUT/LC | FF | carry | DSP | BRAM |")
    assert lines[2].startswith("| ice40-up5k-sg48 | does not fit: DSP 327 of 8 |")
    assert len(lines[2].split("|")) == len(lines[0].split("|"))
    f = runs["tiny", ECP5].fmax_mhz
    assert f"| 9 | {9 / f * 1e3:.1f} | {f * 1e6:,.0f} |" in lines[3]
    with pytest.raises(ValueError, match=r"^initiation_interval must be a positive integer, not 0$"):
        render_markdown(res, 9, 0)
    with pytest.raises(ValueError, match=r"^latency_cycles must be a non-negative integer, not -1$"):
        render_markdown(res, -1)


def test_insert_section_replaces_its_own_section():
    md = "# r\n\n## Timing\n\nt\n\n## Coefficients\n\nc\n"
    once = insert_section(md, f"{SECTION_TITLE}\n\nA\n")
    assert once == f"# r\n\n## Timing\n\nt\n\n{SECTION_TITLE}\n\nA\n\n## Coefficients\n\nc\n"
    assert insert_section(once, f"{SECTION_TITLE}\n\nB\n") == once.replace("\nA\n", "\nB\n")
    assert insert_section("# r\n\nx", f"{SECTION_TITLE}\n") == f"# r\n\nx\n{SECTION_TITLE}\n\n"


def test_cli_report_pnr(wide_verilog, tmp_path, capsys):
    bdir = tmp_path / "build"
    bdir.mkdir()
    (bdir / "wide.v").write_text(wide_verilog)
    (bdir / "manifest.json").write_text(json.dumps({
        "module": "wide", "clock": {"port": "clk", "frequency_hz": CLOCK}, "reset": {"port": "rst"},
        "latency_cycles": 2, "throughput": {"targets_per_cycle": 1}}))
    (bdir / "report.md").write_text("# report\n\n## Timing\n\nt\n\n## Coefficients\n\nc\n")
    assert main(["report", "--pnr", str(bdir), "-q"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [x.split(":")[0] for x in out[:2]] == [ICE40, ECP5]
    assert out[0].endswith(", timing harness") and not out[1].endswith(", timing harness")
    assert out[2] == f"wrote {bdir / 'pnr.json'} and the place-and-route section of {bdir / 'report.md'}"
    pnr = json.loads((bdir / "pnr.json").read_text())
    assert pnr["format"] == "ikseries.pnr" and pnr["latency_cycles"] == 2 and pnr["clock_hz"] == CLOCK
    assert sorted(pnr["devices"]) == sorted([ICE40, ECP5])
    assert all(d["fits"] and d["fmax_mhz"] > 0 and d["utilisation"]["carry"]["used"] > 0
               for d in pnr["devices"].values())
    md = (bdir / "report.md").read_text()
    assert md.index("## Timing") < md.index(SECTION_TITLE) < md.index("## Coefficients")
    assert f"| {ICE40} | " in md and "(harness)" in md
    assert sorted(p.name for p in bdir.iterdir()) == [".ikseries-build.json", "manifest.json", "pnr.json", "report.md",
                                                      "wide.v"]
    from ikseries.buildrecord import recorded_files
    assert "pnr.json" in recorded_files(bdir)      # a rebuild may replace it


def test_cli_report_errors(tmp_path, capsys):
    assert main(["report", "--pnr", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"ikseries: error: {str(tmp_path)!r} holds no ikseries build (no manifest.json); "
                   f"run `ikseries build -o {tmp_path}` first\n")
    assert main(["report", str(tmp_path)]) == 2
    assert capsys.readouterr().err == ("ikseries: error: report needs --pnr (place-and-route on every "
                                       "device), the only report it makes so far\n")
    assert main(["report", "--pnr", "--seed", "-3", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "ikseries: error: --seed must be an integer in [0, 2**31), not -3\n"
    assert not any(tmp_path.iterdir())


def test_report_skips_other_families_for_a_build_with_ecp5_primitives(wide_verilog, tmp_path):
    from ikseries.pnr_report import report_build
    bdir = tmp_path / "build"
    bdir.mkdir()
    (bdir / "wide.v").write_text(wide_verilog)
    (bdir / "manifest.json").write_text(json.dumps({
        "module": "wide", "clock": {"port": "clk", "frequency_hz": CLOCK}, "reset": {"port": "rst"},
        "latency_cycles": 2, "throughput": {"targets_per_cycle": 1},
        "primitives": {"family": "ecp5", "cells": ["MULT18X18D"]}}))
    (bdir / "report.md").write_text("# report\n")
    pnr = report_build(bdir, [ICE40])
    why = "not run: the Verilog instantiates ECP5 MULT18X18D primitives"
    assert pnr["devices"][ICE40] == {"fits": False, "error": why, "stage": "primitives", "overflow": {}}
    assert f"| {ICE40} | {why} |" in (bdir / "report.md").read_text()
