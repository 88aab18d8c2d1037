"""Per-servo calibration: each servo's own reference, gain, limits, trim or table."""
import copy
import tomllib

import numpy as np
import pytest

from ikseries.calibration import Calibration, LinearMap, TableMap
from ikseries.fit import centred as cn
from ikseries.fit import interval as ia
from ikseries.fit.certify import _reference_function
from ikseries.robot import (RobotError, load_preset, parse_robot, preset_text, robot_from_record, robot_record)

TABLE = [[30, 900], [70, 1300], [110, 1712], [150, 2136]]     # s3 (tibia) spans 38..140 deg
#: the small fit's servos: s2 by its pulse at angle 0 and a negative gain, pulse limits just
#: outside its pulses over the box (1253.9 .. 1873.9 us: the output clamp stays), s3 by a table
FIT_SERVOS = f"""
[calibration.servos.s2]
zero_pulse_us = 1700.0
us_per_degree = -10.67
pulse_min_us = 1250.0
pulse_max_us = 1880.0

[calibration.servos.s3]
table = {TABLE}
trim_us = 12.5
"""


def base():
    return tomllib.loads(preset_text("cylinder-leg"))


def with_servos(servos: dict, **calibration):
    d = base()
    d["calibration"].update(calibration, servos=servos)
    return d


def samples(robot, n=400, seed=1):
    rng = np.random.default_rng(seed)
    ws = robot.workspace
    lo, hi = np.array(ws.lows), np.array(ws.highs)
    return tuple((lo + (hi - lo) * rng.random((n, len(lo)))).T)


# -- the maps ---------------------------------------------------------------------------------
def test_linear_servos_follow_their_own_formula():
    """pulse = reference + gain * (angle - reference angle) + trim, per servo, to 1e-9 pu."""
    robot = parse_robot(with_servos({
        "s1": {"neutral_pulse_us": 1520.0, "us_per_degree": 13.3, "trim_us": -7.5},
        "s2": {"zero_pulse_us": 1700.0, "us_per_degree": -10.67, "pulse_min_us": 900.0},
    }, directions=[1, 1, -1]))
    u, cal = robot.calibration.pulse_unit_us, robot.calibration
    pts = samples(robot)
    a, neutral = robot.geometry.ik(*pts), cal.neutral_angles(robot.geometry)
    expected = [(1520.0 + 13.3 * (a[0] - neutral[0]) - 7.5) / u,
                (1700.0 - 10.67 * a[1]) / u,
                cal.neutral_pulse_pu - cal.pu_per_degree * (a[2] - neutral[2])]     # the defaults, mirrored
    for p, q in zip(robot.pulses_pu(*pts), expected):
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-9)
    assert robot.pulse_limits_ticks() == {"s1": (24000, 120000), "s2": (43200, 120000), "s3": (24000, 120000)}


def test_table_servo_reproduces_its_points_and_is_linear_between():
    m = TableMap(tuple((float(a), p / 0.5) for a, p in TABLE), trim_pu=3.0)
    xs = np.array([a for a, _ in TABLE], dtype=float)
    ps = np.array([p / 0.5 for _, p in TABLE])
    assert np.array_equal(m.pulse(xs), ps + 3.0)                      # exactly, the last point too
    rng = np.random.default_rng(2)
    for (a0, p0), (a1, p1) in zip(m.points, m.points[1:]):
        t = rng.random(50)
        np.testing.assert_allclose(m.pulse(a0 + t * (a1 - a0)), p0 + t * (p1 - p0) + 3.0, rtol=0, atol=1e-9)
    # the certifier's hinge form is the same function (to the rounding of its slopes)
    a = np.linspace(20.0, 160.0, 301)
    np.testing.assert_allclose(m.pulse(a, np.clip), m.pulse(a), rtol=0, atol=1e-9)


