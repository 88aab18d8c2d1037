"""The chain presets of real robots, ``spotmicro`` and ``mearm``, against the robots' own IK and
servo maps (re-implemented from the cited sources in ``tests/robot_refs/``, exact forms):
the descriptions' reference pulses at 1000 seeded points of each workspace box, and (``--long``)
each preset fitted, built (Amaranth simulation bit-exact against the golden model) and the
golden model, what ``ikseries eval`` prints, compared with the port."""
from __future__ import annotations

import numpy as np
import pytest

from ikseries.channels import body_pulses_pu, channel_calibration, channel_pulses_pu, channel_table
from ikseries.robot import load_preset
from robot_refs import mearm, spotmicro

#: |description's reference pulse - port's exact pulse| (pu) allowed
AGREEMENT_PU = 0.05
N_POINTS, SEED = 1000, 7
#: the SpotMicro legs in the preset's channel order (the yaml's servo numbering)
SPOT_LEGS = ("RF", "RB", "LB", "LF")


def _points(robot, n=N_POINTS, seed=SEED):
    ws = robot.workspace
    return np.random.default_rng(seed).uniform(ws.lows, ws.highs, size=(n, len(ws.lows))).T


def spot_source_frame(leg, x, y, z):
    """The source's leg-frame foot (x4, y4, z4) m of a preset leg-frame target (mm; x forward,
    y left, z up, origin 55 mm outboard of the hip; a left leg's target is its mirrored one).
    A right leg's frame has x left (the hip 55 mm inboard), y up, z forward; a left leg's
    target at the mount is (x, -y, z), its hip frame's y is 55 - y, and its source frame
    has x right and z backward."""
    if leg[0] == "R":
        return (y - 55.0) / 1000, z / 1000, x / 1000
    return (y - 55.0) / 1000, z / 1000, -x / 1000


def spot_port_pu(leg, x, y, z):
    """SpotMicro's PCA9685 counts (exact form) of leg ``leg``'s servos at preset leg-frame
    targets; 1 pu = 1 count."""
    return np.array(spotmicro.leg_counts_exact(leg, *spot_source_frame(leg, x, y, z)))


def mearm_port_pu(x, y, z):
    """The MeArm's (base, shoulder, elbow) us (exact form); 1 pu = 1 us."""
    return np.array(mearm.pulses_exact(x, y, z))


#: the preset's servos that drive the MeArm's base, shoulder and elbow servos (s3 is the
#: relative elbow angle, surplus: no MeArm servo follows it)
MEARM_SERVOS = (0, 1, 3)


def test_spotmicro_reference_pulses_are_the_robots_own():
    """Every leg's channels (the plan's pulse through the channel table's map: mirrored and
    scaled for the legs with servos of their own) against the robot's IK and that leg's servo
    maps, at 1000 seeded points of the box."""
    r = load_preset("spotmicro")
    assert r.body.names == SPOT_LEGS
    x, y, z = _points(r)
    for k, leg in enumerate(SPOT_LEGS):
        assert spotmicro.within_servo_range(leg, *spot_source_frame(leg, x, y, z)).all(), leg
        err = np.abs(np.array(channel_pulses_pu(r, k, x, y, z)) - spot_port_pu(leg, x, y, z)).max(axis=1)
        assert err.max() <= AGREEMENT_PU, (leg, err)


def test_spotmicro_body_frame_is_the_sources():
    """A foot given in the body frame reaches each leg's channels as the source's own body ->
    leg transform (spot_micro_leg.cpp, at the default stand height) gives it."""
    r = load_preset("spotmicro")
    for k, leg in enumerate(SPOT_LEGS):
        xs, _, zs = spotmicro.neutral_stance(leg)          # source body frame: x forward, y up, z right
        foot = np.array([xs * 1000 + 10.0, -zs * 1000 - 5.0, -spotmicro.DEFAULT_STAND_HEIGHT * 1000 + 20.0])
        source = spotmicro.body_to_leg(leg, (foot[0] / 1000, foot[2] / 1000 + spotmicro.DEFAULT_STAND_HEIGHT,
                                             -foot[1] / 1000))
        mine = np.array(body_pulses_pu(r, leg, *([v] for v in foot)))[:, 0]
        theirs = np.array(spotmicro.leg_counts_exact(leg, *source))
        np.testing.assert_allclose(mine, theirs, atol=1e-9, err_msg=leg)


def test_spotmicro_pulse_limits_are_the_drivers_clip():
    """Each channel's limits are its servo's proportional command's clip to +-1
    (motion_cmd.cpp:258-267): center -+ range / 2 counts, in whole PWM ticks."""
    r = load_preset("spotmicro")
    tick_us = r.hardware.clock_hz * 1e-6
    for c in channel_calibration(r):
        _, center, rng, _, _ = spotmicro.SERVOS[f"{c.leg_name}_{c.servo[1]}"]
        lo, hi = ((center - rng / 2) * spotmicro.US_PER_COUNT, (center + rng / 2) * spotmicro.US_PER_COUNT)
        assert (c.min, c.max) == (int(np.ceil(lo * tick_us)), int(np.floor(hi * tick_us))), c


