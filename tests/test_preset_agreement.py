"""The real-robot hexapod presets against each robot's own IK and calibration (issue 12).

The ports in ``tests/robot_refs/`` re-implement each robot's published formulas from the cited
source (their ``*_exact`` float64 forms: docs/robots.md says why not the firmware's rounding).
Fast: the description's reference pulses (:func:`ikseries.channels.channel_pulses_pu`, what the fit
approximates) on every leg agree with the port to :data:`AGREEMENT_PU`. Behind ``--long``: the
built plan's pulses (the golden model, bit-exact to the RTL) agree with the port to the fit's
tolerance plus that agreement.
"""
from __future__ import annotations

import json
import time
import tomllib

import numpy as np
import pytest

from robot_refs import freenove, lynxmotion_phoenix as phoenix, phantomx, phoenix_code
from ikseries.body import leg_to_body
from ikseries.channels import channel_pulses_pu, channel_table
from ikseries.cli import main
from ikseries.fit.plan import Plan
from ikseries.robot import load_preset, parse_robot, preset_text
from ikseries.sim import golden

#: issue 12: the description's pulses agree with the robot's own formulas to this (pu)
AGREEMENT_PU = 0.05
#: points per preset, spread over all legs and the walking box
POINTS = 1000
PRESETS = ("phoenix", "phantomx", "freenove-hexapod")


def _phoenix_code_port(mod, cfg, pulses_us):
    """The port of a Phoenix-code robot: body frame -> LegIK target -> its exact pulses (us),
    every target inside the firmware's per-leg limits (CheckAngles would clamp nothing)."""
    def port(robot, name, xb, yb, zb):
        target = phoenix_code.legik_target(cfg, name, xb, yb, zb, robot.geometry.body_height)
        assert mod.within_limits(name, *target).all(), name
        return pulses_us(name, *target)
    return port


def _freenove_port(robot, name, xb, yb, zb):
    """Freenove: body frame -> its body frame -> transform_coordinates -> its exact pulses
    (us), every servo angle inside restrict_value's 0..180 deg (500..2500 us)."""
    k = robot.body.names.index(name)
    leg = freenove.transform_coordinates(k, *freenove.from_preset_body(xb, yb, zb, robot.geometry.body_height))
    pulses = freenove.pulses_exact(k, *leg)
    assert all(((p >= 500.0) & (p <= 2500.0)).all() for p in pulses), name
    return pulses


PORTS = {
    "phoenix": _phoenix_code_port(phoenix, phoenix.PHOENIX, phoenix.pulses_exact),
    "phantomx": _phoenix_code_port(phantomx, phantomx.PHANTOMX, phantomx.hobby_pulses_exact),
    "freenove-hexapod": _freenove_port,
}


def _targets(robot, seed: int):
    """:data:`POINTS` (leg index, leg-frame target) pairs, uniform over the legs and the box."""
    rng = np.random.default_rng(seed)
    legs = rng.integers(0, robot.legs, POINTS)
    return legs, np.array([rng.uniform(s.min, s.max, POINTS) for s in robot.workspace.inputs])


def _port_pulses_pu(robot, port, legs, pts) -> np.ndarray:
    """(servo, point) pulses in pu of leg-frame targets ``pts`` on ``legs`` from the port."""
    out = np.empty((len(robot.servos), len(legs)))
    for k, leg in enumerate(robot.body.legs):
        on = legs == k
        out[:, on] = np.array(port(robot, leg.name, *leg_to_body(leg, *pts[:, on]))) / robot.calibration.pulse_unit_us
    return out


def _reference_pulses_pu(robot, legs, pts) -> np.ndarray:
    out = np.empty((len(robot.servos), len(legs)))
    for k in range(robot.legs):
        on = legs == k
        out[:, on] = np.array(channel_pulses_pu(robot, k, *pts[:, on]))
    return out


def agreement_pu(robot, port, seed: int = 12) -> float:
    """max |description's reference - port| (pu) over :data:`POINTS` targets of ``robot``."""
    legs, pts = _targets(robot, seed)
    assert np.bincount(legs, minlength=robot.legs).min() >= POINTS // (2 * robot.legs)   # every leg sampled
    return float(np.abs(_reference_pulses_pu(robot, legs, pts) - _port_pulses_pu(robot, port, legs, pts)).max())


@pytest.mark.parametrize("name", PRESETS)
def test_preset_pulses_agree_with_the_robots_own_ik(name):
    worst = agreement_pu(load_preset(name), PORTS[name])
    print(f"{name}: max |reference - port| = {worst:.3g} pu over {POINTS} points")
    assert worst <= AGREEMENT_PU