def test_interval_forms_enclose_the_table_across_its_points():
    """Cells around and across table points: the interval and centred enclosures hold the
    pulses, and a cell that straddles a point has no second derivative (a clamp that may switch)."""
    m = TableMap(tuple((float(a), p / 0.5) for a, p in TABLE))
    lo = np.array([[60.0], [69.0], [70.0], [105.0], [40.0]])
    hi = np.array([[65.0], [71.0], [72.0], [115.0], [145.0]])
    for x, dx in ((ia.variables(lo, hi, order=2)[0], None), (cn.variables(lo, hi)[0], "centred")):
        p = m.pulse(x, cn.clamp)
        encl = p.x if dx else p
        for k in range(len(lo)):
            vals = m.pulse(np.linspace(lo[k, 0], hi[k, 0], 101))
            assert encl.lo[k] <= vals.min() + 1e-9 and vals.max() - 1e-9 <= encl.hi[k]
        finite = np.isfinite(encl.h[0]).ravel()
        assert finite.tolist() == [True, False, True, False, False]


def test_certifier_reference_encloses_the_per_servo_pulses():
    robot = parse_robot(tomllib.loads(preset_text("cylinder-leg") + FIT_SERVOS))
    ws, tpp = robot.workspace, robot.ticks_per_pu
    lo, hi = np.array([[10.0, 20.0, 5.0]]), np.array([[14.0, 26.0, 9.0]])
    inside = lo + (hi - lo) * np.random.default_rng(3).random((50, 3))
    for k in range(3):
        for values in (ia.variables(lo, hi, order=1), cn.variables(lo, hi)):
            ref = _reference_function(robot, k, tpp)(dict(zip(ws.names, values)))
            ref = ref.x if isinstance(ref, cn.Centred) else ref
            exact = robot.pulses_pu(*inside.T)[k] * tpp
            assert np.all(ref.lo <= exact + 1e-9) and np.all(exact - 1e-9 <= ref.hi)


def test_kinematic_calibration_of_overridden_servos_gives_the_same_pulses():
    d = tomllib.loads(preset_text("cylinder-leg") + FIT_SERVOS)
    d["geometry"].update(angle_directions=[-1, 1, -1], zero_offsets=[5, 0, 180])   # s3 stays in its table
    robot = parse_robot(d)
    kin = robot.geometry.kinematic_calibration(robot.joint_calibration)
    pts = samples(robot)
    kin_angles = robot.geometry.kinematic_angles(robot.geometry.ik(*pts))
    for p, q in zip(kin.pulses(kin_angles), robot.pulses_pu(*pts)):
        np.testing.assert_allclose(p, q, rtol=0, atol=1e-9)


# -- defaults -----------------------------------------------------------------------------------
def test_defaults_are_the_one_map_of_before():
    """No overrides (or an empty table of them): the record has no servos, equals the preset's,
    and every servo's pulse is the one formula neutral + direction * gain * (angle - neutral)."""
    robot = load_preset("cylinder-leg")
    empty = parse_robot(with_servos({}))
    assert robot_record(empty) == robot_record(robot) and "servos" not in robot_record(robot)["calibration"]
    assert empty.fit_record() == robot.fit_record()
    cal = robot.calibration
    neutral = cal.neutral_angles(robot.geometry)
    assert robot.joint_calibration == Calibration(tuple(
        LinearMap(n, cal.neutral_pulse_pu, d * cal.pu_per_degree) for n, d in zip(neutral, cal.directions)))
    pts = samples(robot)
    for p, a, n, d in zip(robot.pulses_pu(*pts), robot.geometry.ik(*pts), neutral, cal.directions):
        assert np.array_equal(p, cal.neutral_pulse_pu + d * cal.pu_per_degree * (a - n))


