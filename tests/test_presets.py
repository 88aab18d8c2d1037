"""The hexapod-leg, quadruped-hind and quadruped-fore presets: geometry, IK/FK, calibration."""
import math
import tomllib

import numpy as np
import pytest

from ikseries.hexapod_leg import HexapodLeg
from ikseries.kinematics import NUMPY_MATH, UnreachableError
from ikseries.quadruped import QuadrupedFore, QuadrupedHind
from ikseries.geometry import Geometry, geometry_class, geometry_names
from ikseries.robot import (RobotError, load_preset, parse_robot, preset_names, preset_text,
                            robot_from_record, robot_record)

PRESETS = ["hexapod-leg", "quadruped-hind", "quadruped-fore"]


@pytest.fixture(scope="module", params=PRESETS)
def robot(request):
    return load_preset(request.param)


def _samples(robot, n, seed):
    """n uniform random points in the workspace box plus its corners, one array per input."""
    rng = np.random.default_rng(seed)
    lo = np.array([i.min for i in robot.workspace.inputs])
    hi = np.array([i.max for i in robot.workspace.inputs])
    corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(len(lo), -1)
    pts = lo[:, None] + (hi - lo)[:, None] * rng.random((len(lo), n))
    return tuple(np.concatenate([pts, corners], axis=1))


def _grid(robot, n):
    axes = [np.linspace(i.min, i.max, n) for i in robot.workspace.inputs]
    return tuple(g.ravel() for g in np.meshgrid(*axes, indexing="ij"))


# -- loading -------------------------------------------------------------------------
def test_every_geometry_is_registered_and_implements_the_interface():
    assert geometry_names() == ["chain", "cylinder-leg", "hexapod-leg", "planar-arm", "quadruped-fore", "quadruped-hind",
                                "urdf"]
    for name in geometry_names():
        cls = geometry_class(name)
        assert issubclass(cls, Geometry) and not getattr(cls, "__abstractmethods__", None), name
        if isinstance(cls.inputs, property):    # a chain's inputs and servos are its instance's
            continue
        assert len(cls.inputs) == len(cls.input_units) and len(cls.servos) == len(cls.servo_names), name


def test_presets_are_listed_and_registered():
    assert set(PRESETS) <= set(preset_names())
    for name, cls in [("hexapod-leg", HexapodLeg), ("quadruped-hind", QuadrupedHind),
                      ("quadruped-fore", QuadrupedFore)]:
        assert geometry_class(name) is cls and issubclass(cls, Geometry)
        assert isinstance(load_preset(name).geometry, cls)


def test_preset_loads_with_its_documented_parameters(robot):
    g = robot.geometry
    assert g.coordinates == "cartesian"
    assert robot.servos == ("s1", "s2", "s3") and len(g.servo_names) == 3
    assert [i.name for i in robot.workspace.inputs] == list(g.inputs) and all(u == "mm" for u in g.input_units)
    cal = robot.calibration
    assert (cal.pulse_unit_us, cal.neutral_pulse_pu, cal.pu_per_degree, robot.fit.tolerance_pu) == (0.5, 3000, 20, 0.5)
    if robot.name == "hexapod-leg":
        assert (g.coxa, g.femur, g.tibia, g.body_height) == (15, 80, 130, 78)
        assert (robot.calibration.pulse_min_us, robot.calibration.pulse_max_us) == (600, 2400)
        assert robot.calibration.neutral_pose == {"x": 74.0, "y": 0.0, "z": 0.0}
    else:
        assert (robot.calibration.pulse_min_us, robot.calibration.pulse_max_us) == (500, 2500)
        assert robot.calibration.neutral_pose == {"x": 0.0, "y": 0.0}


def test_robot_record_round_trip(robot):
    assert robot_from_record(robot_record(robot)) == robot


