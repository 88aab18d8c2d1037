"""Generic serial chains: FK, the continued Newton IK, the workspace checks, URDF, validation."""
import copy
import math
import re
import tomllib

import numpy as np
import pytest

from ikseries.chain import Chain, Joint, Tool
from ikseries.chain.checks import ChainBoxError, check_box
from ikseries.chain.solve import TOL_MM
from ikseries.hexapod_leg import HexapodLeg
from ikseries.kinematics import NUMPY_MATH, CylinderLeg, UnreachableError
from ikseries.robot import RobotError, load_robot, parse_robot, preset_text, robot_from_record, robot_record

#: the hexapod-leg preset's leg as a chain: the coxa yaws about z at the body underside
#: (78 mm above the ground, the target frame's z = 0); the femur pitches about +y, so a
#: positive angle lowers it (HexapodLeg's s2); the tibia turns about +y by 90 deg more
#: (its zero: at right angles to the femur, HexapodLeg's s3)
HEXAPOD_CHAIN = {
    "type": "chain", "tip": [130.0, 0.0, 0.0],
    "joints": [{"name": "coxa", "axis": [0, 0, 1], "xyz": [0, 0, 78], "range": [-90, 90]},
               {"name": "femur", "axis": [0, 1, 0], "xyz": [15, 0, 0], "range": [-90, 90], "home": -40},
               {"name": "tibia", "axis": [0, 1, 0], "xyz": [80, 0, 0], "zero_offset": -90, "range": [0, 90],
                "home": 40}]}

#: the cylinder-leg preset's leg: its frame has Z down, so the femur's elevation (up) is a
#: turn about +y, the knee's bend (down) one about -y; the S2 axis is z_datum above the datum
CYLINDER_CHAIN = {
    "type": "chain", "tip": [90.0, 0.0, 0.0], "target": "cylindrical", "neutral": [100.0, 0.0, 0.0],
    "joints": [{"name": "coxa", "axis": [0, 0, 1], "range": [-90, 90]},
               {"name": "femur", "axis": [0, 1, 0], "xyz": [30, 0, -50], "range": [-180, 180], "home": 30},
               {"name": "tibia", "axis": [0, -1, 0], "xyz": [60, 0, 0], "range": [0, 180], "home": 90}]}


def _robot_data(preset, geometry):
    data = tomllib.loads(preset_text(preset))
    data["geometry"] = copy.deepcopy(geometry)
    return data


@pytest.fixture(scope="module")
def hexapod_chain():
    return parse_robot(_robot_data("hexapod-leg", HEXAPOD_CHAIN))


def _grid(robot, n):
    axes = [np.linspace(i.min, i.max, n) for i in robot.workspace.inputs]
    return tuple(g.ravel() for g in np.meshgrid(*axes, indexing="ij"))


def _planar(l1=50.0, l2=30.0, ranges=((-170, 170), (-170, 170)), home=(0, 90)):
    """A 2R arm in the x-z plane (both axes +y)."""
    return Chain((Joint("shoulder", (0, 1, 0), ranges[0], home=home[0]),
                  Joint("elbow", (0, 1, 0), ranges[1], xyz=(l1, 0, 0), home=home[1])), (l2, 0, 0), "xz")


# -- forward kinematics -----------------------------------------------------------------------
def test_fk_of_a_planar_arm_is_the_hand_computed_pose():
    # about +y a positive turn takes x towards -z
    x, z = _planar().fk(30.0, 60.0)
    assert x == pytest.approx(50 * math.cos(math.radians(30)), abs=1e-12)
    assert z == pytest.approx(-50 * math.sin(math.radians(30)) - 30, abs=1e-12)


def test_fk_applies_origin_rotation_offset_and_zero_offset():
    # joint 2's frame is turned 90 deg about z (rpy), so its axis +x is the base's +y; with a
    # zero offset of -30 deg (the servo reads 30 deg less than the joint turns) at angle 60 it turns 90 deg: the 40 mm tip along its x (base +y)
    # stays put, a tip along its y (base -x) would go to base z
    c = Chain((Joint("yaw", (0, 0, 1), (-90, 90)),
               Joint("roll", (1, 0, 0), (-90, 90), xyz=(10, 0, 5), rpy=(0, 0, 90), zero_offset=-30)),
              (0, 20, 0), "xy")
    x, y = c.fk(0.0, 60.0)
    tip, _ = c.kinematics(NUMPY_MATH, 0.0, 60.0)
    assert (float(x), float(y)) == pytest.approx((10.0, 0.0), abs=1e-12)
    assert float(tip[2]) == pytest.approx(5.0 + 20.0, abs=1e-12)


