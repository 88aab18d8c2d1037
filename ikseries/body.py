"""Bodies: a robot as a body with legs, each with a mount pose and a side (``[body]``).

Frames (mm, degrees), for a geometry whose target is a Cartesian (x, y, z):

- **body frame**: the robot's own; any right-handed frame the description chooses (the
  presets: x forward, y left, z up, origin on the ground below the body centre);
- **mount frame** of a leg: the body frame translated to the leg's mount ``(x, y, z)`` and
  turned by its ``yaw`` about z, so that its x axis is the leg's rest direction (``p_mount =
  R(-yaw) (p_body - mount)``). The robot core takes targets in this frame;
- **leg frame**: the mount frame, mirrored in its x-z plane (y -> -y) for a left leg; the same
  as the mount frame for a right leg. A left leg is the right leg's mirror image, so in its leg
  frame it is the right leg: the geometry, the workspace box and the fitted plan are the right
  leg's, one for all legs.

The mirror is undone in hardware by the channel table (:mod:`ikseries.channels`, which also
reads the per-channel calibration). So the workspace's y range must be symmetric about 0 when
there are left legs (a negated in-range target must be in range); the description is refused
otherwise (rather than fitting the union of the box and its mirror, which would cost accuracy
on every leg).
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np

from .calibration import ServoOverride
from .robot_parts import RobotError, field_number, field_table, refuse_extra

__all__ = ["BodyLeg", "Body", "SIDES", "MIRROR_INPUT", "body_to_mount", "mount_to_body", "mirror", "body_to_leg",
           "leg_to_body"]

SIDES = ("right", "left")
#: the leg-frame input a left leg's mirror negates
MIRROR_INPUT = "y"
#: the target inputs a body needs (mm): the transforms are of Cartesian points
BODY_INPUTS = ("x", "y", "z")
LEG_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,15}")
_LEG_FIELDS = ("name", "x", "y", "z", "yaw", "side")
#: a leg's servo override: its own linear map of the plan's servo angle, limits and trim
_MAP_FIELDS = ("zero_pulse_us", "neutral_pulse_us", "us_per_degree")


@dataclass(frozen=True)
class BodyLeg:
    """One leg of a body: its name, its mount (the mount frame's origin in the body frame, mm;
    its x axis ``yaw`` degrees from the body's x, counter-clockwise seen from +z) and side."""
    name: str
    x: float
    y: float
    z: float
    yaw: float
    side: str
    servos: tuple[tuple[str, ServoOverride], ...] = ()    # the leg's own servo calibrations

    @property
    def mirrored(self) -> bool:
        return self.side == "left"

    def servo(self, name: str) -> ServoOverride | None:
        """The leg's own calibration of servo ``name`` (None: the leg's default)."""
        return dict(self.servos).get(name)

    def record(self) -> dict:
        d = {f: getattr(self, f) for f in _LEG_FIELDS}
        if self.servos:    # left out without overrides: the records (and manifests) they predate
            d["servos"] = {name: o.record() for name, o in self.servos}
        return d


@dataclass(frozen=True)
class Body:
    """The legs of a robot in channel order (``[[body.legs]]``): leg ``l`` servo ``j`` is
    channel ``l * servos + j``."""
    legs: tuple[BodyLeg, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(leg.name for leg in self.legs)

    def leg(self, name: str) -> tuple[int, BodyLeg]:
        """(index, leg) of the leg called ``name``."""
        if name not in self.names:
            raise RobotError(f"leg must be one of {', '.join(self.names)}, not {name!r}")
        k = self.names.index(name)
        return k, self.legs[k]

    @classmethod
    def parse(cls, table: dict, legs, geometry, workspace) -> "Body":
        """Validate ``[body]`` (``legs``: the description's ``legs`` value, None when absent)."""
        refuse_extra(table, ["legs"], "body.")
        items = table.get("legs")
        if not isinstance(items, list) or not items or not all(isinstance(t, dict) for t in items):
            raise RobotError(f"body.legs must be a non-empty array of tables ([[body.legs]]), not {items!r}")
        if len(items) < 2:
            raise RobotError(f"body.legs must hold at least 2 legs (the legs of a body share one robot core, "
                             f"which applies the mirror and the channel table), not {len(items)}")
        out = [_parse_leg(t, k, geometry.servos) for k, t in enumerate(items)]
        names = [leg.name for leg in out]
        dup = next((n for k, n in enumerate(names) if n in names[:k]), None)
        if dup is not None:
            raise RobotError(f"body.legs[{names.index(dup, names.index(dup) + 1)}].name must be unique, "
                             f"not {dup!r} (body.legs[{names.index(dup)}] has it)")
        if legs is not None and legs != len(out):
            raise RobotError(f"legs must be {len(out)} (the number of [[body.legs]]) or absent, not {legs!r}")
        if tuple(geometry.inputs) != BODY_INPUTS:
            raise RobotError(f"body needs a geometry with a Cartesian target (x, y, z) mm, not "
                             f"({', '.join(geometry.inputs)})")
        body = cls(tuple(out))
        body.check_symmetric(workspace)
        return body

    def check_symmetric(self, workspace) -> None:
        """With a left leg, the y range must be its own mirror (a negated target stays in range)."""
        left = next((leg.name for leg in self.legs if leg.mirrored), None)
        y = workspace.inputs[workspace.names.index(MIRROR_INPUT)]
        if left is not None and (y.min != -y.max or y.lo != -y.hi):
            raise RobotError(f"workspace.y must be symmetric about 0 (min = -max) with a left leg ({left}: its "
                             f"target is mirrored, y -> -y, onto the one box), not [{y.min:g}, {y.max:g}]")

    def record(self) -> dict:
        return {"legs": [leg.record() for leg in self.legs]}

    @classmethod
    def from_record(cls, d: dict) -> "Body":
        return cls(tuple(_leg_from_record(leg) for leg in d["legs"]))


def _leg_from_record(d: dict) -> BodyLeg:
    servos = tuple((name, ServoOverride(**o)) for name, o in d.get("servos", {}).items())
    return BodyLeg(**{f: d[f] for f in _LEG_FIELDS}, servos=servos)


def _parse_leg(t: dict, k: int, servo_names) -> BodyLeg:
    p = f"body.legs[{k}]."
    refuse_extra(t, (*_LEG_FIELDS, "servos"), p)
    name = t.get("name")
    if not isinstance(name, str) or not LEG_NAME.fullmatch(name):
        raise RobotError(f"{p}name must be an ASCII letter followed by at most 15 ASCII letters, digits, '-' "
                         f"and '_', not {name!r}")
    side = t.get("side")
    if side not in SIDES:
        raise RobotError(f"{p}side must be one of {', '.join(SIDES)}, not {side!r}")
    x, y, z, yaw = (float(field_number(t, f, p)) for f in ("x", "y", "z", "yaw"))
    table = field_table(t, "servos", p, required=False)
    refuse_extra(table, servo_names, f"{p}servos.")
    servos = tuple((s, _parse_leg_servo(field_table(table, s, f"{p}servos."), f"{p}servos.{s}"))
                   for s in servo_names if s in table)
    return BodyLeg(name, x, y, z, yaw, side, servos)


def _parse_leg_servo(t: dict, path: str) -> ServoOverride:
    """A leg's own calibration of a servo (``[body.legs.servos.<servo>]``): limits and a trim
    alone, or a whole linear map (``us_per_degree`` and one reference pulse) of the plan's
    servo angle; a table cannot be scaled from the plan's pulse."""
    if "table" in t:
        raise RobotError(f"{path}.table cannot be a leg's own map: a leg's channel is an affine map of the "
                         "plan's pulse; give us_per_degree and zero_pulse_us or neutral_pulse_us")
    given = [f for f in _MAP_FIELDS if f in t]
    try:
        if not given:    # limits and trim only: parsed with a stand-in reference, then dropped
            return dataclasses.replace(ServoOverride.parse({**t, "zero_pulse_us": 1.0}, path), zero_pulse_us=None)
        o = ServoOverride.parse(t, path)
    except ValueError as e:
        raise RobotError(str(e)) from None
    if o.us_per_degree is None:
        raise RobotError(f"{path}.us_per_degree must be given with {path}.{given[0]} (a leg's own map is whole: "
                         "its gain and one reference pulse)")
    return o


# -- frames --------------------------------------------------------------------------------
def _turn(yaw_deg: float):
    a = math.radians(yaw_deg)
    return math.cos(a), math.sin(a)


def body_to_mount(leg: BodyLeg, x, y, z):
    """Body-frame points -> the leg's mount frame: translated by the mount, turned by -yaw."""
    c, s = _turn(leg.yaw)
    dx, dy, dz = (np.asarray(v, dtype=np.float64) - m for v, m in ((x, leg.x), (y, leg.y), (z, leg.z)))
    return c * dx + s * dy, c * dy - s * dx, dz


def mount_to_body(leg: BodyLeg, x, y, z):
    """Inverse of :func:`body_to_mount`."""
    c, s = _turn(leg.yaw)
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    return c * x - s * y + leg.x, s * x + c * y + leg.y, z + leg.z


def mirror(leg: BodyLeg, x, y, z):
    """Mount frame <-> leg frame (its own inverse): y -> -y for a left leg."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    return x, (-y if leg.mirrored else y), z


def body_to_leg(leg: BodyLeg, x, y, z):
    """Body-frame points -> the leg frame (where the workspace box and the plan live)."""
    return mirror(leg, *body_to_mount(leg, x, y, z))


def leg_to_body(leg: BodyLeg, x, y, z):
    """Inverse of :func:`body_to_leg`."""
    return mount_to_body(leg, *mirror(leg, x, y, z))
