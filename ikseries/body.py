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
``mirror_error_ticks``). A leg may calibrate its servos on its own (``[body.legs.servos.<servo>]``):
limits and a trim change its table entry only; a whole linear map of the plan's servo angle
makes its channel ``scale * plan pulse + shift``, a fixed-point gain in the table, and that
channel's error is ``|scale|`` times the plan's plus the table's rounding. The fit reserves
both (:func:`fit_tolerance_pu`, :attr:`ikseries.robot.Robot.fitted`): the plan is certified
to the least over the channels of ``(tolerance - rounding) / |scale|``, so every channel stays
within the tolerance.

:func:`channel_calibration` is the one place the per-channel constants (direction, centre,
trim, limits) are read from the description; :func:`channel_table` turns them into the
hardware table.
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np

from .calibration import LinearMap, ServoOverride
from .fit.channels import ChannelTable, TableChannel
from .robot_parts import RobotError, field_number, field_table, refuse_extra

__all__ = ["BodyLeg", "Body", "SIDES", "MIRROR_INPUT", "GAIN_WIDTH", "mirror_margin_pu", "fit_tolerance_pu",
           "gain_bits", "channel_errors", "channel_error_ticks", "check_channels", "body_to_mount", "mount_to_body", "mirror", "body_to_leg",
           "leg_to_body", "ChannelCalibration", "channel_calibration", "channel_table", "channel_pulses_pu", "body_pulses_pu",
           "channel_records"]

SIDES = ("right", "left")
#: the leg-frame input a left leg's mirror negates
MIRROR_INPUT = "y"
#: the target inputs a body needs (mm): the transforms are of Cartesian points
BODY_INPUTS = ("x", "y", "z")
LEG_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,15}")
_LEG_FIELDS = ("name", "x", "y", "z", "yaw", "side")
#: a leg's servo override: its own linear map of the plan's servo angle, limits and trim
_MAP_FIELDS = ("zero_pulse_us", "neutral_pulse_us", "us_per_degree")
#: fraction bits are chosen so that a channel's gain fits this many bits (one DSP operand)
GAIN_WIDTH = 16


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
    servos = tuple((name, ServoOverride(**{k: v for k, v in o.items()})) for name, o in d.get("servos", {}).items())
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


# -- per-channel calibration ---------------------------------------------------------------
@dataclass(frozen=True)
class ChannelCalibration:
    """The per-channel part of the calibration, in PWM clock ticks.

    The channel's pulse is ``scale * plan_pulse + shift`` (unclamped): an affine map of the
    plan's, the right leg's servo pulse at the leg-frame target (``scale`` +1, ``shift`` 0 for a
    right leg of the description's own calibration; -1 and ``2 centre`` for a left leg, mirrored;
    the ratio of the gains for a leg with a servo map of its own). ``direction``: the channel's
    pulse direction against its servo angle (the sense of ``calibration.directions``);
    ``centre``: the channel's pulse at the neutral pose (ticks, not rounded); ``trim``: added
    after the plan; ``min``/``max``: the pulse the channel saturates to."""
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
    scale: float = 1.0
    shift: float = 0.0

    @property
    def scaled(self) -> bool:
        """True when the channel scales the plan's pulse (not just passes or mirrors it)."""
        return abs(self.scale) != 1.0


def _legs(robot) -> list[BodyLeg | None]:
    return list(robot.body.legs) if robot.body is not None else [None] * robot.legs


def _leg_map(robot, leg: BodyLeg, j: int, servo: str, o: ServoOverride) -> tuple[float, float]:
    """(scale, shift in ticks) of ``leg``'s own linear map of servo ``servo``, from the plan's
    linear map of the same servo angle."""
    base = robot.joint_calibration.servos[j]
    if not isinstance(base, LinearMap):
        k = robot.body.names.index(leg.name)
        raise RobotError(f"body.legs[{k}].servos.{servo} cannot scale calibration.servos.{servo}.table: a leg's "
                         "own map needs a linear map of the plan's (us_per_degree)")
    u, tpu = robot.calibration.pulse_unit_us, robot.ticks_per_pu
    neutral = robot.calibration.neutral_angles(robot.geometry)[j]
    if o.zero_pulse_us is not None:
        own = LinearMap(0.0, o.zero_pulse_us / u, o.us_per_degree / u, (o.trim_us or 0.0) / u)
    else:
        own = LinearMap(neutral, o.neutral_pulse_us / u, o.us_per_degree / u, (o.trim_us or 0.0) / u)
    scale = own.pu_per_degree / base.pu_per_degree
    at_zero = base.angle_deg - (base.pulse_pu + base.trim_pu) / base.pu_per_degree   # the angle of plan pulse 0
    return scale, float(own.pulse(at_zero)) * tpu