def test_fk_of_the_hexapod_chain_is_the_closed_form_fk(hexapod_chain):
    rng = np.random.default_rng(3)
    q = [rng.uniform(lo, hi, 500) for lo, hi in HexapodLeg().joint_ranges]
    for a, b in zip(hexapod_chain.geometry.fk(*q), HexapodLeg().fk(*q)):
        assert np.max(np.abs(a - b)) < 1e-12


# -- the issue's agreement test: the chain pins the closed forms' joint conventions -------------
def test_hexapod_chain_ik_agrees_with_the_closed_form_over_its_workspace(hexapod_chain):
    pts = _grid(hexapod_chain, 15)
    for a, b in zip(hexapod_chain.geometry.ik(*pts), HexapodLeg().ik(*pts)):
        assert np.max(np.abs(a - b)) < 1e-9


def test_cylinder_chain_ik_agrees_with_the_closed_form_over_its_workspace():
    robot = parse_robot(_robot_data("cylinder-leg", CYLINDER_CHAIN))
    assert robot.geometry.inputs == ("r", "theta", "z") and robot.geometry.input_units == ("mm", "deg", "mm")
    pts = _grid(robot, 13)
    for a, b in zip(robot.geometry.ik(*pts), CylinderLeg().ik(*pts)):
        assert np.max(np.abs(a - b)) < 1e-9


# -- IK round trips ---------------------------------------------------------------------------
def _fk_residual(chain, targets):
    return max(float(np.max(np.abs(a - b))) for a, b in zip(chain.fk(*chain.ik(*targets)), targets))


def test_ik_round_trip_on_random_targets(hexapod_chain):
    rng = np.random.default_rng(7)
    ws = hexapod_chain.workspace
    targets = [rng.uniform(lo, hi, 2000) for lo, hi in zip(ws.lows, ws.highs)]
    assert _fk_residual(hexapod_chain.geometry, targets) <= TOL_MM


def _arm4(angle=None):
    """Base yaw, then shoulder, elbow and wrist pitch; the tool's pitch is their sum."""
    return Chain((Joint("base", (0, 0, 1), (-90, 90)),
                  Joint("shoulder", (0, -1, 0), (-10, 170), xyz=(0, 0, 40), home=60),
                  Joint("elbow", (0, -1, 0), (-170, 0), xyz=(80, 0, 0), home=-90),
                  Joint("wrist", (0, -1, 0), (-120, 120), xyz=(80, 0, 0))),
                 (30, 0, 0), "xyz", None, Tool(("shoulder", "elbow", "wrist"), angle))


@pytest.mark.parametrize("angle", [-30.0, None])
def test_four_dof_chain_holds_or_takes_its_tool_angle(angle):
    c = _arm4(angle)
    rng = np.random.default_rng(11)
    targets = [rng.uniform(60, 120, 500), rng.uniform(-40, 40, 500), rng.uniform(0, 60, 500)]
    if angle is None:
        assert c.inputs == ("x", "y", "z", "phi") and c.input_units[-1] == "deg"
        targets.append(rng.uniform(-40, -20, 500))
    q = c.ik(*targets)
    assert np.max(np.abs(q[1] + q[2] + q[3] - (targets[3] if angle is None else angle))) < 1e-9
    assert _fk_residual(c, targets) <= TOL_MM


def test_record_round_trip_gives_the_same_chain(hexapod_chain):
    again = robot_from_record(robot_record(hexapod_chain))
    assert again.geometry == hexapod_chain.geometry and robot_record(again)["geometry"]["type"] == "chain"


def test_angles_runs_on_floats_and_the_certifiers_namespaces_only(hexapod_chain):
    from types import SimpleNamespace
    g = hexapod_chain.geometry
    assert np.allclose(g.angles(NUMPY_MATH, 74.0, 0.0, 0.0), g.ik(74.0, 0.0, 0.0), atol=1e-12)
    with pytest.raises(TypeError, match=r"^a chain geometry's IK is numeric \(Newton\): it is evaluated on float64 "
                                        r"arrays \(NUMPY_MATH\) or enclosed over intervals \(ikseries.fit.interval.MATH, "
                                        r"ikseries.fit.centred.MATH\), not over the math namespace SimpleNamespace$"):
        g.angles(SimpleNamespace(cos=np.cos, sin=np.sin), 74.0, 0.0, 0.0)


