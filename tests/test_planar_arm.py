"""The planar 3R arm: reference IK/FK, its conventions, and the planar-arm preset."""
import dataclasses
import tomllib

import numpy as np
import pytest

from ikseries.kinematics import NUMPY_MATH, UnreachableError
from ikseries.planar_arm import PlanarArm
from ikseries.robot import RobotError, load_preset, parse_robot, preset_text, robot_from_record, robot_record


@pytest.fixture(scope="module")
def arm_robot():
    return load_preset("planar-arm")


def _box_grid(robot, n=81):
    (x, y) = robot.workspace.inputs
    return np.meshgrid(np.linspace(x.min, x.max, n), np.linspace(y.min, y.max, n), indexing="ij")


def _reachable_targets(arm, n, rng):
    """Random tool tips whose wrist lies strictly inside the reachable annulus."""
    lo, hi = arm.reach()
    r = np.sqrt(rng.uniform((lo + 0.01) ** 2, (hi - 0.01) ** 2, n))
    a = rng.uniform(-np.pi, np.pi, n)
    ph = np.radians(arm.phi)
    return r * np.cos(a) + arm.l3 * np.cos(ph), r * np.sin(a) + arm.l3 * np.sin(ph)


@pytest.mark.parametrize("phi", [180.0, 90.0, 45.0, -30.0])
def test_fk_inverts_ik_over_the_whole_annulus(phi):
    arm = PlanarArm(phi=phi)
    x, y = _reachable_targets(arm, 20_000, np.random.default_rng(1))
    x2, y2 = arm.fk(*arm.ik(x, y))
    assert max(np.max(np.abs(x2 - x)), np.max(np.abs(y2 - y))) < 1e-9


def test_ik_inverts_fk_for_clockwise_elbows():
    arm = PlanarArm(phi=45.0)
    rng = np.random.default_rng(2)
    s1 = rng.uniform(0, 360, 5000)
    s2 = s1 - rng.uniform(1, 179, 5000)  # link 2 clockwise from link 1
    b1, b2 = arm.ik(*arm.fk(s1, s2))
    turn = lambda a, b: (a - b + 180) % 360 - 180  # noqa: E731
    assert np.max(np.abs(turn(b1, s1))) < 1e-7 and np.max(np.abs(turn(b2, s2))) < 1e-7


def test_elbow_is_clockwise_and_angles_are_in_0_360():
    arm = PlanarArm(phi=90.0)
    x, y = _reachable_targets(arm, 20_000, np.random.default_rng(3))
    s1, s2 = arm.ik(x, y)
    assert np.all((s1 >= 0) & (s1 < 360) & (s2 >= 0) & (s2 < 360))
    rel = np.mod(s2 - s1, 360.0)  # s2 - s1 in (-180, 0) mod 360
    assert np.all((rel > 180) & (rel < 360))
    # geometrically: the elbow lies to the left of the shoulder -> wrist line
    ex, ey = arm.l1 * np.cos(np.radians(s1)), arm.l1 * np.sin(np.radians(s1))
    wx, wy = arm.wrist(x, y)
    assert np.all(wx * ey - wy * ex > 0)


def test_link_along_plus_x_gives_0_not_360():
    arm = PlanarArm(phi=0.0)
    s1, s2 = arm.ik(*arm.fk(0.0, -60.0))
    assert 0 <= s1 < 360 and 0 <= s2 < 360
    assert min(s1, 360 - s1) < 1e-9 and abs(s2 - 300) < 1e-9


def test_unreachable_targets_are_named_in_one_line():
    arm = PlanarArm(phi=180.0)
    with pytest.raises(UnreachableError) as e:
        arm.ik(80.0, 0.0)
    assert str(e.value) == ("target (x=80, y=0) is unreachable: wrist distance from the shoulder 90 mm "
                            "must be within [5, 65] mm and > 0")
    # the first bad point among good ones, inside the hole
    with pytest.raises(UnreachableError, match=r"^target \(x=-9, y=0\) is unreachable: wrist distance from "
                                               r"the shoulder 1 mm must be within \[5, 65\] mm and > 0$"):
        arm.ik([-50.0, -9.0, 80.0], [0.0, 0.0, 0.0])
    with pytest.raises(UnreachableError, match=r"target \(x=nan, y=0\)"):
        arm.ik(np.nan, 0.0)