def test_overrides_are_recorded_and_read_back():
    robot = parse_robot(tomllib.loads(preset_text("cylinder-leg") + FIT_SERVOS))
    rec = robot_record(robot)
    assert rec["calibration"]["servos"] == {
        "s2": {"zero_pulse_us": 1700.0, "us_per_degree": -10.67, "pulse_min_us": 1250.0, "pulse_max_us": 1880.0},
        "s3": {"table": [[30.0, 900.0], [70.0, 1300.0], [110.0, 1712.0], [150.0, 2136.0]], "trim_us": 12.5}}
    assert robot.fit_record()["servos"] == rec["calibration"]["servos"]   # the plan-cache key sees them
    back = robot_from_record(copy.deepcopy(rec))
    assert robot_record(back) == rec and back.joint_calibration == robot.joint_calibration


def test_servo_records_list_each_servos_calibration():
    robot = parse_robot(tomllib.loads(preset_text("cylinder-leg") + FIT_SERVOS))
    s1, s2, s3 = robot.calibration.servo_records(robot.geometry)
    assert s1 == {"servo": "s1", "map": "linear", "neutral_angle_deg": 0.0, "neutral_pulse_us": 1500.0,
                  "zero_pulse_us": 1500.0, "us_per_degree": 10.0, "trim_us": 0.0,
                  "pulse_min_us": 500.0, "pulse_max_us": 2500.0}
    assert s2["us_per_degree"] == -10.67 and s2["zero_pulse_us"] == 1700.0
    assert (s2["pulse_min_us"], s2["pulse_max_us"]) == (1250.0, 1880.0)
    assert s2["neutral_pulse_us"] == pytest.approx(1700.0 - 10.67 * s2["neutral_angle_deg"], abs=1e-9)
    assert s3["map"] == "table" and s3["table"] == TABLE and s3["trim_us"] == 12.5 and "us_per_degree" not in s3
    assert s3["neutral_pulse_us"] == pytest.approx(float(np.interp(s3["neutral_angle_deg"], *zip(*TABLE))) + 12.5)


# -- messages -----------------------------------------------------------------------------------
S2 = "calibration.servos.s2"


