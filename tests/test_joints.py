"""Joint conventions of the closed-form geometries: joint_ranges, zero_offsets, angle_directions
(ikseries/joints.py): validation, the servo angles of ik / angles / fk, pulses, the range check
of the workspace, records."""
import dataclasses
import tomllib

import numpy as np
import pytest

from ikseries.fit import interval as ia
from ikseries.fit.certify import _reference_function
from ikseries.joints import JointConventions
from ikseries.kinematics import NUMPY_MATH, UnreachableError
from ikseries.robot import (RobotError, fit_record, load_preset, parse_robot, preset_text, robot_from_record,
                            robot_record)

#: every preset of a closed-form geometry (hexapod shares hexapod-leg's)
PRESETS = ["cylinder-leg", "hexapod-leg", "planar-arm", "quadruped-fore", "quadruped-hind"]


def description(preset="hexapod-leg", **geometry):
    d = tomllib.loads(preset_text(preset))
    d["geometry"].update(geometry)
    return d


def samples(robot, n=400, seed=3):
    rng = np.random.default_rng(seed)
    return [i.min + (i.max - i.min) * rng.random(n) for i in robot.workspace.inputs]


# -- validation ----------------------------------------------------------------------------
@pytest.mark.parametrize("field, value, message", [
    ("joint_ranges", [[-90, 90], [-90, 90], [90, 0]],
     "geometry.joint_ranges[2] must be [min, max] deg with min < max, not [90, 0]"),
    ("joint_ranges", [[-90, 90], [10, 10], [0, 90]],
     "geometry.joint_ranges[1] must be [min, max] deg with min < max, not [10, 10]"),
    ("joint_ranges", [[-90, 90], [-90, 90]],
     "geometry.joint_ranges must be a list of 3 [min, max] pairs in deg (one per servo: coxa, femur, tibia), "
     "not [[-90, 90], [-90, 90]]"),
    ("joint_ranges", [[-200, 200], [-90, 90], [0, 90]],
     "geometry.joint_ranges[0] must be at most 360 deg wide, not [-200, 200] (400 deg)"),
    ("joint_ranges", [[-90, 90], [-90, float("nan")], [0, 90]],
     "geometry.joint_ranges[1] must be [min, max] deg with two finite numbers, not [-90, nan]"),
    ("joint_ranges", [[-90, 90], [-90, 90], [0, 90, 180]],
     "geometry.joint_ranges[2] must be [min, max] deg with two finite numbers, not [0, 90, 180]"),
    ("joint_ranges", [[-90, 90], [-90, 90], "0..90"],
     "geometry.joint_ranges[2] must be [min, max] deg with two finite numbers, not '0..90'"),
    ("joint_ranges", 90, "geometry.joint_ranges must be a list of 3 [min, max] pairs in deg (one per servo: "
                         "coxa, femur, tibia), not 90"),
    ("zero_offsets", [0, -3.5], "geometry.zero_offsets must be a list of 3 numbers in deg (one per servo: "
                                "coxa, femur, tibia), not [0, -3.5]"),
    ("zero_offsets", [0, float("inf"), 46.3], "geometry.zero_offsets[1] must be a finite number of deg, not inf"),
    ("zero_offsets", [0, True, 46.3], "geometry.zero_offsets[1] must be a finite number of deg, not True"),
    ("angle_directions", [1, 1, 0], "geometry.angle_directions[2] must be +1 or -1, not 0"),
    ("angle_directions", [1, -2, 1], "geometry.angle_directions[1] must be +1 or -1, not -2"),
    ("angle_directions", [1, 1, "-1"], "geometry.angle_directions[2] must be +1 or -1, not '-1'"),
    ("angle_directions", [1, 1, 1, 1], "geometry.angle_directions must be a list of 3 values +1 or -1 "
                                       "(one per servo: coxa, femur, tibia), not [1, 1, 1, 1]"),
])
def test_bad_convention_is_one_line_naming_field_index_and_value(field, value, message):
    with pytest.raises(RobotError) as e:
        parse_robot(description(**{field: value}))
    assert str(e.value) == message


def test_the_length_is_the_geometry_servo_count():
    with pytest.raises(RobotError, match=r"^geometry.zero_offsets must be a list of 2 numbers in deg \(one per "
                                         r"servo: link1, link2\), not \[0, 0, 0\]$"):
        parse_robot(description("planar-arm", zero_offsets=[0, 0, 0]))
    assert parse_robot(description("planar-arm", zero_offsets=[0, 0])) == load_preset("planar-arm")


