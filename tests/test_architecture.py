"""Architecture options: robot fields, the auto choice, LegCore with a folded evaluator,
the flat robot top (i_leg/o_leg, 18 PWM ports) and the build options of the CLI."""
import dataclasses
import re
import tomllib

import numpy as np
import pytest

from ikseries.architecture import ArchitectureError, choose_architecture
from ikseries.cli import main
from ikseries.hdl.export import manifest, robot_verilog
from ikseries.hdl.leg import LegCore
from ikseries.constraints.devices import dsp_size
from ikseries.hdl.shared import RobotCore
from ikseries.robot import (RobotError, load_preset, parse_robot, preset_text, robot_from_record, robot_record,
                            with_hardware)
from helpers import flat_record
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_leg
from ikseries.sim.targets import corner_targets, random_targets


def base(**top):
    d = tomllib.loads(preset_text("cylinder-leg"))
    d.update(top)
    return d


@pytest.fixture
def auto_robot(small_robot):
    """The session's small leg with architecture auto (a single leg defaults to pipelined)."""
    return dataclasses.replace(small_robot, hardware=dataclasses.replace(small_robot.hardware, architecture="auto"))


def test_defaults_and_hexapod_preset():
    r = parse_robot(base())
    hw = r.hardware
    assert (r.legs, hw.architecture, hw.multipliers, hw.dsp, hw.min_refresh_hz) == (1, "pipelined", 1, "ice40", 1000.0)
    assert parse_robot(base(legs=2)).hardware.architecture == "auto"
    h = load_preset("hexapod")
    hw = h.hardware
    assert (h.legs, hw.architecture, hw.dsp, hw.min_refresh_hz, h.ticks_per_pu) == (6, "auto", "ice40", 1000.0, 12.0)
    leg = load_preset("hexapod-leg")
    assert (h.geometry, h.workspace, h.calibration) == (leg.geometry, leg.workspace, leg.calibration)


@pytest.mark.parametrize("top, hw, message", [
    ({"legs": 0}, {}, "legs must be an integer >= 1, not 0"),
    ({"legs": 2.0}, {}, "legs must be an integer >= 1, not 2.0"),
    ({"legs": True}, {}, "legs must be an integer >= 1, not True"),
    ({}, {"architecture": "systolic"},
     "hardware.architecture must be one of auto, pipelined, folded, modulo, fastest, not 'systolic'"),
    ({}, {"architecture": "modulo", "interval": 0}, "hardware.interval must be an integer >= 1, not 0"),
    ({}, {"interval": 4}, "hardware.architecture must be modulo when hardware.interval is given "
                          "(auto and fastest pick the interval themselves), not 'pipelined'"),
    ({"legs": 6}, {"architecture": "modulo"},
     "hardware.architecture must be auto, folded or fastest for legs = 6 (the legs share one folded evaluator), "
     "not 'modulo'"),
    ({}, {"multipliers": 0}, "hardware.multipliers must be an integer >= 1, not 0"),
    ({}, {"multipliers": 2}, "hardware.architecture must be folded when hardware.multipliers is given "
                             "(auto picks 1 or 2 multipliers itself), not 'pipelined'"),
    ({}, {"dsp": "gowin"}, "hardware.dsp must be one of ice40, ecp5, xc7, none, not 'gowin'"),
    ({}, {"min_refresh_hz": 0}, "hardware.min_refresh_hz must be a number > 0, not 0"),
    ({}, {"min_refresh_hz": "fast"}, "hardware.min_refresh_hz must be a number > 0, not 'fast'"),
    ({"legs": 6}, {"architecture": "pipelined"},
     "hardware.architecture must be auto, folded or fastest for legs = 6 (the legs share one folded evaluator), "
     "not 'pipelined'"),
    ({}, {"colour": 1}, "unknown field hardware.colour (expected one of: architecture, clock_hz, cost, "
                        "dsp, dsp_primitives, fit_device, interval, min_refresh_hz, multipliers, pwm_period_us)"),
    ({}, {"dsp_primitives": "yes"}, "hardware.dsp_primitives must be true or false, not 'yes'"),
    ({}, {"dsp_primitives": True, "dsp": "xc7"}, "hardware.dsp must be ice40 or ecp5 when hardware.dsp_primitives "
                                                 "is true (the DSP primitives instantiated: iCE40 SB_MAC16, ECP5 "
                                                 "MULT18X18D), not 'xc7'"),
    ({}, {"architecture": "fastest", "fit_device": "foo"},
     "hardware.fit_device must be one of ice40-up5k, ecp5-25f, xc7a35t, not 'foo'"),
    ({}, {"architecture": "fastest", "fit_device": 3},
     "hardware.fit_device must be one of ice40-up5k, ecp5-25f, xc7a35t, not 3"),
    ({}, {"fit_device": "ecp5-25f"}, "hardware.architecture must be fastest when hardware.fit_device is given "
                                     "(the device the fastest configuration must fit), not 'pipelined'"),
    ({"legs": 6}, {"architecture": "auto", "fit_device": "ecp5-25f"},
     "hardware.architecture must be fastest when hardware.fit_device is given "
     "(the device the fastest configuration must fit), not 'auto'"),
    ({}, {"architecture": "fastest"}, "hardware.fit_device must be one of ice40-up5k, ecp5-25f, xc7a35t when "
                                      "hardware.architecture is fastest (the device to fit), not None"),
    ({}, {"architecture": "fastest", "fit_device": "ecp5-25f", "multipliers": 2},
     "hardware.architecture must be folded when hardware.multipliers is given "
     "(auto picks 1 or 2 multipliers itself), not 'fastest'"),
])
def test_bad_hardware_fields_are_one_line_errors(top, hw, message):
    d = base(**top)
    d["hardware"].update(hw)
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert str(e.value) == message


