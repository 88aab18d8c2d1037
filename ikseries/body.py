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

The mirror is undone in two places in hardware (:mod:`ikseries.fit.channels`): a left leg's
``y`` port is negated before the plan, and each of its servos' pulses is mirrored about the
servo's centre after it (a mirror image turns every joint the other way: ``2 centre - pulse``).
So the workspace's y range must be symmetric about 0 when there are left legs (a negated
in-range target must be in range); the description is refused otherwise (rather than fitting
the union of the box and its mirror, which would cost accuracy on every leg).

The mirror's ``2 centre`` is rounded to whole ticks, so a mirrored channel's error is the
plan's plus that rounding (at most half a tick; the channel records give it per channel as
``mirror_error_ticks``). The fit reserves it (:func:`mirror_margin_pu`,
:attr:`ikseries.robot.Robot.fitted`): the plan is certified to the tolerance less that margin,
so every channel stays within the tolerance.

:func:`channel_calibration` is the one place the per-channel constants (direction, centre,
trim, limits) are read from the description; :func:`channel_table` turns them into the
hardware table.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from .fit.channels import ChannelTable, TableChannel
from .robot_parts import RobotError, field_number, refuse_extra

__all__ = ["BodyLeg", "Body", "SIDES", "MIRROR_INPUT", "mirror_margin_pu", "body_to_mount", "mount_to_body", "mirror", "body_to_leg",
           "leg_to_body", "ChannelCalibration", "channel_calibration", "channel_table", "channel_pulses_pu", "body_pulses_pu",
           "channel_records"]

SIDES = ("right", "left")
#: the leg-frame input a left leg's mirror negates
MIRROR_INPUT = "y"
#: the target inputs a body needs (mm): the transforms are of Cartesian points
BODY_INPUTS = ("x", "y", "z")
LEG_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,15}")
_LEG_FIELDS = ("name", "x", "y", "z", "yaw", "side")


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

    @property
    def mirrored(self) -> bool:
        return self.side == "left"

    def record(self) -> dict:
        return {f: getattr(self, f) for f in _LEG_FIELDS}


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
        out = [_parse_leg(t, k) for k, t in enumerate(items)]
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
        return cls(tuple(BodyLeg(**leg) for leg in d["legs"]))


def _parse_leg(t: dict, k: int) -> BodyLeg:
    p = f"body.legs[{k}]."
    refuse_extra(t, _LEG_FIELDS, p)
    name = t.get("name")
    if not isinstance(name, str) or not LEG_NAME.fullmatch(name):
        raise RobotError(f"{p}name must be an ASCII letter followed by at most 15 ASCII letters, digits, '-' "
                         f"and '_', not {name!r}")
    side = t.get("side")
    if side not in SIDES:
        raise RobotError(f"{p}side must be one of {', '.join(SIDES)}, not {side!r}")
    x, y, z, yaw = (float(field_number(t, f, p)) for f in ("x", "y", "z", "yaw"))
    return BodyLeg(name, x, y, z, yaw, side)


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


# -- per-channel calibration ---------------------------------------------------------------
@dataclass(frozen=True)
class ChannelCalibration:
    """The per-channel part of the calibration, in PWM clock ticks.

    ``direction``: the channel's pulse direction against its servo angle (the sense of
    ``calibration.directions``); ``centre``: the pulse a mirrored channel is mirrored about
    (ticks, not rounded); ``trim``: added after the plan; ``min``/``max``: the pulse the
    channel saturates to."""
    channel: int
    leg: int
    leg_name: str
    servo: str
    side: str
    direction: int
    centre: float
    trim: int
    min: int
    max: int


def _legs(robot) -> list[BodyLeg | None]:
    return list(robot.body.legs) if robot.body is not None else [None] * robot.legs


def channel_calibration(robot) -> tuple[ChannelCalibration, ...]:
    """Per channel (leg-major): direction, centre, trim and limits in ticks, read from the
    :class:`~ikseries.robot_parts.CalibrationSpec`: a right leg's servo has the direction of
    ``calibration.directions``, a left leg's the opposite one (the mirror image); the centre
    is the servo's pulse at the neutral pose (its own calibration, trim included: the same in
    every leg's own frame); trim 0 (a servo's trim is in the plan); the limits the servo's
    pulse limits (the plan's own clamp)."""
    cal, limits, tpu = robot.calibration, robot.pulse_limits_ticks(), robot.ticks_per_pu
    maps, neutral = robot.joint_calibration, cal.neutral_angles(robot.geometry)
    centres = [float(maps.pulse(j, np.asarray(neutral[j]))) * tpu for j in range(len(robot.servos))]
    out = []
    for k, leg in enumerate(_legs(robot)):
        side = "right" if leg is None else leg.side
        for j, servo in enumerate(robot.servos):
            d = cal.directions[j] * (-1 if side == "left" else 1)
            out.append(ChannelCalibration(len(out), k, str(k) if leg is None else leg.name, servo, side, d,
                                          centres[j], 0, *limits[servo]))
    return tuple(out)


