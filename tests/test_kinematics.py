import numpy as np
import pytest

from ikseries.kinematics import CylinderLeg, UnreachableError


def test_neutral_pose_pulses_are_the_neutral_pulse(robot):
    p = robot.pulses_pu(0.0, 0.0, 20.0)
    assert np.allclose(p, robot.calibration.neutral_pulse_pu)


def test_fk_inverts_ik_over_the_workspace(robot):
    rng = np.random.default_rng(3)
    n = 200_000
    r, th, z = (np.concatenate([lo + (hi - lo) * rng.random(n), [lo, hi]]) for lo, hi in
                ((i.min, i.max) for i in robot.workspace.inputs))
    g = robot.geometry
    angles = g.ik(r, th, z)
    x, y, zz = g.to_cartesian(r, th, z)
    x2, y2, z2 = g.fk_cartesian(*angles)
    assert max(np.max(np.abs(x - x2)), np.max(np.abs(y - y2)), np.max(np.abs(zz - z2))) < 1e-9
    # and back to cylindrical coordinates where theta is defined
    r3, th3, z3 = g.fk(*angles)
    far = r > 1e-3
    assert np.max(np.abs(r3 - r)) < 1e-9
    dth = (th3 - th + 180) % 360 - 180
    assert np.max(np.abs(dth[far] * np.radians(1) * r[far])) < 1e-9


def test_s1_odd_and_s2_s3_even_in_theta(robot):
    th = np.linspace(0, 180, 50)
    a = robot.geometry.ik(25.0, th, 10.0)
    b = robot.geometry.ik(25.0, -th, 10.0)
    assert np.allclose(a[0], -b[0], atol=1e-12)
    assert np.allclose(a[1], b[1], atol=1e-12) and np.allclose(a[2], b[2], atol=1e-12)


def test_unreachable_target_names_the_point():
    leg = CylinderLeg()
    with pytest.raises(UnreachableError, match=r"target \(r=200, theta=0, z=0\) is unreachable: .*\[30, 150\] mm"):
        leg.ik(200.0, 0.0, 0.0)
    # one bad point among good ones is found and named
    with pytest.raises(UnreachableError, match=r"r=300, theta=90, z=5"):
        leg.ik([0.0, 300.0], [0.0, 90.0], [5.0, 5.0])


def test_direction_sign_mirrors_the_pulse(robot):
    import dataclasses
    flipped = dataclasses.replace(robot, calibration=dataclasses.replace(robot.calibration, directions=(-1, 1, -1)))
    a = np.array(robot.pulses_pu(30.0, 40.0, 5.0))
    b = np.array(flipped.pulses_pu(30.0, 40.0, 5.0))
    n = robot.calibration.neutral_pulse_pu
    assert np.allclose(b[0] - n, -(a[0] - n)) and np.isclose(b[1], a[1]) and np.allclose(b[2] - n, -(a[2] - n))


def test_pure_formula_matches_checked_ik():
    """``angles(xp, ...)`` (used for the certified bound) is the same IK as ``ik``."""
    from ikseries.kinematics import NUMPY_MATH, CylinderLeg
    g = CylinderLeg()
    rng = np.random.default_rng(0)
    r, th, z = rng.random(2000) * 40, rng.random(2000) * 360 - 180, rng.random(2000) * 40
    for a, b in zip(g.ik(r, th, z), g.angles(NUMPY_MATH, r, th, z)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