def test_record_round_trip_and_old_records_load():
    d = base(legs=3)
    d["hardware"].update(architecture="folded", multipliers=2, dsp="xc7", min_refresh_hz=250)
    r = parse_robot(d)
    hw = r.hardware
    assert (r.legs, hw.architecture, hw.multipliers, hw.dsp, hw.min_refresh_hz) == (3, "folded", 2, "xc7", 250.0)
    assert robot_from_record(robot_record(r)) == r
    old = flat_record(robot_record(r))
    for k in ("legs", "architecture", "multipliers", "dsp", "min_refresh_hz"):
        del old[k]                       # a record written before these fields existed
    assert robot_from_record(old) == parse_robot(base())
    bad = robot_record(r)
    bad["hardware"]["dsp"] = "gowin"
    with pytest.raises(RobotError, match="^hardware.dsp must be one of ice40, ecp5, xc7, none, not 'gowin'$"):
        robot_from_record(bad)


def test_with_hardware_names_the_option():
    r = load_preset("hexapod")
    with pytest.raises(RobotError) as e:
        with_hardware(r, {"architecture": "--architecture"}, architecture="pipelined")
    assert str(e.value).startswith("--architecture must be auto, folded or fastest for legs = 6")
    assert with_hardware(r, multipliers=2).hardware.multipliers == 2


def _targets(plan, n, seed):
    return {k: np.concatenate([c, r]) for (k, c), r in
            zip(corner_targets(plan, port_extremes=True).items(), random_targets(plan, n, seed).values())}


def test_leg_core_with_folded_evaluator_is_bit_exact(small_plan):
    core = LegCore(small_plan, 4000, multipliers=2, dsp=dsp_size("ice40"))
    assert core.architecture == "folded"
    assert core.latency == core.initiation_interval == core.evaluator.latency > 1
    assert LegCore(small_plan, 4000).initiation_interval == 1
    t = _targets(small_plan, 40, 3)
    exp = golden.outputs(small_plan, t)
    res = simulate_leg(core, t)
    for s in exp:
        assert np.array_equal(res.outputs[s], exp[s]), s
    assert set(res.latencies.tolist()) == {core.latency}
    assert set(np.diff(res.input_cycles).tolist()) == {core.initiation_interval}
    res = simulate_leg(core, t, ready_prob=0.4, valid_prob=0.7, seed=2)   # backpressure, gaps
    for s in exp:
        assert np.array_equal(res.outputs[s], exp[s]), s


@pytest.mark.parametrize("kw, msg", [
    ({"multipliers": 0}, "multipliers must be None or an integer >= 1, not 0"),
    ({"dsp": (16, 16)}, "dsp must be None for the pipelined evaluator (multipliers=None), not (16, 16)"),
])
def test_leg_core_evaluator_errors(small_plan, kw, msg):
    with pytest.raises(ValueError) as e:
        LegCore(small_plan, 4000, **kw)
    assert str(e.value) == msg