@pytest.mark.parametrize("preset", PRESETS)
def test_defaults_are_today_values_and_stay_out_of_the_record(preset):
    robot = load_preset(preset)
    g = robot.geometry
    n = len(g.servos)
    assert isinstance(g, JointConventions)
    assert g.zero_offsets == (0.0,) * n and g.angle_directions == (1,) * n
    assert g.joint_ranges == type(g).default_joint_ranges
    assert not {"joint_ranges", "zero_offsets", "angle_directions"} & set(robot_record(robot)["geometry"])
    explicit = {"zero_offsets": [0] * n, "angle_directions": [1] * n}
    if g.joint_ranges is not None:
        explicit["joint_ranges"] = [list(r) for r in g.joint_ranges]
    again = parse_robot(description(preset, **explicit))
    assert again == robot and robot_record(again) == robot_record(robot)


def test_hexapod_leg_default_ranges_are_the_paper_table():
    assert load_preset("hexapod-leg").geometry.joint_ranges == ((-90.0, 90.0), (-90.0, 90.0), (0.0, 90.0))
    assert load_preset("cylinder-leg").geometry.joint_ranges is None      # unchecked, as before


# -- the workspace range check ---------------------------------------------------------------
#: a Lynxmotion Phoenix leg (coxa 29, femur 76, tibia 106 mm; KurtE/Arduino_Phoenix_Parts
#: Hex_Cfg.h) 80 mm above the ground, walking box with 20 mm of body raise (z down to -20)
PHOENIX = {"coxa": 29.0, "femur": 76.0, "tibia": 106.0, "body_height": 80.0}
PHOENIX_BOX = {"x": (90.0, 130.0), "y": (-40.0, 40.0), "z": (-20.0, 30.0)}


def phoenix(**geometry):
    d = description(**PHOENIX, **geometry)
    for name, (lo, hi) in PHOENIX_BOX.items():
        d["workspace"][name].update(min=lo, max=hi)
    d["calibration"]["neutral_pose"] = {"x": 110.0, "y": 0.0, "z": 0.0}
    return d


def test_phoenix_box_is_refused_with_the_default_tibia_range_and_accepted_widened():
    with pytest.raises(RobotError) as e:
        parse_robot(phoenix())
    assert str(e.value) == ("workspace: target (x=110, y=-40, z=-20) is unreachable: tibia angle -2.63341 deg "
                            "must be within [0, 90] deg (geometry.joint_ranges[2])")
    robot = parse_robot(phoenix(joint_ranges=[[-90, 90], [-90, 90], [-30, 90]]))
    assert robot.geometry.joint_ranges[2] == (-30.0, 90.0)
    assert float(robot.geometry.ik(110.0, -40.0, -20.0)[2]) == pytest.approx(-2.63341, abs=1e-5)


def test_the_box_proof_checks_the_servo_angles_of_the_offsets():
    """The default hexapod-leg box keeps the tibia in 17.0..69.4 deg: a tibia zero 20 deg
    further back puts the servo angle below 0 somewhere in the box, one 15 deg ahead does not."""
    with pytest.raises(RobotError, match=r"^workspace: target .* is unreachable: tibia angle -[\d.]+ deg must "
                                         r"be within \[0, 90\] deg \(geometry.joint_ranges\[2\]\)$"):
        parse_robot(description(zero_offsets=[0, 0, -20]))
    parse_robot(description(zero_offsets=[0, 0, 15]))
    with pytest.raises(RobotError, match=r"tibia angle -[\d.]+ deg must be within \[0, 90\] deg"):
        parse_robot(description(angle_directions=[1, 1, -1]))      # the mirrored tibia counts negative
    parse_robot(description(angle_directions=[1, 1, -1], joint_ranges=[[-90, 90], [-90, 90], [-90, 0]]))


def test_a_range_given_to_a_geometry_without_defaults_is_checked():
    """cylinder-leg has no joint ranges of its own; given one, its box is checked against it."""
    base = load_preset("cylinder-leg")
    femur = base.geometry.ik(*samples(base, 2000))[1]
    lo, hi = float(np.min(femur)), float(np.max(femur))
    d = description("cylinder-leg", joint_ranges=[[-180, 180], [lo + 1.0, 180], [-180, 180]])
    with pytest.raises(RobotError, match=r"^workspace: target .* is unreachable: femur angle [-\d.]+ deg must "
                                         r"be within \[[-\d.]+, 180\] deg \(geometry.joint_ranges\[1\]\)$"):
        parse_robot(d)
    parse_robot(description("cylinder-leg", joint_ranges=[[-180, 180], [lo - 5.0, hi + 5.0], [-180, 180]]))