@pytest.mark.parametrize("servos, extra, message", [
    ({"s4": {"zero_pulse_us": 1500.0}}, {}, "unknown field calibration.servos.s4 (expected one of: s1, s2, s3)"),
    ({"s2": {"zero_pulse_us": 1500.0, "neutral_pulse_us": 1500.0}}, {},
     f"{S2} must give exactly one of zero_pulse_us (the pulse at servo angle 0) or neutral_pulse_us (the pulse "
     "at the neutral pose) or a table, not both"),
    ({"s2": {"us_per_degree": 10.0}}, {},
     f"{S2} must give exactly one of zero_pulse_us (the pulse at servo angle 0) or neutral_pulse_us (the pulse "
     "at the neutral pose) or a table, not neither"),
    ({"s2": {"zero_pulse_us": 1500.0, "us_per_degree": 0}}, {},
     f"{S2}.us_per_degree must be a nonzero finite number of us per degree (its sign is the direction), not 0.0"),
    ({"s2": {"zero_pulse_us": 1500.0, "us_per_degree": float("inf")}}, {},
     f"{S2}.us_per_degree must be a finite number of us per degree, not inf"),
    ({"s2": {"zero_pulse_us": "1500"}}, {}, f"{S2}.zero_pulse_us must be a finite number of us, not '1500'"),
    ({"s2": {"zero_pulse_us": 1500.0, "pulse_min_us": 2000.0, "pulse_max_us": 1800.0}}, {},
     f"{S2}.pulse_max_us must be > the pulse_min_us of s2 (2000.0), not 1800.0"),
    ({"s2": {"zero_pulse_us": 1500.0, "pulse_min_us": 2600.0}}, {},
     f"{S2}.pulse_min_us must be < the pulse_max_us of s2 (2500.0), not 2600.0"),
    ({"s2": {"neutral_pulse_us": 1500.0, "trim_us": 1200.0}}, {},
     f"{S2}.trim_us = 1200 drives the pulse at the neutral pose to 2700 us, outside its pulse limits [500, 2500] us"),
    ({"s2": {"neutral_pulse_us": 2400.0, "pulse_max_us": 2000.0}}, {},
     f"{S2} gives a pulse of 2400 us at the neutral pose, outside its pulse limits [500, 2000] us"),
    ({"s3": {"table": [[30, 900], [110, 1700], [70, 1300]]}}, {},
     "calibration.servos.s3.table angles must be strictly increasing, not 70 deg after 110.0 deg "
     "(calibration.servos.s3.table[2])"),
    ({"s3": {"table": [[30, 900]]}}, {},
     "calibration.servos.s3.table must be a list of at least 2 [deg, us] points, not [[30, 900]]"),
    ({"s3": {"table": [[30, 900], [150, "x"]]}}, {},
     "calibration.servos.s3.table[1] must be [deg, us] with two finite numbers, not [150, 'x']"),
    ({"s3": {"table": TABLE, "us_per_degree": 10.0}}, {},
     "calibration.servos.s3.table gives the pulse at every angle: drop calibration.servos.s3.us_per_degree"),
    ({"s3": {"table": [[0, 900], [90, 1800]]}}, {},
     "calibration.servos.s3.table covers servo angles [0, 90] deg, not the neutral pose's 100.133 deg"),
    ({"s2": {"zero_pulse_us": 1500.0, "us_per_degree": 10.0}}, {"directions": [1, -1, 1]},
     "calibration.directions[1] must be 1 when calibration.servos.s2.us_per_degree is given (its sign is the "
     "direction), not -1"),
    ({"s3": {"table": TABLE}}, {"directions": [1, 1, -1]},
     "calibration.directions[2] must be 1 when calibration.servos.s3.table is given (it gives the pulses), not -1"),
    ({"s2": {"zero_pulse_us": 1500.0, "knee": 1}}, {},
     "unknown field calibration.servos.s2.knee (expected one of: neutral_pulse_us, pulse_max_us, pulse_min_us, "
     "table, trim_us, us_per_degree, zero_pulse_us)"),
])
def test_bad_servo_calibration_is_refused_in_one_line(servos, extra, message):
    with pytest.raises(RobotError) as e:
        parse_robot(with_servos(servos, **extra))
    assert str(e.value) == message


@pytest.mark.parametrize("servos, message", [
    ({"s2": {"zero_pulse_us": 1500.0, "us_per_degree": 30.0}},
     "calibration: target (r=0, theta=-180, z=0) drives servo s2 (femur) to 2644.39 us, past its pulse limits "
     "[500, 2500] us (calibration.pulse_max_us)"),
    ({"s2": {"neutral_pulse_us": 1500.0, "us_per_degree": -30.0, "pulse_min_us": 1000.0}},
     "calibration: target (r=0, theta=-180, z=0) drives servo s2 (femur) to 910.696 us, past its pulse limits "
     "[1000, 2500] us (calibration.servos.s2.pulse_min_us)"),
    ({"s3": {"table": [[40, 900], [150, 2100]]}},
     "calibration: target (r=40, theta=0, z=40) needs servo s3 (tibia) at 38.0905 deg, outside its table "
     "[40, 150] deg (calibration.servos.s3.table)"),
])
def test_a_calibration_past_the_limits_inside_the_box_names_the_target_and_servo(servos, message):
    with pytest.raises(RobotError) as e:
        parse_robot(with_servos(servos))
    assert str(e.value) == message