def test_auto_takes_the_smallest_configuration_that_meets_the_rate(auto_robot, small_plan):
    c = choose_architecture(auto_robot, small_plan)
    assert (c.candidate.name, c.candidate.multipliers, c.candidate.dsp) == ("folded", 1, "ice40")
    ii = LegCore(small_plan, auto_robot.hardware.pwm_period_ticks, multipliers=1, dsp=(16, 16)).initiation_interval
    assert c.core.initiation_interval == ii and c.refresh_hz == auto_robot.hardware.clock_hz / ii
    assert [t.candidate.name for t in c.tried] == ["folded"]
    # too fast for any folded evaluator: the modulo-scheduled one with the longest interval
    # that meets the rate, after trying k = 1, 2 and the longer intervals
    half = dataclasses.replace(auto_robot, hardware=dataclasses.replace(auto_robot.hardware,
                                                                 min_refresh_hz=auto_robot.hardware.clock_hz / 2))
    c = choose_architecture(half, small_plan)
    assert (c.candidate.name, c.candidate.interval) == ("modulo", 2) and c.core.architecture == "modulo"
    assert c.core.initiation_interval == 2 and c.refresh_hz == auto_robot.hardware.clock_hz / 2
    assert [(t.candidate.name, t.candidate.multipliers or t.candidate.interval) for t in c.tried] == [
        ("folded", 1), ("folded", 2), ("modulo", 16), ("modulo", 8), ("modulo", 4), ("modulo", 2)]
    assert all(t.refresh_hz < half.hardware.min_refresh_hz for t in c.tried[:-1])
    assert c.record()["multipliers"] == c.core.evaluator.multipliers
    # one target per cycle: the pipelined evaluator
    fast = dataclasses.replace(auto_robot, hardware=dataclasses.replace(auto_robot.hardware,
                                                                 min_refresh_hz=auto_robot.hardware.clock_hz))
    c = choose_architecture(fast, small_plan)
    assert c.candidate.name == "pipelined" and isinstance(c.core, LegCore)
    assert c.core.initiation_interval == 1 and c.refresh_hz == auto_robot.hardware.clock_hz
    rec = c.record()
    assert rec["architecture"] == "pipelined" and rec["reason"].startswith("auto: the smallest configuration")


def test_explicit_modulo_configuration(auto_robot, small_plan):
    c = choose_architecture(dataclasses.replace(auto_robot, hardware=dataclasses.replace(
        auto_robot.hardware, architecture="modulo", interval=5, dsp="ecp5", min_refresh_hz=1.0)), small_plan)
    assert (c.candidate.name, c.candidate.interval) == ("modulo", 5)
    assert c.core.architecture == "modulo" and c.core.initiation_interval == 5
    assert c.record()["multipliers"] == c.core.evaluator.multipliers
    assert c.reason.startswith("hardware.architecture = modulo:")


def test_explicit_and_shared_configurations(auto_robot, small_plan):
    c = choose_architecture(dataclasses.replace(auto_robot, hardware=dataclasses.replace(
        auto_robot.hardware, architecture="folded", multipliers=2, dsp="none")), small_plan)
    assert (c.candidate.name, c.candidate.multipliers, c.candidate.dsp) == ("folded", 2, "none")
    assert c.core.evaluator.dsp is None and c.core.evaluator.multipliers == 2
    six = dataclasses.replace(auto_robot, legs=6)
    c = choose_architecture(six, small_plan)
    assert isinstance(c.core, RobotCore) and c.candidate.name == "shared" and c.core.legs == 6
    assert c.refresh_hz == c.core.refresh_hz == six.hardware.clock_hz / (6 * c.core.initiation_interval)
    c = choose_architecture(dataclasses.replace(six, hardware=dataclasses.replace(six.hardware, architecture="folded",
                                                                                  multipliers=2)), small_plan)
    assert c.candidate.multipliers == 2 and c.core.evaluator.multipliers == 2


def test_unreachable_rate_for_several_legs_names_the_best(auto_robot, small_plan):
    six = dataclasses.replace(auto_robot, legs=6, hardware=dataclasses.replace(auto_robot.hardware, min_refresh_hz=1e7))
    best = max((RobotCore(small_plan, 6, six.hardware.pwm_period_ticks, six.hardware.clock_hz, multipliers=k,
                          dsp=(16, 16))
                for k in (1, 2)), key=lambda core: core.refresh_hz)
    with pytest.raises(ArchitectureError) as e:
        choose_architecture(six, small_plan)
    k = best.evaluator.multipliers
    assert str(e.value) == (
        f"hardware.min_refresh_hz must be at most {best.refresh_hz:.6g} Hz, the best rate of any architecture "
        f"for cylinder-leg-small at 48 MHz with 6 legs (folded evaluator shared by 6 legs, {k} "
        f"multiplier{'s' if k > 1 else ''} (ice40 16x16 DSP), initiation interval {best.initiation_interval} "
        f"cycles), not 1e+07")