# -- servo angles and pulses -----------------------------------------------------------------
CONVENTIONS = {  # offsets and directions per preset that keep its box within the ranges
    "cylinder-leg": ([12.5, -3.5, 46.3], [-1, 1, -1]),
    "hexapod-leg": ([0.0, -3.5, 46.3], [1, 1, -1]),
    "planar-arm": ([-180.0, 30.0], [1, -1]),
    "quadruped-fore": ([5.0, 10.0, 0.0], [-1, 1, 1]),
    "quadruped-hind": ([-5.0, 2.0, 3.0], [1, -1, -1]),
}


def with_conventions(preset):
    """The preset with CONVENTIONS' offsets and directions and ranges that take every servo
    angle they give over its box."""
    offsets, directions = CONVENTIONS[preset]
    return parse_robot(description(preset, zero_offsets=offsets, angle_directions=directions,
                                   joint_ranges=[[-180, 180]] * len(offsets)))


@pytest.mark.parametrize("preset", PRESETS)
def test_servo_angle_is_direction_times_kinematic_plus_offset(preset):
    base, robot = load_preset(preset), with_conventions(preset)
    offsets, directions = CONVENTIONS[preset]
    pts = samples(base)
    kinematic = base.geometry.ik(*pts)
    servo = robot.geometry.ik(*pts)
    for k, (a, s) in enumerate(zip(kinematic, servo)):
        np.testing.assert_allclose(s, directions[k] * np.asarray(a) + offsets[k], rtol=0, atol=1e-9)
    for a, s in zip(robot.geometry.angles(NUMPY_MATH, *pts), servo):
        np.testing.assert_allclose(a, s, rtol=0, atol=1e-9)    # the pure formula is the checked ik
    for x, y in zip(robot.geometry.fk(*servo), base.geometry.fk(*kinematic)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)    # fk takes the servo angles


@pytest.mark.parametrize("preset", PRESETS)
def test_pulses_follow_the_calibration_formula_of_the_servo_angles(preset):
    """pulse = neutral_pulse + calibration.direction * pu_per_degree * (servo - servo at the
    neutral pose): the offset cancels, the joint's direction flips the deviation."""
    base, robot = load_preset(preset), with_conventions(preset)
    cal = robot.calibration
    pose = [cal.neutral_pose[n] for n in robot.geometry.inputs]
    pts = samples(robot)
    servo, neutral = robot.geometry.ik(*pts), robot.geometry.ik(*pose)
    pulses = robot.pulses_pu(*pts)
    for k, p in enumerate(pulses):
        expected = cal.neutral_pulse_pu + cal.directions[k] * cal.pu_per_degree * (servo[k] - float(neutral[k]))
        np.testing.assert_allclose(p, expected, rtol=0, atol=1e-9)
    _, directions = CONVENTIONS[preset]
    for d, p, q in zip(directions, pulses, base.pulses_pu(*pts)):
        np.testing.assert_allclose(p - cal.neutral_pulse_pu, d * (q - cal.neutral_pulse_pu), rtol=0, atol=1e-9)


def test_hexapod_offsets_shift_the_reported_angle_not_the_pulse():
    base = load_preset("hexapod-leg")
    robot = parse_robot(description(zero_offsets=[0, -3.5, 46.3], joint_ranges=[[-90, 90], [-90, 90], [0, 150]]))
    femur, tibia = (float(v) for v in base.geometry.ik(74.0, 0.0, 0.0)[1:])      # -40.53, 41.33
    assert [float(v) for v in robot.geometry.ik(74.0, 0.0, 0.0)] == pytest.approx(
        [0.0, femur - 3.5, tibia + 46.3], abs=1e-12)
    pts = samples(robot)
    for p, q in zip(robot.pulses_pu(*pts), base.pulses_pu(*pts)):
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-9)
    assert robot.fit_record() != base.fit_record()    # the description differs, so does the key