# -- a small fit with a per-servo gain and a table servo ------------------------------------------
FIT_TOML = (preset_text("cylinder-leg").replace('name = "cylinder-leg"', 'name = "calibrated-leg"')
            .replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 ") + FIT_SERVOS)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """The robot of FIT_TOML, its description file and its certified plan (a fit of seconds)."""
    from ikseries.fit.fitter import fit_robot
    path = tmp_path_factory.mktemp("calibrated") / "calibrated-leg.toml"
    path.write_text(FIT_TOML)
    robot = parse_robot(tomllib.loads(FIT_TOML))
    plan = fit_robot(robot)[0]
    plan.meta["robot_description"] = robot_record(robot)
    (path.parent / "plan.json").write_text(plan.dumps())
    return robot, path, plan


def test_per_servo_fit_is_certified_with_its_own_clamps(calibrated):
    robot, _, plan = calibrated
    cert = plan.meta["certificate"]["servos"]
    assert [c["name"] for c in cert] == ["s1", "s2", "s3"]
    assert all(c["converged"] and c["total_pu"] <= robot.fit.tolerance_pu and c["clamp_pu"] == 0 for c in cert)
    limits = robot.pulse_limits_ticks()
    assert limits == {"s1": (24000, 120000), "s2": (60000, 90240), "s3": (24000, 120000)}
    for o in plan.outputs:      # a clamp that never acts is dropped: the output's range is inside
        n, (lo, hi) = plan.nodes[o.node], limits[o.name]
        assert lo <= n.lo and n.hi <= hi and (n.op != "clamp" or tuple(n.param) == (lo, hi))
    assert plan.nodes[plan.outputs[1].node].op == "clamp"     # s2's own limits act


def test_per_servo_fit_golden_model_meets_the_tolerance(calibrated):
    from ikseries.accuracy import measure, verification_points
    robot, _, plan = calibrated
    worst = measure(robot, plan, verification_points(robot, n_points=20_000, n_face=2_000))
    assert all(w["total"] <= robot.fit.tolerance_pu for w in worst["servos"].values())


def test_eval_uses_the_per_servo_map(calibrated, capsys):
    from ikseries.cli import main
    robot, path, _ = calibrated
    assert main(["eval", "--robot", str(path), "--plan", str(path.parent / "plan.json"), "-q", "10", "45", "5"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines() if line.startswith("s")][1:]
    ref = [float(p[0]) for p in robot.pulses_pu([10.0], [45.0], [5.0])]
    assert [r[0] for r in rows] == ["s1", "s2", "s3"]
    assert [float(r[1]) for r in rows] == pytest.approx(ref, abs=1e-3)
    assert all(abs(float(r[4])) <= robot.fit.tolerance_pu for r in rows)
    a = robot.geometry.ik(10.0, 45.0, 5.0)
    assert ref[1] == pytest.approx((1700.0 - 10.67 * float(a[1])) / 0.5, abs=1e-9)
    assert ref[2] == pytest.approx((float(np.interp(a[2], *zip(*TABLE))) + 12.5) / 0.5, abs=1e-9)


def test_cordic_datapath_refuses_a_table_servo(calibrated):
    from ikseries.fit.baselines.cordic import CordicDesign, CordicPlan
    design = CordicDesign(rot_iters=13, xy_iters=13, uv_iters=14, law_iters=13, len_frac=11, area_frac=3,
                          angle_frac=11, gain_frac=18, scale_frac=0)
    with pytest.raises(ValueError, match=r"^the CORDIC datapath scales angles to pulses linearly: "
                                         r"calibration\.servos\.s3\.table needs the polynomial fit$"):
        CordicPlan(calibrated[0], design)


@pytest.mark.long
def test_build_lists_each_servos_calibration(calibrated, tmp_path):
    import json

    from ikseries.cli import main
    robot, path, _ = calibrated
    out = tmp_path / "build"
    assert main(["build", str(path), "--no-synth", "--cocotb", "none", "-q", "-o", str(out)]) == 0
    man = json.loads((out / "manifest.json").read_text())
    assert man["calibration"] == json.loads(json.dumps(robot.calibration.servo_records(robot.geometry)))
    md = (out / "report.md").read_text()
    assert "## Calibration" in md and "| s3 | table 30:900, 70:1300, 110:1712, 150:2136 |" in md
