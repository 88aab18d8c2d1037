"""A chain read from a URDF file (``[geometry] type = "urdf"``) with the PyPI parser yourdfpy.

The TOML names the file (relative to the robot description), the revolute ``joints`` from the
base to the tip and the ``tip`` link; the chain's base frame is the parent link of the first
joint. Fixed joints between two of the named joints, or between the last one and the tip
link, are folded into the next joint's origin or the tip offset. Angles are URDF's (radians
in the file, a joint's zero where URDF has it), with the range from its ``<limit>``; lengths
are metres in the file and millimetres in the chain.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..robot_parts import RobotError, refuse_extra
from .frames import matrix_rpy
from .model import Chain, Joint
from .parse import COMMON_FIELDS, check_counts, finish, parse_target, parse_tool, vector

__all__ = ["parse_urdf_table", "load_urdf"]

URDF_FIELDS = (*COMMON_FIELDS, "file", "home")
#: URDF lengths are metres, a chain's millimetres
MM_PER_M = 1000.0


def load_urdf(path: Path, label: str):
    """The yourdfpy model of ``path``; ``label`` names the file in messages. The file must be
    well-formed XML (yourdfpy alone would recover a broken file silently)."""
    from lxml import etree
    import yourdfpy
    if not path.is_file():
        raise RobotError(f"geometry.file must name a URDF file, not {label!r} (no file {str(path)!r})")
    try:
        etree.parse(str(path))
        with path.open("rb") as f:
            return yourdfpy.URDF.load(f, build_scene_graph=False, load_meshes=False,
                                      build_collision_scene_graph=False, load_collision_meshes=False)
    except (etree.LxmlError, ValueError, TypeError, AttributeError, OSError) as e:
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise RobotError(f"geometry.file {label!r} is not a readable URDF file: {first}") from None


def _fixed_path(model, parent: str, child: str):
    """Transform (4 x 4) from link ``parent`` to link ``child`` through fixed joints only, or None."""
    by_child = {j.child: j for j in model.joint_map.values()}
    m, link = np.eye(4), child
    while link != parent:
        j = by_child.get(link)
        if j is None or j.type != "fixed":
            return None
        m = (j.origin if j.origin is not None else np.eye(4)) @ m
        link = j.parent
    return m


def _joint(model, name, i, prev_child, home) -> tuple[Joint, str]:
    p = f"geometry.joints[{i}]"
    j = model.joint_map.get(name) if isinstance(name, str) else None
    if j is None:
        raise RobotError(f"{p} must name a joint of the URDF file (one of {', '.join(sorted(model.joint_map))}), "
                         f"not {name!r}")
    if j.type != "revolute":
        raise RobotError(f"{p}: URDF joint {name!r} must be revolute (with a <limit>), not {j.type!r}")
    if j.limit is None or j.limit.lower is None or j.limit.upper is None or not j.limit.lower < j.limit.upper:
        raise RobotError(f"{p}: URDF joint {name!r} must have a <limit> with lower < upper")
    origin = j.origin if j.origin is not None else np.eye(4)
    if prev_child is not None:
        link = _fixed_path(model, prev_child, j.parent)
        if link is None:
            raise RobotError(f"{p}: URDF joint {name!r} must follow the previous joint (its parent link "
                             f"{j.parent!r} must be, or hang by fixed joints from, link {prev_child!r})")
        origin = link @ origin
    axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=np.float64)
    rng = (float(np.degrees(j.limit.lower)), float(np.degrees(j.limit.upper)))
    if not rng[0] <= home <= rng[1]:
        raise RobotError(f"geometry.home[{i}] must lie within joint {name!r}'s range [{rng[0]:g}, {rng[1]:g}] deg, "
                         f"not {home!r}")
    joint = Joint(name, tuple(axis / np.linalg.norm(axis)), rng, tuple(MM_PER_M * float(v) for v in origin[:3, 3]),
                  matrix_rpy(origin[:3, :3].tolist()), 0.0, home)
    return joint, j.child


def _homes(geo, n) -> tuple[float, ...]:
    """The optional ``home`` angles (deg, one per joint; 0 by default)."""
    return vector(geo, "home", "geometry.", n, default=(0.0,) * n)


def parse_urdf_table(geo: dict, base_dir: Path) -> Chain:
    """The :class:`Chain` of a ``[geometry] type = "urdf"`` table."""
    refuse_extra(geo, URDF_FIELDS, "geometry.")
    target, neutral = parse_target(geo)
    names = geo.get("joints")
    if not isinstance(names, list) or not names or len(set(map(repr, names))) != len(names):
        raise RobotError(f"geometry.joints must be a non-empty list of distinct URDF joint names, not {names!r}")
    tool = parse_tool(geo, [str(n) for n in names])
    check_counts(target, tool, len(names))
    homes = _homes(geo, len(names))
    file = geo.get("file")
    if not isinstance(file, str) or not file:
        raise RobotError(f"geometry.file must be the URDF file's path (relative to the robot description), "
                         f"not {file!r}")
    tip = geo.get("tip")
    if not isinstance(tip, str) or not tip:
        raise RobotError(f"geometry.tip must name the URDF tip link, not {tip!r}")
    model = load_urdf(base_dir / file, file)
    joints, child = [], None
    for i, (name, home) in enumerate(zip(names, homes)):
        j, child = _joint(model, name, i, child, home)
        joints.append(j)
    if tip not in model.link_map:
        raise RobotError(f"geometry.tip must name a link of the URDF file (one of {', '.join(sorted(model.link_map))}), "
                         f"not {tip!r}")
    offset = _fixed_path(model, child, tip)
    if offset is None:
        raise RobotError(f"geometry.tip: link {tip!r} must be, or hang by fixed joints from, the last joint's "
                         f"child link {child!r}")
    return finish(Chain(tuple(joints), tuple(MM_PER_M * float(v) for v in offset[:3, 3]), target, neutral, tool))