# -- URDF -----------------------------------------------------------------------------------------
LEG_URDF = """<?xml version="1.0"?>
<robot name="leg">
  <link name="body"/><link name="coxa_link"/><link name="femur_link"/><link name="knee"/>
  <link name="tibia_link"/><link name="foot"/>
  <joint name="coxa" type="revolute">
    <parent link="body"/><child link="coxa_link"/>
    <origin xyz="0 0 0.078"/><axis xyz="0 0 1"/>
    <limit lower="-1.5707963267948966" upper="1.5707963267948966" effort="1" velocity="1"/>
  </joint>
  <joint name="femur" type="revolute">
    <parent link="coxa_link"/><child link="femur_link"/>
    <origin xyz="0.015 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1.5707963267948966" upper="1.5707963267948966" effort="1" velocity="1"/>
  </joint>
  <joint name="knee_mount" type="fixed">
    <parent link="femur_link"/><child link="knee"/>
    <origin xyz="0.08 0 0" rpy="0 1.5707963267948966 0"/>
  </joint>
  <joint name="tibia" type="revolute">
    <parent link="knee"/><child link="tibia_link"/>
    <axis xyz="0 1 0"/>
    <limit lower="0" upper="1.5707963267948966" effort="1" velocity="1"/>
  </joint>
  <joint name="ankle" type="fixed">
    <parent link="tibia_link"/><child link="foot"/><origin xyz="0.13 0 0"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="foot"/><child link="pad"/>
    <limit lower="0" upper="0.01" effort="1" velocity="1"/>
  </joint>
  <link name="pad"/>
</robot>
"""
URDF_GEOMETRY = {"type": "urdf", "file": "leg.urdf", "joints": ["coxa", "femur", "tibia"], "tip": "foot",
                 "home": [0, -40, 40]}


def _write_urdf_robot(tmp_path, geometry=URDF_GEOMETRY, urdf=LEG_URDF):
    (tmp_path / "leg.urdf").write_text(urdf)
    data = _robot_data("hexapod-leg", geometry)
    lines = [f"{k} = {v!r}".replace("'", '"') for k, v in data["geometry"].items()]
    toml = preset_text("hexapod-leg").replace('type = "hexapod-leg"', "\n".join(lines))
    toml = re.sub(r"^(coxa|femur|tibia|body_height|joint_ranges|zero_offsets|angle_directions) = .*$", "", toml,
                  flags=re.M)
    (tmp_path / "leg.toml").write_text(toml)
    return load_robot(tmp_path / "leg.toml")


def test_urdf_leg_gives_the_angles_of_the_toml_chain(tmp_path, hexapod_chain):
    robot = _write_urdf_robot(tmp_path)
    pts = _grid(robot, 7)
    for a, b in zip(robot.geometry.ik(*pts), hexapod_chain.geometry.ik(*pts)):
        assert np.max(np.abs(a - b)) < 1e-12
    assert robot.geometry.servo_names == ("coxa", "femur", "tibia")


@pytest.mark.parametrize("change, message", [
    ({"file": "nope.urdf"}, r"geometry.file must name a URDF file, not 'nope.urdf' \(no file '.*nope.urdf'\)"),
    ({"joints": ["coxa", "hip", "tibia"]},
     r"geometry.joints\[1\] must name a joint of the URDF file \(one of ankle, coxa, femur, knee_mount, "
     r"slide, tibia\), not 'hip'"),
    ({"joints": ["coxa", "femur", "knee_mount"]},
     r"geometry.joints\[2\]: URDF joint 'knee_mount' must be revolute \(with a <limit>\), not 'fixed'"),
    ({"joints": ["coxa", "tibia", "femur"]},
     r"geometry.joints\[1\]: URDF joint 'tibia' must follow the previous joint \(its parent link 'knee' "
     r"must be, or hang by fixed joints from, link 'coxa_link'\)"),
    ({"tip": "toe"}, r"geometry.tip must name a link of the URDF file \(one of body, coxa_link, femur_link, "
                     r"foot, knee, pad, tibia_link\), not 'toe'"),
    ({"tip": "pad"}, r"geometry.tip: link 'pad' must be, or hang by fixed joints from, the last joint's "
                     r"child link 'tibia_link'"),
    ({"home": [0, -40, 100]}, r"geometry.home\[2\] must lie within joint 'tibia''s range \[0, 90\] deg, "
                              r"not 100.0"),
    ({"home": [0, -40]}, r"geometry.home must be a list of 3 finite numbers, not \[0, -40\]"),
    ({"colour": "red"}, r"unknown field geometry.colour \(expected one of: file, home, joints, neutral, "
                        r"target, tip, tool, type\)"),
])
def test_bad_urdf_geometry_is_one_line(tmp_path, change, message):
    with pytest.raises(RobotError, match=f"^{message}$"):
        _write_urdf_robot(tmp_path, {**URDF_GEOMETRY, **change})