def _leg_limits(robot, leg: BodyLeg | None, servo: str, default: tuple[int, int]) -> tuple[int, int]:
    o = None if leg is None else leg.servo(servo)
    if o is None or (o.pulse_min_us is None and o.pulse_max_us is None):
        return default
    tick_us = robot.hardware.clock_hz * 1e-6
    lo_us, hi_us = robot.calibration.limits_us(servo)
    lo_us = o.pulse_min_us if o.pulse_min_us is not None else lo_us
    hi_us = o.pulse_max_us if o.pulse_max_us is not None else hi_us
    return int(np.ceil(lo_us * tick_us)), int(np.floor(hi_us * tick_us))


def channel_calibration(robot) -> tuple[ChannelCalibration, ...]:
    """Per channel (leg-major): the affine map from the plan's pulse, direction, centre, trim
    and limits in ticks, read from the :class:`~ikseries.robot_parts.CalibrationSpec` and the
    legs' own servo calibrations (``[body.legs.servos.<servo>]``). Without one, a right leg's
    servo has the direction of ``calibration.directions`` and a left leg's the opposite one
    (the mirror image: its pulse mirrored about the centre, the servo's pulse at the neutral
    pose, the same in every leg's own frame); trim 0 (a servo's trim is in the plan); the
    limits the servo's pulse limits (the plan's own clamp). A leg's own map is of the plan's
    servo angle at the leg-frame target (for a left leg, the mirrored right leg's angle)."""
    cal, limits, tpu = robot.calibration, robot.pulse_limits_ticks(), robot.ticks_per_pu
    maps, neutral = robot.joint_calibration, cal.neutral_angles(robot.geometry)
    centres = [float(maps.pulse(j, np.asarray(neutral[j]))) * tpu for j in range(len(robot.servos))]
    out = []
    for k, leg in enumerate(_legs(robot)):
        side = "right" if leg is None else leg.side
        for j, servo in enumerate(robot.servos):
            o = None if leg is None else leg.servo(servo)
            if o is not None and o.us_per_degree is not None:
                scale, shift = _leg_map(robot, leg, j, servo, o)
                centre = scale * centres[j] + shift
            elif side == "left":
                scale, shift, centre = -1.0, 2 * centres[j], centres[j]
            else:
                scale, shift, centre = 1.0, 0.0, centres[j]
            trim = 0 if o is None or o.us_per_degree is not None or not o.trim_us \
                else int(np.rint(o.trim_us * robot.hardware.clock_hz * 1e-6))
            d = cal.directions[j] * (1 if scale > 0 else -1)
            out.append(ChannelCalibration(len(out), k, str(k) if leg is None else leg.name, servo, side, d,
                                          centre, trim, *_leg_limits(robot, leg, servo, limits[servo]),
                                          scale, shift))
    return tuple(out)


def gain_bits(calibration: tuple[ChannelCalibration, ...]) -> int:
    """The fraction bits of a table's gains: 0 when every channel passes or mirrors the plan's
    pulse; else the most that keep every gain within :data:`GAIN_WIDTH` bits."""
    scales = [abs(c.scale) for c in calibration]
    if not any(c.scaled for c in calibration):
        return 0
    f = GAIN_WIDTH - max(1, int(max(scales)).bit_length())
    while max(int(np.rint(x * 2 ** f)) for x in scales) >= 1 << GAIN_WIDTH:
        f -= 1
    return f


