"""The per-channel calibration of a robot's legs, read from the description, and the channel
table it becomes (:class:`ikseries.fit.channels.ChannelTable`, applied around the shared plan).

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

:func:`channel_calibration` is the one place the per-channel constants (map from the plan's
pulse, direction, centre, trim, limits) are read from the description; :func:`channel_table`
turns them into the hardware table; :func:`check_channels` checks them over the box before any
fit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .body import MIRROR_INPUT, BodyLeg, body_to_leg
from .calibration import LinearMap, ServoOverride, first_failure
from .fit.channels import ChannelTable, TableChannel
from .kinematics import format_point
from .robot_parts import PULSE_SLACK_US, RobotError

__all__ = ["GAIN_WIDTH", "ChannelCalibration", "channel_calibration", "gain_bits", "channel_error_ticks",
           "channel_errors", "mirror_margin_pu", "fit_tolerance_pu", "channel_table", "channel_pulses_pu",
           "body_pulses_pu", "channel_records", "check_channels"]

#: fraction bits are chosen so that a channel's gain fits this many bits (one DSP operand)
GAIN_WIDTH = 16


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


def _leg_map(robot, k: int, servo: str, o: ServoOverride, base, neutral: float) -> tuple[float, float]:
    """(scale, shift in ticks) of leg ``k``'s own linear map of servo ``servo``, from the plan's
    map ``base`` of the same servo angle (``neutral`` at the neutral pose)."""
    if not isinstance(base, LinearMap):
        raise RobotError(f"body.legs[{k}].servos.{servo} cannot scale calibration.servos.{servo}.table: a leg's "
                         "own map needs a linear map of the plan's (us_per_degree)")
    u, tpu = robot.calibration.pulse_unit_us, robot.ticks_per_pu
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
    lo_us, hi_us = robot.calibration.limits_us(servo)
    return robot.limits_ticks(o.pulse_min_us if o.pulse_min_us is not None else lo_us,
                              o.pulse_max_us if o.pulse_max_us is not None else hi_us)


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
                scale, shift = _leg_map(robot, k, servo, o, maps.servos[j], neutral[j])
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
        return TableChannel(sign, int(np.rint(c.shift)) + c.trim, c.min, c.max)
    gain = int(np.rint(abs(c.scale) * 2 ** f))
    mid = (widths[0] + widths[1]) / 2
    exact = c.shift + c.trim - sign * (gain / 2 ** f - abs(c.scale)) * mid
    return TableChannel(sign, int(np.rint(exact * 2 ** f)) + (1 << (f - 1)), c.min, c.max, gain)


def channel_error_ticks(c: ChannelCalibration, t: TableChannel, f: int, widths: tuple[int, int]) -> float:
    """How far channel ``c``'s table entry ``t`` can put its pulse from ``scale * w + shift +
    trim`` (ticks) for plan widths ``w`` in ``widths``: the rounded offset, and with gains the
    rounded gain over the widths (largest at their ends: it is linear in ``w``) and the final
    rounding (half a tick; none when the gain and offset are whole ticks)."""
    if f == 0:
        return abs(t.offset - c.trim - c.shift)
    off = (t.offset - (1 << (f - 1))) / 2 ** f
    whole = t.gain % (1 << f) == 0 and (t.offset - (1 << (f - 1))) % (1 << f) == 0    # no fraction to round
    return (0.0 if whole else 0.5) + max(abs(off + t.sign * t.gain / 2 ** f * w - (c.scale * w + c.shift + c.trim))
                                         for w in widths)


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
    n = len(robot.servos)
    return tuple(_through(c, p, robot.ticks_per_pu)
                 for p, c in zip(robot.pulses_pu(x, y, z), channel_calibration(robot)[leg * n:(leg + 1) * n]))


def _through(c: ChannelCalibration, plan_pu, tpu: float):
    """Channel ``c``'s reference pulses (pu) of the plan's reference pulses ``plan_pu``."""
    return c.scale * np.asarray(plan_pu) + (c.shift + c.trim) / tpu


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
    not just pass the plan's pulse with its clamp (a mirrored, scaled, trimmed or differently
    clamped one) within its pulse limits; the
    first target (C order) that fails is named with the leg and servo, in one line."""
    n, tick_us = len(robot.servos), robot.hardware.clock_hz * 1e-6
    u, tpu, plan_limits = robot.calibration.pulse_unit_us, robot.ticks_per_pu, robot.pulse_limits_ticks()
    pulses = robot.pulses_pu(*coords)      # the plan's reference, once: each channel is a map of it
    for c in channel_calibration(robot):
        if c.scale == 1.0 and not c.shift and not c.trim and (c.min, c.max) == plan_limits[c.servo]:
            continue          # the plan's own pulse and clamp: the calibration's box check has it
        us = np.ravel(_through(c, pulses[c.channel % n], tpu)) * u
        lo, hi = c.min / tick_us, c.max / tick_us
        masks = [us < lo - PULSE_SLACK_US - 1 / tick_us, us > hi + PULSE_SLACK_US + 1 / tick_us]
        bad = first_failure(masks)
        if bad is not None:
            i, which = bad
            point = format_point(names, [np.ravel(v)[i] for v in coords])
            field = _limit_field(robot, c, ("pulse_min_us", "pulse_max_us")[which])
            raise RobotError(f"calibration: target {point} drives leg {c.leg_name} servo {c.servo} to "
                             f"{us[i]:.6g} us, past its pulse limits [{lo:.6g}, {hi:.6g}] us ({field})")