@pytest.mark.parametrize("phi", [180.0, 90.0, 45.0])
def test_pure_formula_matches_checked_ik(phi):
    arm = PlanarArm(phi=phi)
    x, y = _reachable_targets(arm, 20_000, np.random.default_rng(4))
    ref = arm.ik(x, y)
    for a, b in zip(ref, arm.angles(NUMPY_MATH, x, y)):
        # equal modulo 360 everywhere; equal outright where no link points along +x
        np.testing.assert_allclose((b - a + 180) % 360 - 180, 0, atol=1e-9)
        assert np.all((b > 0) & (b <= 360))


def test_rates_match_finite_differences_of_ik():
    arm = PlanarArm(phi=45.0)
    ux, uy = 2 / np.sqrt(5), -1 / np.sqrt(5)
    t = np.linspace(0, 30, 7)
    x0, y0 = -10.0, 45.0
    h = 1e-3
    at = lambda s: np.unwrap(np.radians(np.array(arm.ik(x0 + s * ux, y0 + s * uy))), axis=-1)  # noqa: E731
    a_m, a_0, a_p = at(t - h), at(t), at(t + h)
    (w1, w2), (c1, c2) = arm.rates(*np.degrees(a_0), ux, uy)
    np.testing.assert_allclose(np.radians([w1, w2]), (a_p - a_m) / (2 * h), rtol=0, atol=1e-7)
    np.testing.assert_allclose(np.radians([c1, c2]), (a_p - 2 * a_0 + a_m) / h ** 2, rtol=0, atol=1e-4)


# -- the preset --------------------------------------------------------------------------------
def test_preset_neutral_pose_and_servos(arm_robot):
    assert arm_robot.servos == ("s1", "s2") and arm_robot.geometry == PlanarArm(35.0, 30.0, 10.0, 180.0)
    assert [i.name for i in arm_robot.workspace.inputs] == ["x", "y"]
    assert np.allclose(arm_robot.pulses_pu(-50.0, 0.0), 3000.0)


def test_preset_box_has_no_wrap_and_pulses_within_limits(arm_robot):
    g = _box_grid(arm_robot, 161)
    for a in arm_robot.geometry.ik(*g):
        assert np.max(np.abs(np.diff(a, axis=0))) < 1 and np.max(np.abs(np.diff(a, axis=1))) < 1
        assert 0 < a.min() and a.max() < 360
    cal = arm_robot.calibration
    lo, hi = cal.pulse_min_us / cal.pulse_unit_us, cal.pulse_max_us / cal.pulse_unit_us
    for p in arm_robot.pulses_pu(*g):
        assert lo < p.min() and p.max() < hi
    # and the pure formula is the checked IK over the box (no wrap to undo)
    for a, b in zip(arm_robot.geometry.ik(*g), arm_robot.geometry.angles(NUMPY_MATH, *g)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)


def _arm_toml():
    return tomllib.loads(preset_text("planar-arm"))


def test_phi_may_be_negative_but_lengths_must_be_positive():
    d = _arm_toml()
    d["geometry"]["phi"] = -180.0
    assert parse_robot(d).geometry.phi == -180.0
    d["geometry"]["l1"] = -35.0
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert str(e.value) == "geometry.l1 must be > 0, not -35.0"
    d = _arm_toml()
    d["geometry"]["phi"] = "west"
    with pytest.raises(RobotError, match=r"^geometry.phi must be a number, not 'west'$"):
        parse_robot(d)


def test_unreachable_preset_box_is_a_one_line_error():
    d = _arm_toml()
    d["workspace"]["x"]["min"] = -90.0
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert str(e.value).startswith("workspace: target (x=-90, y=-20) is unreachable: wrist distance")
    assert "\n" not in str(e.value)


def test_preset_record_round_trip(arm_robot):
    assert robot_from_record(robot_record(arm_robot)) == arm_robot
    assert robot_record(arm_robot)["geometry"] == {"type": "planar-arm", "l1": 35.0, "l2": 30.0, "l3": 10.0,
                                                    "phi": 180.0}


def test_geometry_is_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        PlanarArm().phi = 0.0