def _table_channel(c: ChannelCalibration, f: int, widths: tuple[int, int]) -> TableChannel:
    """``c``'s entry at ``f`` fraction bits for plan widths in ``widths``: with gains, the
    offset also moves the rounded gain's error to the middle of the widths (half as large at
    the ends) and carries the rounding half."""
    sign = 1 if c.scale > 0 else -1
    if f == 0:
        return TableChannel(sign, int(np.rint(c.shift)) + c.trim if sign == -1 or c.shift else c.trim, c.min, c.max)
    gain = int(np.rint(abs(c.scale) * 2 ** f))
    mid = (widths[0] + widths[1]) / 2
    exact = c.shift + c.trim - sign * (gain / 2 ** f - abs(c.scale)) * mid
    return TableChannel(sign, int(np.rint(exact * 2 ** f)) + (1 << (f - 1)), c.min, c.max, gain)


def channel_error_ticks(c: ChannelCalibration, t: TableChannel, f: int, widths: tuple[int, int]) -> float:
    """How far channel ``c``'s table entry ``t`` can put its pulse from ``scale * w + shift +
    trim`` (ticks) for plan widths ``w`` in ``widths``: the rounded offset, and with gains the
    rounded gain over the widths (largest at their ends: it is linear in ``w``) and the final
    rounding (half a tick)."""
    if f == 0:
        return abs(t.offset - c.trim - c.shift)
    off = (t.offset - (1 << (f - 1))) / 2 ** f
    return 0.5 + max(abs(off + t.sign * t.gain / 2 ** f * w - (c.scale * w + c.shift + c.trim)) for w in widths)


def channel_errors(robot) -> list[tuple[float, float]]:
    """Per channel (|scale|, error in pu): a channel's pulse is within ``|scale| e + error``
    of its reference when the plan's is within ``e`` of its own."""
    cal = channel_calibration(robot)
    table, limits = channel_table(robot, cal), robot.pulse_limits_ticks()
    tpu = robot.ticks_per_pu
    return [(abs(c.scale), channel_error_ticks(c, t, table.gain_bits, limits[c.servo]) / tpu)
            for c, t in zip(cal, table.channels)]


def mirror_margin_pu(robot) -> float:
    """The largest error (pu) a channel's table entry adds to the plan's: a mirrored channel's
    ``2 centre`` rounded to whole ticks, a scaled channel's rounded gain and offset; 0 without."""
    return max((e for _, e in channel_errors(robot)), default=0.0)


def fit_tolerance_pu(robot) -> float:
    """The tolerance the plan is certified to so that every channel stays within
    ``fit.tolerance_pu``: the least over the channels of ``(tolerance - error) / |scale|``."""
    tol = robot.fit.tolerance_pu
    return min(((tol - e) / k if k != 1.0 else tol - e for k, e in channel_errors(robot)), default=tol)


def channel_table(robot, calibration: tuple[ChannelCalibration, ...] | None = None) -> ChannelTable:
    """The hardware table of ``calibration`` (default :func:`channel_calibration`): a channel
    whose direction is the plan's passes ``pulse + trim``; one turning the other way is
    mirrored, ``2 centre - pulse + trim``, with ``2 centre`` rounded to whole ticks; with a
    scaled channel, every channel's gain and offset at :func:`gain_bits` fraction bits."""
    cal = channel_calibration(robot) if calibration is None else calibration
    f, limits = gain_bits(cal), robot.pulse_limits_ticks()
    chans = tuple(_table_channel(c, f, limits[c.servo]) for c in cal)
    mirrored = tuple(leg is not None and leg.mirrored for leg in _legs(robot))
    return ChannelTable(robot.legs, tuple(robot.servos), MIRROR_INPUT if any(mirrored) else None, mirrored,
                        chans, f)