def test_certified_reference_encloses_the_servo_pulses():
    """The certifier's interval reference (fit/certify.py) runs the servo conventions on
    intervals with derivatives: over cells it must enclose the exact pulses inside them."""
    robot = with_conventions("hexapod-leg")
    ws = robot.workspace
    rng = np.random.default_rng(5)
    lo = np.array(ws.lows) + (np.array(ws.highs) - np.array(ws.lows)) * rng.random((50, 3)) * 0.9
    hi = lo + 0.5
    inside = lo + (hi - lo) * rng.random((50, 3))
    tpp = robot.ticks_per_pu
    for k in range(3):
        ref = _reference_function(robot, k, tpp)(dict(zip(ws.names, ia.variables(lo, hi, order=1))))
        exact = robot.pulses_pu(*inside.T)[k] * tpp
        assert np.all(ref.lo <= exact) and np.all(exact <= ref.hi)


def test_cordic_datapath_calibration_is_the_same_map_of_kinematic_angles():
    base, robot = load_preset("cylinder-leg"), with_conventions("cylinder-leg")
    cal = robot.joint_calibration
    kin = robot.geometry.kinematic_calibration(cal)
    pts = samples(robot)
    for p, q in zip(kin.pulses(base.geometry.ik(*pts)), robot.pulses_pu(*pts)):
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-9)
    plain = base.joint_calibration
    assert base.geometry.kinematic_calibration(plain) is plain      # the defaults change nothing


def test_planar_arm_servo_angle_of_the_wrapped_link_angle():
    base, robot = load_preset("planar-arm"), with_conventions("planar-arm")
    s1, s2 = (float(v) for v in base.geometry.ik(-50.0, 0.0))
    t1, t2 = (float(v) for v in robot.geometry.ik(-50.0, 0.0))
    assert (t1, t2) == pytest.approx((s1 - 180.0, 30.0 - s2), abs=1e-12)
    (w1, w2), (a1, a2) = robot.geometry.rates(t1, t2, 1.0, 0.5)
    (v1, v2), (b1, b2) = base.geometry.rates(s1, s2, 1.0, 0.5)
    assert (w1, w2, a1, a2) == pytest.approx((v1, -v2, b1, -b2), rel=1e-12)
    narrow = dataclasses.replace(robot.geometry, joint_ranges=((-180, 180), (-90, 90)))
    with pytest.raises(UnreachableError, match=r"^target \(x=-50, y=0\) is unreachable: link2 angle "
                                               r"-92\.\d+ deg must be within \[-90, 90\] deg "
                                               r"\(geometry.joint_ranges\[1\]\)$"):
        narrow.ik(-50.0, 0.0)


# -- records ---------------------------------------------------------------------------------
def test_given_conventions_are_recorded_and_read_back():
    robot = with_conventions("hexapod-leg")
    geo = robot_record(robot)["geometry"]
    assert geo["zero_offsets"] == [0.0, -3.5, 46.3] and geo["angle_directions"] == [1, 1, -1]
    assert geo["joint_ranges"] == [[-180.0, 180.0]] * 3
    assert robot_from_record(robot_record(robot)) == robot
    assert fit_record(robot_record(robot))["geometry"] == geo
    only = parse_robot(description(angle_directions=[1, 1, -1], joint_ranges=[[-90, 90], [-90, 90], [-90, 0]]))
    assert set(robot_record(only)["geometry"]) == {"type", "coxa", "femur", "tibia", "body_height",
                                                   "angle_directions", "joint_ranges"}


@pytest.mark.long
def test_mirrored_tibia_with_horn_offsets_fits_and_certifies():
    """One fit (about 25 s): hexapod-leg with horn offsets femur -3.5, tibia +46.3 deg and the
    tibia mirrored; the certifier runs the conventions on intervals over the whole box."""
    from ikseries.accuracy import measure
    from ikseries.fit.fitter import fit_robot
    robot = parse_robot(description(zero_offsets=[0, -3.5, 46.3], angle_directions=[1, 1, -1],
                                    joint_ranges=[[-90, 90], [-90, 90], [-90, 90]]))
    plan, _ = fit_robot(robot)
    acc = measure(robot, plan)
    for s in plan.meta["certificate"]["servos"]:
        assert s["converged"] and s["total_pu"] <= robot.fit.tolerance_pu, s
        assert s["approximation_pu"] >= acc["servos"][s["name"]]["approximation"], s
        assert acc["servos"][s["name"]]["total"] <= robot.fit.tolerance_pu, s
