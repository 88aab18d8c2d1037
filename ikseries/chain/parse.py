"""The ``[geometry]`` table of a chain robot: ``type = "chain"`` (joints as tables) or
``type = "urdf"`` (joints read from a URDF file, :mod:`ikseries.chain.urdf`).

Every field is checked here, each with a one-line :class:`~ikseries.robot_parts.RobotError`
naming it and the bad value, before any solve runs.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..robot_parts import RobotError, field_number, refuse_extra
from .model import TARGETS, Chain, Joint, Tool

__all__ = ["CHAIN_TYPES", "parse_chain", "vector", "check_counts", "parse_tool", "parse_target", "finish"]

#: geometry.type values this module parses
CHAIN_TYPES = ("chain", "urdf")
#: the fields both types share
COMMON_FIELDS = ("type", "joints", "tip", "target", "neutral", "tool")
JOINT_FIELDS = ("name", "axis", "range", "xyz", "rpy", "zero_offset", "home")
#: how far from 1 an axis's norm may be (it is then normalised)
AXIS_NORM_TOL = 1e-6


def vector(table, key, path, n=3, default=None) -> tuple[float, ...]:
    """``table[key]`` checked to be a list of ``n`` finite numbers (``default`` when absent)."""
    if key not in table and default is not None:
        return default
    v = table.get(key)
    if (not isinstance(v, list) or len(v) != n
            or any(isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a) for a in v)):
        raise RobotError(f"{path}{key} must be a list of {n} finite numbers, not {v!r}")
    return tuple(float(a) for a in v)


def _joint(t, i: int, names: set) -> Joint:
    p = f"geometry.joints[{i}]."
    if not isinstance(t, dict):
        raise RobotError(f"geometry.joints[{i}] must be a table ([[geometry.joints]]), not {t!r}")
    refuse_extra(t, JOINT_FIELDS, p)
    name = t.get("name")
    if not isinstance(name, str) or not name or name in names:
        raise RobotError(f"{p}name must be a non-empty string unlike the other joints' names, not {name!r}")
    names.add(name)
    axis = vector(t, "axis", p)
    norm = math.sqrt(sum(a * a for a in axis))
    if abs(norm - 1.0) > AXIS_NORM_TOL:
        raise RobotError(f"{p}axis must be a unit vector (norm 1), not {t['axis']!r} (norm {norm:.6g})")
    rng = vector(t, "range", p, 2)
    if not rng[0] < rng[1]:
        raise RobotError(f"{p}range must be [min, max] deg with min < max, not {t['range']!r}")
    home = float(field_number(t, "home", p, default=0.0))
    if not rng[0] <= home <= rng[1]:
        raise RobotError(f"{p}home must lie within its range [{rng[0]:g}, {rng[1]:g}] deg, not {home!r}")
    return Joint(name, tuple(a / norm for a in axis), rng, vector(t, "xyz", p, default=(0.0, 0.0, 0.0)),
                 vector(t, "rpy", p, default=(0.0, 0.0, 0.0)), float(field_number(t, "zero_offset", p, default=0.0)),
                 home)


def parse_tool(geo, joint_names) -> Tool | None:
    """The optional ``[geometry.tool]`` table."""
    t = geo.get("tool")
    if t is None:
        return None
    if not isinstance(t, dict):
        raise RobotError(f"geometry.tool must be a table, not {t!r}")
    refuse_extra(t, ("joints", "angle"), "geometry.tool.")
    js = t.get("joints")
    if (not isinstance(js, list) or not js or len(set(map(str, js))) != len(js)
            or any(j not in joint_names for j in js)):
        raise RobotError(f"geometry.tool.joints must be a non-empty list of distinct joint names "
                         f"(of {', '.join(joint_names)}), not {js!r}")
    angle = t.get("angle")
    if angle == "input":
        return Tool(tuple(js), None)
    if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not math.isfinite(angle):
        raise RobotError(f"geometry.tool.angle must be a finite number (deg) or \"input\", not {angle!r}")
    return Tool(tuple(js), float(angle))


def check_counts(target, tool, n_joints) -> None:
    """One joint per solved quantity (tip coordinates, tool angle): the IK is a square system."""
    need = (3 if target == "cylindrical" else len(target)) + (tool is not None)
    if n_joints != need:
        what = f"target {target!r}" + (" with geometry.tool" if tool is not None else "")
        raise RobotError(f"geometry.joints must be {need} joints for {what} (one per solved coordinate), "
                         f"not {n_joints}")


def parse_target(geo) -> tuple[str, tuple | None]:
    target = geo.get("target", "xyz")
    if target not in TARGETS:
        raise RobotError(f"geometry.target must be one of {', '.join(TARGETS)}, not {target!r}")
    if target == "cylindrical":
        return target, vector(geo, "neutral", "geometry.")
    if "neutral" in geo:
        raise RobotError(f"geometry.neutral is only taken with geometry.target = \"cylindrical\", "
                         f"not with {target!r}")
    return target, None


def parse_chain(geo: dict, base_dir=None) -> Chain:
    """The :class:`Chain` of a ``[geometry]`` table of type "chain" or "urdf"; a URDF ``file``
    is relative to ``base_dir`` (the robot description's folder; the current one if None)."""
    if geo.get("type") == "urdf":
        from .urdf import parse_urdf_table
        return parse_urdf_table(geo, Path(base_dir) if base_dir is not None else Path("."))
    refuse_extra(geo, COMMON_FIELDS, "geometry.")
    target, neutral = parse_target(geo)
    js = geo.get("joints")
    if not isinstance(js, list) or not js:
        raise RobotError(f"geometry.joints must be a non-empty list of tables ([[geometry.joints]]), not {js!r}")
    names: set = set()
    joints = tuple(_joint(t, i, names) for i, t in enumerate(js))
    tool = parse_tool(geo, [j.name for j in joints])
    check_counts(target, tool, len(joints))
    return finish(Chain(joints, vector(geo, "tip", "geometry.", default=(0.0, 0.0, 0.0)), target, neutral, tool))


def finish(chain: Chain) -> Chain:
    """``chain`` once its home pose is checked to be off the singular poses."""
    from .checks import home_error
    problem = home_error(chain)
    if problem:
        raise RobotError(f"geometry.joints: {problem}")
    return chain