def channel_pulses_pu(robot, leg: int, x, y, z) -> tuple:
    """Reference pulses (pu, float64) of leg ``leg``'s channels for leg-frame targets: the
    plan's reference (:meth:`~ikseries.robot.Robot.pulses_pu`, the right leg's) through the
    channel's calibration, ``scale * pulse + shift + trim``; unsaturated, like the plan's
    reference."""
    tpu = robot.ticks_per_pu
    pulses = robot.pulses_pu(x, y, z)
    n = len(robot.servos)
    out = []
    for p, c in zip(pulses, channel_calibration(robot)[leg * n:(leg + 1) * n]):
        if c.scale == -1.0:      # the mirror about the centre, as written
            centre = c.centre / tpu
            out.append(centre - (np.asarray(p) - centre) + c.trim / tpu)
        else:
            out.append(c.scale * np.asarray(p) + (c.shift + c.trim) / tpu)
    return tuple(out)


def body_pulses_pu(robot, leg_name: str, x, y, z) -> tuple:
    """:func:`channel_pulses_pu` of the leg called ``leg_name`` for body-frame targets."""
    k, leg = robot.body.leg(leg_name)
    return channel_pulses_pu(robot, k, *body_to_leg(leg, x, y, z))


def channel_records(robot, ports=None) -> list[dict]:
    """The channel table of the manifest and the report: per channel its leg, servo, side,
    mount, calibration (ticks) and, for a mirrored channel, how far the rounded ``2 centre``
    is from the exact one (ticks: added to the plan's error bound on that channel); with
    scaled channels, every channel's scale and error bound; ``ports``: {channel: port} to add."""
    cal = channel_calibration(robot)
    table = channel_table(robot, cal)
    legs, limits = _legs(robot), robot.pulse_limits_ticks()
    out = []
    for c, t in zip(cal, table.channels):
        leg = legs[c.leg]
        err = channel_error_ticks(c, t, table.gain_bits, limits[c.servo])
        rec = {"channel": c.channel, "leg": c.leg, "leg_name": c.leg_name, "servo": c.servo, "side": c.side,
               "mount": None if leg is None else {k: getattr(leg, k) for k in ("x", "y", "z", "yaw")},
               "direction": c.direction, "centre_ticks": c.centre, "trim_ticks": c.trim,
               "min_ticks": c.min, "max_ticks": c.max, "mirrored": t.sign == -1,
               "mirror_error_ticks": err if t.sign == -1 else 0.0}
        if table.gain_bits:      # left out without gains: the records (and manifests) they predate
            rec.update(scale=c.scale, error_ticks=err)
        if ports is not None:
            rec["port"] = ports[c.channel]
        out.append(rec)
    return out


def _limit_field(robot, c: ChannelCalibration, which: str) -> str:
    leg = _legs(robot)[c.leg]
    o = None if leg is None else leg.servo(c.servo)
    if o is not None and getattr(o, which) is not None:
        return f"body.legs[{c.leg}].servos.{c.servo}.{which}"
    return robot.calibration.limit_field(c.servo, which)


def check_channels(robot, names, coords) -> None:
    """At the leg-frame targets ``coords`` (arrays, input ``names``): every channel that does
    not just pass the plan's pulse (a mirrored or a scaled one) within its pulse limits; the
    first target (C order) that fails is named with the leg and servo, in one line."""
    from .calibration import first_failure
    from .kinematics import format_point
    from .robot_parts import PULSE_SLACK_US

    n, tick_us = len(robot.servos), robot.hardware.clock_hz * 1e-6
    u = robot.calibration.pulse_unit_us
    for c in channel_calibration(robot):
        if c.scale == 1.0 and not c.shift and not c.trim:
            continue          # the plan's own pulse: the calibration's box check has it
        us = np.ravel(channel_pulses_pu(robot, c.leg, *coords)[c.channel % n]) * u
        lo, hi = c.min / tick_us, c.max / tick_us
        masks = [us < lo - PULSE_SLACK_US - 1 / tick_us, us > hi + PULSE_SLACK_US + 1 / tick_us]
        bad = first_failure(masks)
        if bad is not None:
            i, which = bad
            point = format_point(names, [np.ravel(v)[i] for v in coords])
            field = _limit_field(robot, c, ("pulse_min_us", "pulse_max_us")[which])
            raise RobotError(f"calibration: target {point} drives leg {c.leg_name} servo {c.servo} to "
                             f"{us[i]:.6g} us, past its pulse limits [{lo:.6g}, {hi:.6g}] us ({field})")
