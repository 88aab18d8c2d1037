"""The chain presets of real robots, ``spotmicro`` and ``mearm``, against the robots' own IK and
servo maps (re-implemented from the cited sources in ``tests/robot_refs/``, exact forms):
the descriptions' reference pulses at 1000 seeded points of each workspace box, and (``--long``)
each preset fitted, built (Amaranth simulation bit-exact against the golden model) and the
golden model, what ``ikseries eval`` prints, compared with the port."""
from __future__ import annotations

import numpy as np
import pytest

from ikseries.robot import load_preset
from robot_refs import mearm, spotmicro

#: |description's reference pulse - port's exact pulse| (pu) allowed
AGREEMENT_PU = 0.05
N_POINTS, SEED = 1000, 7
#: the SpotMicro leg the preset is (its servos' rows of the yaml's table)
SPOT_LEG = "RF"


def _points(robot, n=N_POINTS, seed=SEED):
    ws = robot.workspace
    return np.random.default_rng(seed).uniform(ws.lows, ws.highs, size=(n, len(ws.lows))).T


def spot_port_pu(x, y, z):
    """SpotMicro's PCA9685 counts (exact form) of preset-frame targets (mm; x forward, y left,
    z up): the source's leg frame (x4, y4, z4) m is (y, z, x) / 1000; 1 pu = 1 count."""
    return np.array(spotmicro.leg_counts_exact(SPOT_LEG, y / 1000, z / 1000, x / 1000))


def mearm_port_pu(x, y, z):
    """The MeArm's (base, shoulder, elbow) us (exact form); 1 pu = 1 us."""
    return np.array(mearm.pulses_exact(x, y, z))


#: the preset's servos that drive the MeArm's base, shoulder and elbow servos (s3 is the
#: relative elbow angle, surplus: no MeArm servo follows it)
MEARM_SERVOS = (0, 1, 3)


def test_spotmicro_reference_pulses_are_the_robots_own():
    r = load_preset("spotmicro")
    x, y, z = _points(r)
    assert spotmicro.within_servo_range(SPOT_LEG, y / 1000, z / 1000, x / 1000).all()
    err = np.abs(np.array(r.pulses_pu(x, y, z)) - spot_port_pu(x, y, z)).max(axis=1)
    assert err.max() <= AGREEMENT_PU, err


def test_spotmicro_pulse_limits_are_the_drivers_clip():
    """Each servo's limits are its proportional command's clip to +-1 (motion_cmd.cpp:258-267):
    center -+ range / 2 counts."""
    r = load_preset("spotmicro")
    for k, servo in enumerate(r.servos, start=1):
        _, center, rng, _, _ = spotmicro.SERVOS[f"{SPOT_LEG}_{k}"]
        lo, hi = r.calibration.limits_us(servo)
        assert (lo, hi) == pytest.approx(((center - rng / 2) * spotmicro.US_PER_COUNT,
                                          (center + rng / 2) * spotmicro.US_PER_COUNT), abs=1e-9), servo


def test_spotmicro_box_is_the_walking_box_of_its_stride():
    """The box is ``spotmicro.walking_box`` of one stride (read off its x range), turned into
    the preset's frame, and that stride is within the largest one every leg allows."""
    r = load_preset("spotmicro")
    lo, hi = (dict(zip(r.workspace.names, v)) for v in (r.workspace.lows, r.workspace.highs))
    stride = (hi["x"] / 1000 - spotmicro.STAND_FRONT_X_OFFSET - spotmicro.BACK_BODY_BALANCE_SHIFT)
    assert 0 < stride <= spotmicro.largest_stride()
    box = spotmicro.walking_box(SPOT_LEG, stride)
    for mine, theirs in (("x", "z"), ("y", "x"), ("z", "y")):
        assert (lo[mine], hi[mine]) == pytest.approx(tuple(1000 * v for v in box[theirs]), abs=1e-9), mine