def test_unreadable_urdf_file_is_one_line(tmp_path):
    with pytest.raises(RobotError, match=r"^geometry.file 'leg.urdf' is not a readable URDF file: .*line 1"):
        _write_urdf_robot(tmp_path, urdf="<robot name='leg'><link name=")


# -- workspace checks ------------------------------------------------------------------------------
def test_near_singular_home_pose_is_refused():
    geo = copy.deepcopy(CYLINDER_CHAIN)
    geo["joints"][2]["home"] = 0                # the knee straight
    with pytest.raises(RobotError, match=r"^geometry.joints: the home pose \(coxa=0, femur=30, tibia=0\) deg is "
                                         r"near-singular: smallest singular value of the Jacobian [\d.e-]+ mm/rad, "
                                         r"0.00% of the chain's reach 208.31 mm \(at least 5% is needed\); give the "
                                         r"joints home angles off it$"):
        parse_robot(_robot_data("cylinder-leg", geo))


def test_near_singular_box_is_refused_naming_where():
    # 50 + 30 mm arm: at x = 79.9 the elbow is almost straight (5.9 deg)
    with pytest.raises(ChainBoxError, match=r"^the chain is near-singular at target \(x=79.9, z=-0.0001\): smallest "
                                            r"singular value of the Jacobian 1.81 mm/rad, 2.27% of the "
                                            r"chain's reach 80 mm \(at least 5% is needed\); keep the box off "
                                            r"the singular poses$"):
        check_box(_planar(ranges=((-170, 170), (0, 170))), [40, -0.0001], [79.9, 0.0001])
    check_box(_planar(ranges=((-170, 170), (0, 170))), [40, 0], [79, 0.0001])


def test_target_across_a_singular_pose_is_reported_as_another_branch():
    # 60 + 30 mm arm: the path from the home tip (60, -30) to (-50, 10) passes the folded pose
    c = _planar(60, 30)
    with pytest.raises(UnreachableError, match=r"^target \(x=-50, z=10\) is unreachable: the path from the home "
                                               r"pose \(shoulder=0, elbow=90\) deg crosses a singular pose near "
                                               r"\(x=-32.4, z=3.6\) \(84% of the way; the Jacobian's determinant "
                                               r"changes sign there\), so the target is on another branch$"):
        c.ik(-50.0, 10.0)


def test_second_solution_inside_the_ranges_is_reported():
    geo = copy.deepcopy(CYLINDER_CHAIN)
    geo["joints"][2]["range"] = [-180, 180]     # the knee may bend either way
    with pytest.raises(RobotError, match=r"^workspace: a second solution inside the joint ranges at target "
                                         r"\(r=0, theta=-180, z=0\): \(coxa=[-\d.e]+, femur=-\d+.\d+, "
                                         r"tibia=-\d+.\d+\) deg besides the home branch's \(coxa=0, "
                                         r"femur=\d+.\d+, tibia=\d+.\d+\) deg; narrow the joint ranges to "
                                         r"exclude it$"):
        parse_robot(_robot_data("cylinder-leg", geo))


def test_unreachable_target_and_joint_out_of_range_are_named():
    c = _planar(ranges=((-170, 170), (0, 170)))
    with pytest.raises(UnreachableError, match=r"^target \(x=100, z=0\) is unreachable: the Newton IK continued "
                                               r"from the home pose \(shoulder=0, elbow=90\) deg leaves the tip "
                                               r"[\d.]+ mm from it \(out of reach on the home pose's branch\)$"):
        c.ik([60.0, 100.0], [0.0, 0.0])
    narrow = _planar(ranges=((-30, 30), (0, 170)))
    with pytest.raises(UnreachableError, match=r"^target \(x=0, z=-60\) is unreachable: shoulder angle "
                                               r"[\d.]+ deg must be within \[-30, 30\] deg \(geometry.joints\[0\].range\)$"):
        narrow.ik(0.0, -60.0)