def test_phoenix_channels_clamp_at_each_legs_own_joint_limits():
    """Every Phoenix channel saturates where the firmware's CheckAngles clamps that leg's joint
    (Hex_Cfg.h's per-leg min/max, mirrored left/right), as the SSC-32 pulse of the limit angle
    after the Inv flip, in whole PWM ticks; inside the box no channel reaches its clamp."""
    r = load_preset("phoenix")
    cfg, tick_us = phoenix.PHOENIX, r.hardware.clock_hz * 1e-6
    table = channel_table(r)
    for k, leg in enumerate(phoenix.LEGS):
        i = cfg.leg(leg)
        for j, (mm, inv) in enumerate(zip((cfg.coxa_minmax[i], cfg.femur_minmax[i], cfg.tibia_minmax[i]),
                                          (cfg.coxa_inv[i], cfg.femur_inv[i], cfg.tibia_inv[i]))):
            us = sorted(float(phoenix.ssc32_pulse_exact((-a if inv else a) / 10.0)) for a in mm)
            c = table.channel(k, r.servos[j])
            assert (c.lo, c.hi) == (int(np.ceil(us[0] * tick_us)), int(np.floor(us[1] * tick_us))), (leg, j)
    assert table.gain_bits == 0 and len({(c.lo, c.hi) for c in table.channels}) > 3    # per leg, not one clamp
    pts = np.random.default_rng(5).uniform(r.workspace.lows, r.workspace.highs, size=(2000, 3)).T
    for k in range(len(phoenix.LEGS)):
        pulses = np.array(channel_pulses_pu(r, k, *pts)) * r.ticks_per_pu
        for j, p in enumerate(pulses):
            c = table.channel(k, r.servos[j])
            assert c.lo < p.min() and p.max() < c.hi, (k, j)


def test_agreement_notices_a_wrong_horn_offset():
    """The comparison can fail: a PhantomX whose servos are centred (1500 us) at the pose
    where LegIK's angles would be 0 without the horn offsets (Hex_Cfg.h:38-39: femur level,
    118 mm out, tibia straight down) is 46.3 deg x 22.2 pu/deg off on the tibias."""
    d = tomllib.loads(preset_text("phantomx"))
    d["calibration"]["neutral_pose"] = {"x": 118.0, "y": 0.0, "z": -3.0}
    assert agreement_pu(parse_robot(d), PORTS["phantomx"]) > 1000


# -- the built plan ------------------------------------------------------------------------
def _golden_pulses_pu(robot, plan, legs, pts) -> tuple[np.ndarray, np.ndarray]:
    """(the golden model's channel pulses (pu), the leg-frame targets the ports saw) for
    leg-frame targets ``pts`` on ``legs``: the core takes them in the mount frame (a left leg's
    y negated), at the ports' resolution, as ``ikseries eval --leg`` does."""
    names = [i.name for i in robot.workspace.inputs]
    flip = np.array([1.0 if robot.body.legs[k].side == "right" else -1.0 for k in legs])
    mount = pts.copy()
    mount[names.index("y")] *= flip
    ints = golden.quantize_inputs(plan, dict(zip(names, mount)))
    seen = np.array([ints[i.name] * 2.0 ** -i.frac_bits for i in robot.workspace.inputs])
    seen[names.index("y")] *= flip
    outs = golden.robot_outputs(plan, channel_table(robot), legs, ints)
    return np.array([outs[o.name] / o.ticks_per_pu for o in plan.outputs]), seen


#: freenove-hexapod fits in seconds, so it runs by default: its plan is the one on which Icarus's
#: -g2012 rules left constant-driven always @* blocks at X (sim/runner.py ICARUS_ARGS)
BUILT = [pytest.param(n, marks=() if n == "freenove-hexapod" else pytest.mark.long) for n in PRESETS]


@pytest.mark.parametrize("name", BUILT)
def test_built_preset_agrees_with_the_robots_own_ik(name, tmp_path):
    """``ikseries build --preset NAME --cocotb icarus``: certified within the tolerance, the
    RTL bit-exact to the golden model on Icarus, and the golden model's pulses within the
    tolerance plus :data:`AGREEMENT_PU` of the robot's own IK at :data:`POINTS` targets."""
    out = tmp_path / "build"
    start = time.monotonic()
    assert main(["build", "--preset", name, "--cocotb", "icarus", "-q", "-o", str(out)]) == 0
    seconds = time.monotonic() - start
    robot = load_preset(name)
    rep = json.loads((out / "report.json").read_text())
    assert rep["cocotb"]["icarus"]["passed"] and rep["simulation"]["mismatches"] == 0
    bounds = [s["error_pu"]["total"] for s in rep["servos"]]
    assert max(bounds) <= robot.fit.tolerance_pu
    plan = Plan.from_json(json.loads((out / "plan.json").read_text()))
    legs, pts = _targets(robot, seed=13)
    built, seen = _golden_pulses_pu(robot, plan, legs, pts)
    worst = float(np.abs(built - _port_pulses_pu(robot, PORTS[name], legs, seen)).max())
    print(f"{name}: build {seconds:.0f} s (steps {rep['times_s']}), certified bounds {bounds} pu, max |golden - port| = {worst:.3f} pu "
          f"over {POINTS} points")
    assert worst <= robot.fit.tolerance_pu + AGREEMENT_PU