def test_spotmicro_left_leg_is_the_mirrored_chain():
    """The LF leg (the source's is_leg_12 false branch, in its own leg frame) at a target of its
    hip frame (x forward, y left, z up) has the angles (hip, -shoulder, -knee) of this chain at
    the mirrored target (x, -y, z): the geometry would mount as a body's left leg."""
    r = load_preset("spotmicro")
    x, y, z = _points(r)
    y = -y                                          # the LF box: the RF one mirrored
    q = np.array(r.geometry.ik(x, -y, z))
    lf = np.degrees(np.array(spotmicro.ikine(-y / 1000, z / 1000, -x / 1000, spotmicro.IS_LEG_12["LF"])))
    np.testing.assert_allclose(lf, q * np.array([[1], [-1], [-1]]), atol=1e-7)


def test_mearm_reference_pulses_are_the_arms_own():
    r = load_preset("mearm")
    x, y, z = _points(r)
    port = mearm_port_pu(x, y, z)
    assert np.isfinite(port).all()                 # solve reaches the whole box
    assert ((port >= mearm.MIN_PULSE_WIDTH) & (port <= mearm.MAX_PULSE_WIDTH)).all()   # no Servo.write clamp
    pulses = np.array(r.pulses_pu(x, y, z))
    err = np.abs(pulses[list(MEARM_SERVOS)] - port).max(axis=1)
    assert err.max() <= AGREEMENT_PU, err
    assert np.abs(pulses[2] - 1500.0).max() <= 0.1      # the surplus s3 holds 1500 us


def test_mearm_linkage_holds_the_hand_level_and_the_wrist_is_minus_a2():
    r = load_preset("mearm")
    x, y, z = _points(r)
    q = np.array(r.geometry.ik(x, y, z))
    a0, a1, a2 = (np.degrees(a) for a in mearm.solve_exact(x, y, z))
    np.testing.assert_allclose(q[1] + q[2] + q[3], 0.0, atol=1e-9)
    np.testing.assert_allclose(q[[0, 1, 3]], np.array([a0, a1, -a2]), atol=1e-7)


def test_mearm_box_is_inside_the_iktest_box():
    r = load_preset("mearm")
    box = mearm.workspace_box()
    for name, lo, hi in zip(r.workspace.names, r.workspace.lows, r.workspace.highs):
        assert box[name][0] <= lo < hi <= box[name][1], name


# -- fitted, built and simulated ------------------------------------------------------------

@pytest.mark.long
@pytest.mark.parametrize("name, port, servos", [("spotmicro", spot_port_pu, (0, 1, 2)),
                                                ("mearm", mearm_port_pu, MEARM_SERVOS)])
def test_preset_builds_and_its_golden_model_agrees_with_the_port(name, port, servos, tmp_path, monkeypatch):
    """Fit (certified), build (Amaranth simulation bit-exact, else the build fails), then the
    golden model at 1000 seeded targets, quantised as ``ikseries eval`` does, against the port
    at the quantised target: within the tolerance plus the agreement allowance."""
    import ikseries.steps
    from ikseries.build import build
    from ikseries.fit.fitter import fit_robot
    from ikseries.sim import golden
    robot = load_preset(name)
    fit = fit_robot(robot)
    plan = fit[0]
    for s in plan.meta["certificate"]["servos"]:
        assert s["converged"] and s["total_pu"] <= robot.fit.tolerance_pu, s
    monkeypatch.setattr(ikseries.steps, "fit_robot", lambda r, progress, **options: fit)
    rep = build(robot, tmp_path / name, synth=False, cocotb=[], progress=lambda m: None)
    assert all(s["error_pu"]["total"] <= robot.fit.tolerance_pu for s in rep.record()["servos"])
    ins = robot.workspace.inputs
    ints = golden.quantize_inputs(plan, dict(zip([i.name for i in ins], _points(robot))))
    q = [ints[i.name].astype(np.float64) * 2.0 ** -i.frac_bits for i in ins]
    outs = golden.outputs(plan, ints)
    got = np.array([outs[o.name] / o.ticks_per_pu for o in plan.outputs])[list(servos)]
    err = np.abs(got - port(*q)).max(axis=1)
    assert err.max() <= robot.fit.tolerance_pu + AGREEMENT_PU, err
