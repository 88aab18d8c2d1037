import hashlib
import json
import tomllib

import pytest

from ikseries.robot import RobotError, load_robot, parse_robot, preset_names, preset_text


def base():
    return tomllib.loads(preset_text("cylinder-leg"))


def test_presets_list_and_default():
    assert "cylinder-leg" in preset_names()
    r = parse_robot(base())
    assert r.servos == ("s1", "s2", "s3") and r.ticks_per_pu == 24.0 and r.hardware.pwm_period_ticks == 960000


def _set(d, path, value):
    keys = path.split(".")
    for k in keys[:-1]:
        d = d[k]
    if value is _DEL:
        del d[keys[-1]]
    else:
        d[keys[-1]] = value


_DEL = object()


@pytest.mark.parametrize("path, value, message", [
    ("fit.tolerance_pu", -1, "fit.tolerance_pu must be > 0 pu, not -1"),
    ("fit.tolerance_pu", "x", "fit.tolerance_pu must be > 0 pu, not 'x'"),
    ("fit.products", "narrow", "fit.products must be one of exact, dsp, not 'narrow'"),
    ("geometry.femur", -60.0, "geometry.femur must be > 0, not -60.0"),
    ("geometry.femur", _DEL, "geometry.femur is missing"),
    ("geometry.type", "hexapod", "geometry.type must be one of chain, cylinder-leg, hexapod-leg, planar-arm, quadruped-fore, quadruped-hind, urdf, not 'hexapod'"),
    ("geometry.knee", 3.0, "unknown field geometry.knee"),
    ("workspace.r.max", -1.0, "workspace.r.max must be > workspace.r.min (0.0), not -1.0"),
    ("workspace.theta.min", -270.0, "workspace.theta must lie within [-180, 180] deg, not [-270.0, 180.0]"),
    ("workspace.z.frac_bits", 2.5, "workspace.z.frac_bits must be an integer, not 2.5"),
    ("workspace.z.frac_bits", 40, "workspace.z.frac_bits must be in 0..16, not 40"),
    ("workspace.r.max", 400.0, "workspace: target (r=100, theta=-45, z=0) is unreachable: tip distance"),
    ("calibration.directions", [1, 2, 1], "calibration.directions must be a list of 3 values each +1 or -1, not [1, 2, 1]"),
    ("calibration.pu_per_degree", 0, "calibration.pu_per_degree must be > 0, not 0"),
    ("calibration.pulse_max_us", 400.0, "calibration.pulse_max_us must be > pulse_min_us (500.0), not 400.0"),
    ("calibration.neutral_pose.z", 500.0, "calibration.neutral_pose: target (r=0, theta=0, z=500) is unreachable"),
    ("hardware.clock_hz", 1e6, "hardware.clock_hz must be an integer, not 1000000.0"),
    ("hardware.clock_hz", 1_000_000, "hardware.clock_hz must give at least one PWM tick per pulse unit (>= 2e+06 Hz), not 1000000"),
    ("hardware.pwm_period_us", 2000.0, "hardware.pwm_period_us must be > calibration.pulse_max_us (2500), not 2000.0"),
    ("name", "my leg", "name must be an ASCII letter followed by at most 63 ASCII letters, digits, '-' and '_' "
                       "(it names the output files and the Verilog module), not 'my leg'"),
    ("name", "3leg", "(it names the output files and the Verilog module), not '3leg'"),
    ("name", "beinä", "(it names the output files and the Verilog module), not 'beinä'"),
    ("name", "x" * 65, "name must be an ASCII letter followed by at most 63"),
    ("fit.tolerance_pu", float("inf"), "fit.tolerance_pu must be finite, not inf"),
    ("fit.tolerance_pu", float("nan"), "fit.tolerance_pu must be > 0 pu, not nan"),
    ("fit.tolerance_pu", 0.02, "fit.tolerance_pu must be > 0.0277778 pu with 24 PWM ticks per pulse unit "
                               "(rounding to whole ticks costs 0.0208333 pu; or raise hardware.clock_hz or "
                               "calibration.pulse_unit_us to give more than 33.3333 ticks per pu), not 0.02"),
    ("calibration.neutral_pulse_pu", 6000.0, "calibration.neutral_pulse_pu must give a pulse within "
     "[pulse_min_us, pulse_max_us] = [500, 2500] us, i.e. within [1000, 5000] pu at pulse_unit_us = 0.5, not 6000.0"),
    ("hardware.min_refresh_hz", 5e7, "hardware.min_refresh_hz must be at most 4.8e+07 Hz (one target per clock "
                                     "cycle at hardware.clock_hz = 48000000 shared by legs = 1), not 50000000.0"),
    ("colour", "red", "unknown field colour"),
])
def test_bad_description_names_field_and_value(path, value, message):
    d = base()
    _set(d, path, value)
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def test_load_robot_file_errors(tmp_path):
    with pytest.raises(RobotError, match="cannot read robot description"):
        load_robot(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(RobotError, match="invalid TOML"):
        load_robot(bad)
    good = tmp_path / "leg.toml"
    good.write_text(preset_text("cylinder-leg").replace('name = "cylinder-leg"', 'name = "my-leg"'))
    assert load_robot(good).name == "my-leg"


def test_robot_record_round_trip():
    from ikseries.robot import robot_from_record, robot_record
    r = parse_robot(base())
    assert robot_from_record(robot_record(r)) == r
    with pytest.raises(RobotError, match="not a robot record"):
        robot_from_record({"geometry": {"type": "cylinder-leg"}})


def test_products_dsp_makes_the_dsp_family_part_of_the_fit():
    from ikseries.fit.fitter import operand_bits
    from ikseries.robot import fit_record, robot_record, with_hardware
    r = parse_robot(base())
    assert r.fit.products == "exact" and operand_bits(r) is None
    exact = fit_record(robot_record(r))
    assert "products" not in exact and "dsp" not in exact     # records from before fit.products still match
    assert fit_record(robot_record(with_hardware(r, dsp="xc7"))) == exact
    d = base()
    _set(d, "fit.products", "dsp")
    _set(d, "hardware.dsp", "ecp5")
    r = parse_robot(d)
    assert operand_bits(r) == (18, 18)
    rec = fit_record(robot_record(r))
    assert rec["products"] == "dsp" and rec["dsp"] == "ecp5"
    assert fit_record(robot_record(with_hardware(r, dsp="ice40"))) != rec
    assert operand_bits(with_hardware(r, dsp="none")) is None


#: SHA-256 of the canonical JSON of the presets' fit records as the flat records before the
#: description had parts gave them: the plan cache's keys, so plans cached then are still found
FIT_RECORD_SHA256 = {"cylinder-leg": "436b5b95a55deedd49e0888710c881eba52e802cafcd1a6d5d9259dca460bc7d",
                     "planar-arm": "1e538fc33090ae62385b242e5f8d9b8d662a433c4ad45d9e08d71a6ad030f53e"}


@pytest.mark.parametrize("preset", sorted(FIT_RECORD_SHA256))
def test_fit_record_of_a_flat_record_is_the_nested_one(preset):
    from helpers import flat_record
    from ikseries.robot import fit_record, load_preset, robot_from_record, robot_record
    r = load_preset(preset)
    nested = robot_record(r)
    assert set(nested) == {"name", "description", "legs", "geometry", "workspace", "calibration", "fit", "hardware"}
    flat = flat_record(nested)
    assert fit_record(flat) == fit_record(nested) == r.fit_record()
    assert robot_from_record(flat) == r
    key = json.dumps(r.fit_record(), sort_keys=True, separators=(",", ":")).encode()
    assert hashlib.sha256(key).hexdigest() == FIT_RECORD_SHA256[preset]


def test_fit_record_holds_what_the_fit_reads():
    from ikseries.robot import with_fit, with_hardware
    r = parse_robot(base())
    key = r.fit_record()
    assert set(key) == {"geometry", "inputs", "neutral_pose", "pulse_unit_us", "neutral_pulse_pu", "pu_per_degree",
                        "directions", "pulse_min_us", "pulse_max_us", "tolerance_pu", "lowering", "clock_hz"}
    d = base(); d["name"], d["description"], d["legs"] = "other", "another leg", 2
    _set(d, "hardware.pwm_period_us", 10000.0)
    _set(d, "hardware.min_refresh_hz", 10.0)
    assert parse_robot(d).fit_record() == key
    assert with_hardware(r, architecture="folded", multipliers=2, dsp="xc7").fit_record() == key
    assert with_fit(r, tolerance_pu=1.0).fit_record() != key
    assert with_fit(r, lowering="horner").fit_record() != key
    d = base()
    _set(d, "hardware.clock_hz", 96_000_000)
    assert parse_robot(d).fit_record() != key


def test_with_fit_validates():
    from ikseries.robot import with_fit
    r = parse_robot(base())
    with pytest.raises(RobotError, match=r"^fit.tolerance_pu must be > 0 pu, not -1$"):
        with_fit(r, tolerance_pu=-1)
    with pytest.raises(RobotError, match=r"^fit.lowering must be one of mixed, horner, not 'estrin'$"):
        with_fit(r, lowering="estrin")
    with pytest.raises(RobotError, match=r"^fit.tolerance_pu must be > 0.0277778 pu with 24 PWM ticks"):
        with_fit(r, tolerance_pu=0.02)


def test_unknown_field_of_a_flat_record_is_named():
    from helpers import flat_record
    from ikseries.robot import robot_from_record, robot_record
    flat = {**flat_record(robot_record(parse_robot(base()))), "colour": "red"}
    with pytest.raises(RobotError, match=r"^not a robot record: unknown field 'colour'$"):
        robot_from_record(flat)


def test_plan_with_a_flat_robot_record_is_found(tmp_path):
    from helpers import flat_record, tiny_plan
    from ikseries.plancache import PlanLookupError, read_plan
    from ikseries.robot import robot_record, with_fit
    r = parse_robot(base())
    plan = tiny_plan()
    plan.meta["robot_description"] = flat_record(robot_record(r))
    path = tmp_path / "plan.json"
    path.write_text(plan.dumps())
    assert read_plan(r, path, True).dumps() == plan.dumps()
    with pytest.raises(PlanLookupError, match="was fitted for a different robot description than 'cylinder-leg'"):
        read_plan(with_fit(r, tolerance_pu=1.0), path, True)


def _pocket(tibia):
    """A cylinder leg whose femur-tibia reach has a hole of radius |femur - tibia| around the
    femur axis, inside the workspace but between the points of the 9-point grid."""
    d = base()
    d["geometry"].update(neutral_distance=30.0, tibia=tibia)
    d["workspace"]["z"].update(min=-57.0, max=-44.5)
    d["calibration"]["neutral_pose"] = {"r": 20.0, "theta": 0.0, "z": -45.0}
    return d


def test_workspace_unreachable_between_grid_points_is_found():
    import numpy as np
    d = _pocket(60.5)
    r = d["workspace"]
    axes = [np.linspace(r[k]["min"], r[k]["max"], 9) for k in ("r", "theta", "z")]
    from ikseries.kinematics import CylinderLeg
    grid = [g.ravel() for g in np.meshgrid(*axes, indexing="ij")]
    CylinderLeg(30.0, 60.0, 60.5, 30.0, 50.0).ik(*grid)       # the grid alone finds nothing
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert str(e.value) == ("workspace: target (r=22.5, theta=112.5, z=-49.9688) is unreachable: tip distance "
                            "from the femur axis 0.176172 mm must be within [0.5, 120.5] mm")


def test_workspace_that_cannot_be_proven_is_refused():
    """femur = tibia: the reach hole is the single point on the femur axis, never sampled, which
    the reach proof cannot close; the femur angle wraps around it, and that is what is named."""
    with pytest.raises(RobotError) as e:
        parse_robot(_pocket(60.0))
    assert str(e.value).startswith("workspace: servo s2 (femur) angle wraps inside the box: ")


def test_a_box_the_reach_proof_cannot_close_is_refused_in_one_line():
    """Without a wrap on the grid, the reach proof's own message: the box, its cells and what to do."""
    import numpy as np

    from ikseries.kinematics import CylinderLeg
    from ikseries.reach import ReachUnprovenError, prove_box_reachable
    with pytest.raises(ReachUnprovenError) as e:
        prove_box_reachable(CylinderLeg(30.0, 60.0, 60.0, 30.0, 50.0), np.array([0.0, -10.0, -57.0]),
                            np.array([30.0, 10.0, -44.5]), max_cells=50)
    msg = str(e.value)
    assert msg.startswith("could not establish that every target is reachable: after ")
    assert "cells of interval analysis" in msg and "keep the box clear of the reach and joint limits" in msg


def test_presets_are_proven_reachable_in_few_cells():
    """Every closed-form preset's box, by interval analysis (a chain's is checked on a grid, by
    parse_robot)."""
    from ikseries.reach import prove_box_reachable
    from ikseries.robot import load_preset
    for name in preset_names():
        r = load_preset(name)
        if hasattr(r.geometry, "check_box"):    # a chain: no formula for intervals; its own grid check ran
            continue
        cells = prove_box_reachable(r.geometry, r.workspace.lows, r.workspace.highs)
        assert cells <= 1000, name


def test_with_hardware_checks_the_refresh_bound():
    from ikseries.robot import with_hardware
    r = parse_robot(base())
    with pytest.raises(RobotError, match=r"^hardware.min_refresh_hz must be at most 8e\+06 Hz \(one target per "
                                         r"clock cycle at hardware.clock_hz = 48000000 shared by legs = 6\), not 10000000.0$"):
        with_hardware(r, legs=6, architecture="auto", min_refresh_hz=1e7)


def _planar_box(x, y):
    d = tomllib.loads(preset_text("planar-arm"))
    d["geometry"]["phi"] = 90.0
    d["workspace"]["x"].update(min=float(x[0]), max=float(x[1]))
    d["workspace"]["y"].update(min=float(y[0]), max=float(y[1]))
    d["calibration"]["neutral_pose"] = {"x": sum(x) / 2, "y": sum(y) / 2}
    d["calibration"]["pu_per_degree"] = 0.1          # pulses in range for any angle: the wrap alone fails
    return d


def test_an_angle_that_wraps_inside_the_box_is_refused_where_it_wraps():
    """The planar arm's link 2 points along +x inside this box: its absolute angle jumps from
    about 0 to about 360 deg between two grid neighbours, named in one line before any fit
    (not the reach proof's open cells)."""
    with pytest.raises(RobotError) as e:
        parse_robot(_planar_box((0.0, 25.0), (35.0, 55.0)))
    assert str(e.value) == ("workspace: servo s2 (link2) angle wraps inside the box: 4.7 deg at target "
                            "(x=3.125, y=35), 358.6 deg at its neighbour (x=6.25, y=35) (a jump of a full turn "
                            "no servo can follow); move the box off the angle's wrap")
    parse_robot(_planar_box((-10.0, 10.0), (40.0, 60.0)))      # link 2 stays above +x: accepted