def test_flat_robot_top_ports_match_the_manifest(auto_robot, small_plan):
    robot = dataclasses.replace(auto_robot, legs=6)
    core = RobotCore(small_plan, 6, robot.hardware.pwm_period_ticks, robot.hardware.clock_hz, multipliers=1,
                     dsp=(16, 16))
    v = robot_verilog(core, "hexa_core")
    top = re.search(r"^module hexa_core\(.*?^endmodule", v, re.M | re.S).group(0)
    ports = {name: int(w) + 1 if w else 1 for w, name in
             re.findall(r"^\s*(?:input|output)\s+(?:\[(\d+):0\]\s+)?(\w+);", top, re.M)}
    pwm = sorted(p for p in ports if p.startswith("pwm_"))
    assert pwm == sorted(f"pwm_l{leg}_s{j}" for leg in range(6) for j in (1, 2, 3))
    assert ports["i_leg"] == ports["o_leg"] == 3
    man = manifest(robot, small_plan, core, "hexa_core", choose_architecture(robot, small_plan).record())
    assert man["legs"] == 6 and man["initiation_interval"] == core.initiation_interval
    assert man["refresh_hz"] == core.refresh_hz and man["clock_hz"] == robot.hardware.clock_hz
    assert man["architecture"]["architecture"] == "shared"
    named = [f["port"] for f in man["inputs"]["fields"] + man["outputs"]["fields"]]
    assert named[0] == "i_leg" and "o_leg" in named
    for f in man["inputs"]["fields"] + man["outputs"]["fields"]:
        assert ports[f["port"]] == f["width"], f
    assert sorted(p["port"] for p in man["pwm"]) == pwm
    expected = {"clk", "rst", "i_valid", "i_ready", "o_valid", "o_ready", "period_start", *named, *pwm}
    assert set(ports) == expected


@pytest.mark.parametrize("argv, message", [
    (["--architecture", "systolic"],
     "--architecture must be one of auto, pipelined, folded, modulo, fastest, not 'systolic'"),
    (["--interval", "0"], "--interval must be an integer >= 1, not '0'"),
    (["--interval", "4"], "--architecture must be modulo when --interval is given "
                          "(auto and fastest pick the interval themselves), not 'pipelined'"),
    (["--multipliers", "0"], "--multipliers must be an integer >= 1, not '0'"),
    (["--multipliers", "2"], "--architecture must be folded when --multipliers is given "
                             "(auto picks 1 or 2 multipliers itself), not 'pipelined'"),
    (["--multipliers", "two"], "--multipliers must be an integer >= 1, not 'two'"),
    (["--dsp", "gowin"], "--dsp must be one of ice40, ecp5, xc7, none, not 'gowin'"),
    (["--products", "narrow"], "--products must be one of exact, dsp, not 'narrow'"),
    (["--dsp-primitives", "--dsp", "xc7"], "--dsp must be ice40 or ecp5 when --dsp-primitives is true (the DSP "
                                           "primitives instantiated: iCE40 SB_MAC16, ECP5 MULT18X18D), not 'xc7'"),
    (["--dsp-primitives", "--dsp", "ecp5", "--architecture", "pipelined"],
     "--architecture must be auto, modulo, folded or fastest when --dsp-primitives is true (the pipelined core "
     "instantiates no primitives; modulo at interval 1 takes a target per cycle on registered ones), "
     "not 'pipelined'"),
    (["--preset", "hexapod", "--architecture", "pipelined"],
     "--architecture must be auto, folded or fastest for legs = 6 (the legs share one folded evaluator), "
     "not 'pipelined'"),
    (["--fit-device", "foo"], "--fit-device must be one of ice40-up5k, ecp5-25f, xc7a35t, not 'foo'"),
    (["--fit-device", "ecp5-25f"], "--architecture must be fastest when --fit-device is given "
                                   "(the device the fastest configuration must fit), not 'pipelined'"),
    (["--architecture", "fastest"], "--fit-device must be one of ice40-up5k, ecp5-25f, xc7a35t when "
                                    "--architecture is fastest (the device to fit), not None"),
    (["--cost", "area"], "--cost must be one of multipliers, device, not 'area'"),
    (["--cost", "device", "--architecture", "folded"],
     "--architecture must be modulo or pipelined when --cost is 'device' (the cores that price a plan on the "
     "device), not 'folded'"),
    (["--cost", "device", "--dsp", "none"], "--dsp must be one of ice40, ecp5, xc7 when --cost is 'device' (the "
                                            "family whose reference part prices the plan), not 'none'"),
])
def test_build_option_errors(capsys, tmp_path, argv, message):
    out = tmp_path / "out"
    assert main(["build", *argv, "-q", "-o", str(out)]) == 2
    assert capsys.readouterr().err == f"ikseries: error: {message}\n"
    assert not out.exists()