# -- IK / FK -------------------------------------------------------------------------
def test_fk_inverts_ik_over_the_workspace(robot):
    pts = _samples(robot, 100_000, seed=7)
    back = robot.geometry.fk(*robot.geometry.ik(*pts))
    assert max(np.max(np.abs(a - b)) for a, b in zip(pts, back)) < 1e-9


def test_ik_inverts_fk(robot):
    """The other way round: joint angles from ik survive fk then ik."""
    g = robot.geometry
    pts = _samples(robot, 2000, seed=8)
    angles = g.ik(*pts)
    again = g.ik(*g.fk(*angles))
    assert max(np.max(np.abs(a - b)) for a, b in zip(angles, again)) < 1e-9


def test_pure_formula_is_the_checked_ik(robot):
    pts = _samples(robot, 5000, seed=9)
    for a, b in zip(robot.geometry.ik(*pts), robot.geometry.angles(NUMPY_MATH, *pts)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
        assert np.shape(b) == np.shape(pts[0])


def test_joint_ranges_and_pulse_limits_hold_over_the_workspace(robot):
    g = robot.geometry
    pts = _grid(robot, 41 if len(robot.workspace.inputs) == 3 else 301)
    angles = g.ik(*pts)  # raises for a joint out of range
    for a, (lo, hi), name in zip(angles, g.joint_ranges, g.servo_names):
        assert lo + 5 < np.min(a) and np.max(a) < hi - 5, name  # a margin of more than 5 deg
    for p in robot.pulses_pu(*pts):
        assert robot.calibration.pulse_min_us < np.min(p) * robot.calibration.pulse_unit_us
        assert np.max(p) * robot.calibration.pulse_unit_us < robot.calibration.pulse_max_us


def test_neutral_pose_gives_the_neutral_pulse(robot):
    pose = [robot.calibration.neutral_pose[i.name] for i in robot.workspace.inputs]
    np.testing.assert_allclose(robot.pulses_pu(*pose), robot.calibration.neutral_pulse_pu, rtol=0, atol=1e-9)
    moved = dict(robot.calibration.neutral_pose, y=robot.calibration.neutral_pose["y"] + 10.0)
    assert not np.allclose(robot.pulses_pu(*(moved[i.name] for i in robot.workspace.inputs)),
                           robot.calibration.neutral_pulse_pu)


# -- unreachable targets -------------------------------------------------------------
@pytest.mark.parametrize("geometry, point, message", [
    (HexapodLeg(), (300.0, 0.0, 0.0),
     "target (x=300, y=0, z=0) is unreachable: tip distance from the femur axis 295.481 mm must be within [50, 210] mm"),
    (HexapodLeg(), (200.0, 0.0, 0.0),
     "target (x=200, y=0, z=0) is unreachable: tibia angle -54.8592 deg must be within [0, 90] deg "
     "(geometry.joint_ranges[2])"),
    (HexapodLeg(), (54.0, 0.0, 45.0),
     "target (x=54, y=0, z=45) is unreachable: femur angle -124.613 deg must be within [-90, 90] deg "
     "(geometry.joint_ranges[1])"),
    (HexapodLeg(), (-50.0, 1.0, 0.0),
     "target (x=-50, y=1, z=0) is unreachable: coxa angle 178.854 deg must be within [-90, 90] deg "
     "(geometry.joint_ranges[0])"),
    (QuadrupedHind(), (0.0, -30.0),
     "target (x=0, y=-30) is unreachable: hip-toe distance 135 mm must be within (30, 130) mm "
     "with the shin bisected by the hip-toe line"),
    (QuadrupedHind(), (0.0, 80.0),
     "target (x=0, y=80) is unreachable: hip-toe distance 25 mm must be within (30, 130) mm "
     "with the shin bisected by the hip-toe line"),
    (QuadrupedHind(), (0.0, 70.0),
     "target (x=0, y=70) is unreachable: knee angle 160.556 deg must be within [0, 150] deg "
     "(geometry.joint_ranges[1])"),
    (QuadrupedFore(), (100.0, 0.0),
     "target (x=100, y=0) is unreachable: shoulder-toe distance 145 mm must be within [20, 120] mm"),
    (QuadrupedFore(), (0.0, 70.0),
     "target (x=0, y=70) is unreachable: shoulder angle 109.616 deg must be within [-90, 90] deg "
     "(geometry.joint_ranges[0])"),
    (QuadrupedFore(), (14.0, 75.0),
     "target (x=14, y=75) is unreachable: elbow angle 154.233 deg must be within [0, 150] deg "
     "(geometry.joint_ranges[1])"),
])
def test_unreachable_target_is_a_one_line_error_naming_it(geometry, point, message):
    with pytest.raises(UnreachableError) as e:
        geometry.ik(*point)
    assert str(e.value) == message


@pytest.mark.parametrize("geometry, good, bad", [
    (HexapodLeg(), (74.0, 0.0, 0.0), (74.0, 0.0, 100.0)),
    (QuadrupedHind(), (0.0, 0.0), (0.0, -40.0)),
    (QuadrupedFore(), (0.0, 0.0), (-120.0, 0.0)),
])
def test_one_bad_target_among_good_ones_is_found(geometry, good, bad):
    coords = [np.array([g, g, b, b]) for g, b in zip(good, bad)]
    names = ", ".join(f"{n}={v:g}" for n, v in zip(geometry.inputs, bad))
    with pytest.raises(UnreachableError, match=rf"^target \({names}\) is unreachable: "):
        geometry.ik(*coords)


def test_unreachable_workspace_is_a_robot_error():
    d = tomllib.loads(preset_text("hexapod-leg"))
    d["workspace"]["z"]["max"] = 60.0
    with pytest.raises(RobotError, match=r"^workspace: target \(x=54, y=-40, z=40\) is unreachable: "
                                         r"femur angle -91.7416 deg must be within \[-90, 90\] deg "
                                         r"\(geometry.joint_ranges\[1\]\)$"):
        parse_robot(d)


# -- hand-checked poses --------------------------------------------------------------
def test_hexapod_standing_pose_reproduces_the_paper_normalisation():
    """The paper subtracts 54.85 (femur) and 41.33 (tibia) deg at its standing pose.

    At (74, 0, 0) the tip is 59 mm out and 78 mm below the femur axis. By hand:
    L^2 = 59^2 + 78^2 = 9565; A3 = acos((80^2 + 130^2 - L^2) / (2 * 80 * 130)) and
    theta3 = 90 - A3 = 41.33. The paper's femur value needs its eq. 2 as printed,
    A1 = atan(L / 78); the geometric A1 = atan(59 / 78) gives -40.53 instead.
    """
    s1, s2, s3 = (float(a) for a in HexapodLeg().ik(74.0, 0.0, 0.0))
    L2 = 59.0 ** 2 + 78.0 ** 2
    a2 = math.degrees(math.acos((80 ** 2 + L2 - 130 ** 2) / (2 * 80 * math.sqrt(L2))))
    assert s1 == 0.0
    assert round(s3, 2) == 41.33
    assert round(90 - (math.degrees(math.atan(math.sqrt(L2) / 78)) + a2), 2) == -54.85  # the paper's eq. 2
    assert s2 == pytest.approx(90 - (math.degrees(math.atan2(59, 78)) + a2), abs=1e-12)
    assert round(s2, 2) == -40.53


def test_hexapod_femur_level_tibia_plumb():
    """Femur horizontal, tibia vertical down: the tip is coxa + femur = 95 mm out and
    tibia - body_height = 52 mm below the ground; turned 30 deg by the coxa."""
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    angles = [float(a) for a in HexapodLeg().ik(95 * c, 95 * s, -52.0)]
    assert angles == pytest.approx([30.0, 0.0, 0.0], abs=1e-9)


def test_fore_leg_right_angled_elbow():
    """Upper arm 60 and straight forearm+hand 80 reach 100 mm with the elbow at 90 deg:
    at (0, 0) the upper arm is acos(60/100) = 53.13 deg behind the vertical; at (60, 20)
    the toe line is atan(60/80) = 36.87 deg ahead of it, leaving 16.26 deg."""
    leg = QuadrupedFore(upper_arm=60.0, forearm=55.0, hand=25.0, shoulder_height=100.0)
    a = [float(v) for v in leg.ik(0.0, 0.0)]
    assert a == pytest.approx([math.degrees(math.acos(0.6)), 90.0, 0.0], abs=1e-9)
    a = [float(v) for v in leg.ik(60.0, 20.0)]
    assert a == pytest.approx([math.degrees(math.acos(0.6) - math.atan(0.75)), 90.0, 0.0], abs=1e-9)


def test_hind_leg_right_angled_split():
    """Thigh 25, shin 30, foot 39 with the toe 56 mm below the hip: the shin crosses the
    hip-toe line at right angles at La = 20, Lb = 36 (15-20-25 and 15-36-39 triangles),
    a split that is not the symmetric Lt / 2. Hip = atan(15/20), knee = 180 - atan(20/15),
    hock = 180 - atan(36/15)."""
    leg = QuadrupedHind(thigh=25.0, shin=30.0, foot=39.0, hip_height=56.0)
    lt, la, lb = (float(v) for v in leg.split(NUMPY_MATH, 0.0, 0.0))
    assert (lt, la, lb) == pytest.approx((56.0, 20.0, 36.0), abs=1e-12)
    a = [float(v) for v in leg.ik(0.0, 0.0)]
    deg = math.degrees
    assert a == pytest.approx([deg(math.atan(15 / 20)), 180 - deg(math.atan(20 / 15)),
                               180 - deg(math.atan(36 / 15))], abs=1e-9)


# -- the hind leg's split point ------------------------------------------------------
def _notes_split_by_bisection(leg, lt):
    """La from the notes' condition IKtest = 1, i.e. equal cosines of the opposite angles at
    the split point, by plain bisection (the notes iterate; this is the independent check)."""
    s, p, h = 0.5 * leg.shin, leg.thigh, leg.foot

    def g(la):  # cos(angle at M, hip side) - cos(angle at M, toe side)
        lb = lt - la
        return (la * la + s * s - p * p) / (2 * la * s) - (lb * lb + s * s - h * h) / (2 * lb * s)

    lo = np.maximum(abs(p - s), lt - (h + s)) + 1e-12
    hi = np.minimum(p + s, lt - abs(h - s)) - 1e-12
    glo = g(lo)
    assert np.all(np.sign(glo) != np.sign(g(hi)))
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        left = np.sign(g(mid)) == np.sign(glo)
        lo, hi = np.where(left, mid, lo), np.where(left, hi, mid)
    return 0.5 * (lo + hi)


def test_hind_split_point_matches_the_notes_condition():
    robot = load_preset("quadruped-hind")
    leg = robot.geometry
    x, y = _samples(robot, 20_000, seed=11)
    lt, la, lb = leg.split(NUMPY_MATH, x, y)
    np.testing.assert_allclose(la, _notes_split_by_bisection(leg, lt), rtol=0, atol=1e-9)
    # the notes' test value, IKtest = (Lt - La)(La^2 + A) / (La ((Lt - La)^2 + B)), is 1
    s = leg.shin / 2
    a, b = s * s - leg.thigh ** 2, s * s - leg.foot ** 2
    iktest = (lt - la) * (la * la + a) / (la * ((lt - la) ** 2 + b))
    assert np.max(np.abs(iktest - 1)) < 1e-12


def test_hind_fk_puts_the_shin_midpoint_on_the_hip_toe_line():
    robot = load_preset("quadruped-hind")
    leg = robot.geometry
    x, y = _samples(robot, 5000, seed=12)
    hip, knee, _ = (np.radians(a) for a in leg.ik(x, y))
    thigh = hip - np.pi / 2
    kx, ky = leg.thigh * np.cos(thigh), leg.thigh * np.sin(thigh)     # knee, from the hip
    shin = thigh - knee
    mx, my = kx + leg.shin / 2 * np.cos(shin), ky + leg.shin / 2 * np.sin(shin)
    tx, ty = x, y - leg.hip_height                                   # toe, from the hip
    lt = np.hypot(tx, ty)
    assert np.max(np.abs(mx * ty - my * tx) / lt) < 1e-9             # distance of M from the line
    t = (mx * tx + my * ty) / lt ** 2
    assert np.all((0 < t) & (t < 1))                                  # between hip and toe
    assert np.all(kx * ty - ky * tx < 0)                              # knee ahead of the line


def test_hind_closed_form_holds_over_the_reach_for_supported_proportions():
    rng = np.random.default_rng(5)
    for _ in range(200):
        thigh, foot = rng.uniform(10, 100, 2)
        leg = QuadrupedHind(thigh=thigh, shin=rng.uniform(1, 2 * min(thigh, foot)), foot=foot,
                            hip_height=300.0)
        lo, hi = leg.reach()
        lt = np.linspace(lo, hi, 402)[1:-1]
        with np.errstate(invalid="ignore"):
            _, la, lb = leg.split(NUMPY_MATH, 0.0 * lt, leg.hip_height - lt)
            angles = leg.angles(NUMPY_MATH, 0.0 * lt, leg.hip_height - lt)
        assert all(np.all(np.isfinite(a)) for a in angles), (thigh, leg.shin, foot)
        np.testing.assert_allclose(la, _notes_split_by_bisection(leg, lt), rtol=0, atol=1e-7)


def test_hind_shin_longer_than_the_closed_form_allows_is_rejected():
    with pytest.raises(ValueError, match=r"^shin must be <= 2 \* min\(thigh, foot\) = 70 mm "
                                         r"\(the closed-form split point\), not 80.0$"):
        QuadrupedHind(shin=80.0)
    d = tomllib.loads(preset_text("quadruped-hind"))
    d["geometry"]["shin"] = 80.0
    with pytest.raises(RobotError, match=r"^geometry.shin must be <= 2 \* min\(thigh, foot\) = 70 mm"):
        parse_robot(d)


# -- symmetries the fitter can use -----------------------------------------------------
def test_hexapod_coxa_odd_femur_tibia_even_in_y():
    g = HexapodLeg()
    x, y, z = np.meshgrid(np.linspace(54, 94, 9), np.linspace(0, 40, 9), np.linspace(-20, 30, 9))
    a, b = g.ik(x, y, z), g.ik(x, -y, z)
    np.testing.assert_allclose(a[0], -b[0], atol=1e-12)
    np.testing.assert_allclose(a[1], b[1], atol=1e-12)
    np.testing.assert_allclose(a[2], b[2], atol=1e-12)


@pytest.mark.parametrize("leg", [QuadrupedHind(), QuadrupedFore()])
def test_quadruped_bends_even_in_x(leg):
    x, y = np.meshgrid(np.linspace(0, 35, 15), np.linspace(-5, 30, 15))
    a, b = leg.ik(x, y), leg.ik(-x, y)
    for u, v in zip(a[1:], b[1:]):
        np.testing.assert_allclose(u, v, atol=1e-12)
    # the pivot angle is even part +- atan2(x, Hh - y): its odd part is exactly that
    sign = 1 if isinstance(leg, QuadrupedHind) else -1
    height = leg.hip_height if isinstance(leg, QuadrupedHind) else leg.shoulder_height
    np.testing.assert_allclose((a[0] - b[0]) / 2, sign * np.degrees(np.arctan2(x, height - y)), atol=1e-12)


def test_cylinder_workspace_checks_still_apply():
    d = tomllib.loads(preset_text("cylinder-leg"))
    d["workspace"]["r"]["min"] = -1.0
    with pytest.raises(RobotError, match=r"^workspace.r.min must be >= 0 mm, not -1.0$"):
        parse_robot(d)