# -- validation ------------------------------------------------------------------------------------
def _joint_change(i, **kw):
    geo = copy.deepcopy(HEXAPOD_CHAIN)
    geo["joints"][i].update(kw)
    return geo


@pytest.mark.parametrize("geometry, message", [
    ({**HEXAPOD_CHAIN, "joints": []}, r"geometry.joints must be a non-empty list of tables \(\[\[geometry.joints\]\]\), not \[\]"),
    ({**HEXAPOD_CHAIN, "joints": [1]}, r"geometry.joints\[0\] must be a table \(\[\[geometry.joints\]\]\), not 1"),
    (_joint_change(1, name="coxa"), r"geometry.joints\[1\].name must be a non-empty string unlike the other "
                                    r"joints' names, not 'coxa'"),
    (_joint_change(0, axis=[0, 0, 2]), r"geometry.joints\[0\].axis must be a unit vector \(norm 1\), not "
                                       r"\[0, 0, 2\] \(norm 2\)"),
    (_joint_change(0, axis=[0, 1]), r"geometry.joints\[0\].axis must be a list of 3 finite numbers, not \[0, 1\]"),
    (_joint_change(2, range=[90, 0]), r"geometry.joints\[2\].range must be \[min, max\] deg with min < max, "
                                      r"not \[90, 0\]"),
    (_joint_change(2, home=100), r"geometry.joints\[2\].home must lie within its range \[0, 90\] deg, not 100.0"),
    (_joint_change(1, xyz=[15, 0, "a"]), r"geometry.joints\[1\].xyz must be a list of 3 finite numbers, not "
                                         r"\[15, 0, 'a'\]"),
    (_joint_change(1, zero_offset=True), r"geometry.joints\[1\].zero_offset must be a number, not True"),
    (_joint_change(1, length=3), r"unknown field geometry.joints\[1\].length \(expected one of: axis, home, "
                                 r"name, range, rpy, xyz, zero_offset\)"),
    ({**HEXAPOD_CHAIN, "target": "xzy"}, r"geometry.target must be one of xyz, xy, xz, yz, cylindrical, not 'xzy'"),
    ({**HEXAPOD_CHAIN, "target": "xz"}, r"geometry.joints must be 2 joints for target 'xz' \(one per solved "
                                        r"coordinate\), not 3"),
    ({**HEXAPOD_CHAIN, "neutral": [0, 0, 0]}, r"geometry.neutral is only taken with geometry.target = "
                                              r"\"cylindrical\", not with 'xyz'"),
    ({**HEXAPOD_CHAIN, "target": "cylindrical"}, r"geometry.neutral must be a list of 3 finite numbers, not None"),
    ({**HEXAPOD_CHAIN, "tip": [1, 2]}, r"geometry.tip must be a list of 3 finite numbers, not \[1, 2\]"),
    ({**HEXAPOD_CHAIN, "tool": {"joints": ["femur", "knee"], "angle": 0}},
     r"geometry.tool.joints must be a non-empty list of distinct joint names \(of coxa, femur, tibia\), "
     r"not \['femur', 'knee'\]"),
    ({**HEXAPOD_CHAIN, "tool": {"joints": ["femur", "tibia"], "angle": "up"}},
     r"geometry.tool.angle must be a finite number \(deg\) or \"input\", not 'up'"),
    ({**HEXAPOD_CHAIN, "tool": {"joints": ["femur", "tibia"], "angle": 0}},
     r"geometry.joints must be 4 joints for target 'xyz' with geometry.tool \(one per solved coordinate\), not 3"),
    ({**HEXAPOD_CHAIN, "links": 3}, r"unknown field geometry.links \(expected one of: joints, neutral, target, "
                                    r"tip, tool, type\)"),
])
def test_bad_chain_geometry_is_one_line(geometry, message):
    with pytest.raises(RobotError, match=f"^{message}$"):
        parse_robot(_robot_data("hexapod-leg", geometry))