def mirror_margin_pu(robot) -> float:
    """The largest error (pu) a mirrored channel adds to the plan's: its ``2 centre`` rounded
    to whole ticks; 0 without one. The fit reserves it (:attr:`ikseries.robot.Robot.fitted`)."""
    errs = [abs(t.offset - c.trim - 2 * c.centre)
            for c, t in zip(channel_calibration(robot), channel_table(robot).channels) if t.sign == -1]
    return max(errs, default=0.0) / robot.ticks_per_pu


def channel_table(robot, calibration: tuple[ChannelCalibration, ...] | None = None) -> ChannelTable:
    """The hardware table of ``calibration`` (default :func:`channel_calibration`): a channel
    whose direction is the plan's passes ``pulse + trim``; one turning the other way is
    mirrored, ``2 centre - pulse + trim``, with ``2 centre`` rounded to whole ticks."""
    cal = channel_calibration(robot) if calibration is None else calibration
    plan_dirs = robot.calibration.directions
    chans = []
    for c in cal:
        sign = c.direction * plan_dirs[robot.servos.index(c.servo)]
        offset = c.trim if sign == 1 else int(np.rint(2 * c.centre)) + c.trim
        chans.append(TableChannel(sign, offset, c.min, c.max))
    mirrored = tuple(leg is not None and leg.mirrored for leg in _legs(robot))
    return ChannelTable(robot.legs, tuple(robot.servos), MIRROR_INPUT if any(mirrored) else None, mirrored,
                        tuple(chans))


def channel_pulses_pu(robot, leg: int, x, y, z) -> tuple:
    """Reference pulses (pu, float64) of leg ``leg``'s channels for leg-frame targets: the
    plan's reference (:meth:`~ikseries.robot.Robot.pulses_pu`, the right leg's) through the
    channel's calibration, ``centre + sign * (pulse - centre) + trim`` (``sign`` -1 for a
    channel turning the other way from the plan's); unsaturated, like the plan's reference."""
    tpu = robot.ticks_per_pu
    pulses = robot.pulses_pu(x, y, z)
    n = len(robot.servos)
    out = []
    for j, (p, c) in enumerate(zip(pulses, channel_calibration(robot)[leg * n:(leg + 1) * n])):
        sign = c.direction * robot.calibration.directions[j]
        centre = c.centre / tpu
        out.append(centre + sign * (np.asarray(p) - centre) + c.trim / tpu)
    return tuple(out)


def body_pulses_pu(robot, leg_name: str, x, y, z) -> tuple:
    """:func:`channel_pulses_pu` of the leg called ``leg_name`` for body-frame targets."""
    k, leg = robot.body.leg(leg_name)
    return channel_pulses_pu(robot, k, *body_to_leg(leg, x, y, z))


def channel_records(robot, ports=None) -> list[dict]:
    """The channel table of the manifest and the report: per channel its leg, servo, side,
    mount, calibration (ticks) and, for a mirrored channel, how far the rounded ``2 centre``
    is from the exact one (ticks: added to the plan's error bound on that channel);
    ``ports``: {channel: port} to add."""
    table = channel_table(robot)
    legs = _legs(robot)
    out = []
    for c, t in zip(channel_calibration(robot), table.channels):
        leg = legs[c.leg]
        rec = {"channel": c.channel, "leg": c.leg, "leg_name": c.leg_name, "servo": c.servo, "side": c.side,
               "mount": None if leg is None else {k: getattr(leg, k) for k in ("x", "y", "z", "yaw")},
               "direction": c.direction, "centre_ticks": c.centre, "trim_ticks": c.trim,
               "min_ticks": c.min, "max_ticks": c.max, "mirrored": t.sign == -1,
               "mirror_error_ticks": abs(t.offset - c.trim - 2 * c.centre) if t.sign == -1 else 0.0}
        if ports is not None:
            rec["port"] = ports[c.channel]
        out.append(rec)
    return out