def test_spotmicro_box_is_the_union_of_the_legs_walking_boxes():
    """The box is the union of ``spotmicro.walking_box`` of every leg at one stride (read off
    its x range), turned into the preset's leg frame, and that stride is within the largest
    one every leg allows."""
    r = load_preset("spotmicro")
    lo, hi = (dict(zip(r.workspace.names, v)) for v in (r.workspace.lows, r.workspace.highs))
    stride = hi["x"] / 1000 - spotmicro.STAND_FRONT_X_OFFSET - spotmicro.BACK_BODY_BALANCE_SHIFT
    assert 0 < stride <= spotmicro.largest_stride()
    boxes = []
    for leg in SPOT_LEGS:
        b = spotmicro.walking_box(leg, stride)
        fwd = b["z"] if leg[0] == "R" else tuple(sorted(-v for v in b["z"]))
        side = tuple(sorted(55.0 + 1000 * v for v in b["x"]))     # x4 = (y - 55) / 1000 on both sides
        boxes.append({"x": tuple(1000 * v for v in fwd), "y": side, "z": tuple(1000 * v for v in b["y"])})
    for name in ("x", "y", "z"):
        assert lo[name] == pytest.approx(min(b[name][0] for b in boxes), abs=1e-9), name
        assert hi[name] == pytest.approx(max(b[name][1] for b in boxes), abs=1e-9), name


def test_spotmicro_left_leg_is_the_mirrored_chain():
    """The LF leg (the source's is_leg_12 false branch, in its own leg frame) at a target of its
    mount frame has the angles (hip, -shoulder, -knee) of this chain at the mirrored target
    (x, -y, z): the body's left legs are mirrored right legs."""
    r = load_preset("spotmicro")
    x, y, z = _points(r)
    q = np.array(r.geometry.ik(x, y, z))
    lf = np.degrees(np.array(spotmicro.ikine(*spot_source_frame("LF", x, y, z), spotmicro.IS_LEG_12["LF"])))
    np.testing.assert_allclose(lf, q * np.array([[1], [-1], [-1]]), atol=1e-7)


def test_spotmicro_channels_scale_the_plan_and_the_fit_reserves_it():
    """The legs with servos of their own scale the plan's pulse (gains 0.94..1.07 of RF's):
    the table has gains, and the plan is fitted to the tolerance less the table's rounding,
    over the largest gain."""
    r = load_preset("spotmicro")
    table = channel_table(r)
    assert table.gain_bits > 0
    scales = [abs(c.scale) for c in channel_calibration(r)]
    assert 0.9 < min(scales) < 1 < max(scales) < 1.1
    assert r.fitted.fit.tolerance_pu < r.fit.tolerance_pu / max(scales)


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

def _spot_ports(k, x, y, z):
    return spot_port_pu(SPOT_LEGS[k], x, y, z)


def _mearm_ports(k, x, y, z):
    return mearm_port_pu(x, y, z)


@pytest.mark.long
@pytest.mark.parametrize("name, port, servos", [("spotmicro", _spot_ports, (0, 1, 2)),
                                                ("mearm", _mearm_ports, MEARM_SERVOS)])
def test_preset_builds_and_its_golden_model_agrees_with_the_port(name, port, servos, tmp_path, monkeypatch):
    """Fit (certified), build (Amaranth simulation bit-exact, else the build fails), then the
    golden model at 1000 seeded targets of every leg, quantised as ``ikseries eval`` does
    (at the leg's mount: a left leg's target mirrored), through the channel table, against the
    port at the quantised target: within the tolerance plus the agreement allowance."""
    import ikseries.steps
    from ikseries.body import mirror
    from ikseries.build import build
    from ikseries.fit.fitter import fit_robot
    from ikseries.sim import golden
    robot = load_preset(name)
    fit = fit_robot(robot)
    plan = fit[0]
    for s in plan.meta["certificate"]["servos"]:
        assert s["converged"] and s["total_pu"] <= robot.fitted.fit.tolerance_pu, s
    monkeypatch.setattr(ikseries.steps, "fit_robot", lambda r, progress, **options: fit)
    rep = build(robot, tmp_path / name, synth=False, cocotb=[], progress=lambda m: None)
    assert all(s["error_pu"]["total"] <= robot.fit.tolerance_pu for s in rep.record()["servos"])
    ins = robot.workspace.inputs
    table = channel_table(robot)
    legs = robot.body.legs if robot.body is not None else [None]
    for k, leg in enumerate(legs):
        pts = _points(robot)
        at_mount = pts if leg is None else mirror(leg, *pts)
        ints = golden.quantize_inputs(plan, dict(zip([i.name for i in ins], at_mount)))
        q = [ints[i.name].astype(np.float64) * 2.0 ** -i.frac_bits for i in ins]
        q = q if leg is None else list(mirror(leg, *q))
        outs = golden.robot_outputs(plan, table if leg is not None else None, np.full(len(q[0]), k), ints)
        got = np.array([outs[o.name] / o.ticks_per_pu for o in plan.outputs])[list(servos)]
        err = np.abs(got - port(k, *q)).max(axis=1)
        assert err.max() <= robot.fit.tolerance_pu + AGREEMENT_PU, (k, err)
