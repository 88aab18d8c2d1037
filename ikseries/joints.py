"""Joint conventions: how each servo's own angle relates to a geometry's kinematic angles.

A closed-form geometry computes its joint angles in its own kinematic convention (its
docstring says where each angle's zero is and which way it counts). A real servo is mounted
with its own zero (the horn offset), perhaps the other way round, and travels only so far.
Three optional ``[geometry]`` fields, one entry per servo in the geometry's servo order, say so:

- ``angle_directions`` (+1 or -1): the servo's positive sense relative to the kinematic one;
- ``zero_offsets`` (deg): the servo's own angle where the kinematic angle is 0 (the horn offset);
- ``joint_ranges`` ([min, max] deg, at most 360 deg wide): the servo's travel, in its own angles.

The servo angle is ``servo = direction * kinematic + offset``. It is what the geometry's ``ik``
and ``angles`` return, what ``joint_ranges`` and the workspace reachability proof check, what
``fk`` takes, and what the calibration (:mod:`ikseries.calibration`) maps to a pulse, by default::

    pulse = neutral_pulse_pu + calibration.directions * pu_per_degree * (servo - servo at the neutral pose)

so ``angle_directions`` and ``calibration.directions`` both flip a servo's pulse deviations, but
only ``angle_directions`` also flips the angle that ``joint_ranges`` and ``zero_offsets`` are
measured in. Because that calibration counts from the neutral pose, an offset shifts the servo
angle and where its range lies, not its pulse (a servo calibrated by its pulse at servo angle 0,
``zero_pulse_us``, or by a table of servo angles does see the offset).

Defaults: direction +1, offset 0 (the servo angle is the kinematic angle, bit for bit: the
conversion is skipped) and the geometry's own ranges (:attr:`JointConventions.default_joint_ranges`;
None: not checked). The defaults are left out of a robot record (:func:`geometry_record`), so a
description without these fields has the record, plan-cache key and plan it had before they existed.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Sequence

import numpy as np

__all__ = ["JointConventions", "CONVENTION_FIELDS", "MAX_RANGE_DEG", "ANGLE_SLACK_DEG", "Check",
           "joint_range_checks", "geometry_record"]

#: the [geometry] fields of the joint conventions
CONVENTION_FIELDS = ("joint_ranges", "zero_offsets", "angle_directions")
#: the widest joint range (deg): one turn
MAX_RANGE_DEG = 360.0
#: Joint ranges are inclusive up to this slack (deg), so that a pose exactly on a range end
#: (e.g. a right-angled knee at 0 deg) is not rejected for a rounding error.
ANGLE_SLACK_DEG = 1e-9

Check = tuple[np.ndarray, Callable[[int], str]]


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _per_servo(name: str, value, servo_names: Sequence[str], what: str) -> list:
    """``value`` checked to be a list of one entry per servo."""
    n = len(servo_names)
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"{name} must be a list of {n} {what} (one per servo: {', '.join(servo_names)}), "
                         f"not {_show(value)}")
    return list(value)


def _show(v) -> str:
    """``v`` as the TOML wrote it (lists, not tuples)."""
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return repr(v)


def parse_ranges(value, servo_names) -> tuple[tuple[float, float], ...]:
    """``joint_ranges`` checked: per servo [min, max] deg, finite, min < max, at most one turn."""
    out = []
    for i, r in enumerate(_per_servo("joint_ranges", value, servo_names, "[min, max] pairs in deg")):
        if not isinstance(r, (list, tuple)) or len(r) != 2 or not all(_number(v) for v in r):
            raise ValueError(f"joint_ranges[{i}] must be [min, max] deg with two finite numbers, not {_show(r)}")
        lo, hi = float(r[0]), float(r[1])
        if not lo < hi:
            raise ValueError(f"joint_ranges[{i}] must be [min, max] deg with min < max, not {_show(r)}")
        if hi - lo > MAX_RANGE_DEG:
            raise ValueError(f"joint_ranges[{i}] must be at most {MAX_RANGE_DEG:g} deg wide, not {_show(r)} "
                             f"({hi - lo:g} deg)")
        out.append((lo, hi))
    return tuple(out)


def parse_offsets(value, servo_names) -> tuple[float, ...]:
    """``zero_offsets`` checked: per servo a finite number of degrees."""
    out = []
    for i, v in enumerate(_per_servo("zero_offsets", value, servo_names, "numbers in deg")):
        if not _number(v):
            raise ValueError(f"zero_offsets[{i}] must be a finite number of deg, not {_show(v)}")
        out.append(float(v))
    return tuple(out)


def parse_directions(value, servo_names) -> tuple[int, ...]:
    """``angle_directions`` checked: per servo +1 or -1."""
    out = []
    for i, v in enumerate(_per_servo("angle_directions", value, servo_names, "values +1 or -1")):
        if not _number(v) or v not in (1, -1):
            raise ValueError(f"angle_directions[{i}] must be +1 or -1, not {_show(v)}")
        out.append(int(v))
    return tuple(out)


@dataclass(frozen=True)
class JointConventions:
    """Mixin of a geometry dataclass: the servo conventions of its joints (module docstring).

    The fields are keyword-only (after the geometry's own fields) and normalised on
    construction: None becomes the default, lists become tuples of floats (directions: ints).
    A geometry applies :meth:`servo_angles` to what its ``angles`` formula computes,
    :meth:`kinematic_angles` to what its ``fk`` is given, and :meth:`range_checks` in ``ik``.
    """

    joint_ranges: tuple | None = field(default=None, kw_only=True)
    zero_offsets: tuple | None = field(default=None, kw_only=True)
    angle_directions: tuple | None = field(default=None, kw_only=True)

    #: the geometry's own joint ranges (deg, per servo) when none are given; None: unchecked
    default_joint_ranges: ClassVar[tuple | None] = None

    def __post_init__(self):
        names = self.servo_names
        given = {"joint_ranges": (self.joint_ranges, parse_ranges),
                 "zero_offsets": (self.zero_offsets, parse_offsets),
                 "angle_directions": (self.angle_directions, parse_directions)}
        defaults = self.convention_defaults()
        for key, (value, parse) in given.items():
            object.__setattr__(self, key, defaults[key] if value is None else parse(value, names))

    def convention_defaults(self) -> dict:
        """The value of each convention field when it is not given."""
        n = len(self.servos)
        return {"joint_ranges": self.default_joint_ranges, "zero_offsets": (0.0,) * n,
                "angle_directions": (1,) * n}

    def _identity(self, k: int) -> bool:
        return self.angle_directions[k] == 1 and self.zero_offsets[k] == 0

    def servo_angles(self, angles) -> tuple:
        """Servo angles ``direction * kinematic + offset`` of kinematic angles (deg, one per servo;
        arrays or interval numbers); a servo with the default conventions gets its angle as is."""
        return tuple(a if self._identity(k) else (a + o if d == 1 else o - a)
                     for k, (a, d, o) in enumerate(zip(angles, self.angle_directions, self.zero_offsets)))

    def kinematic_angles(self, angles) -> tuple:
        """Kinematic angles of servo angles (deg, one per servo): the inverse of :meth:`servo_angles`."""
        return tuple(a if self._identity(k) else (a - o if d == 1 else o - a)
                     for k, (a, d, o) in enumerate(zip(angles, self.angle_directions, self.zero_offsets)))

    def range_checks(self, angles) -> list[Check]:
        """Checks of servo ``angles`` against :attr:`joint_ranges` (none when unchecked)."""
        if self.joint_ranges is None:
            return []
        return joint_range_checks(angles, self.servo_names, self.joint_ranges)

    def kinematic_calibration(self, cal):
        """``cal`` (an :class:`ikseries.calibration.Calibration` of the servo angles) as the same
        map of the kinematic angles: pulses are unchanged, each servo's map takes the kinematic
        angle (``of_kinematic``: a linear gain's sign times the joint's direction)."""
        if all(self._identity(k) for k in range(len(self.servos))):
            return cal
        return dataclasses.replace(cal, servos=tuple(
            m if self._identity(k) else m.of_kinematic(d, o)
            for k, (m, d, o) in enumerate(zip(cal.servos, self.angle_directions, self.zero_offsets))))


def joint_range_checks(angles: Sequence[np.ndarray], servo_names: Sequence[str],
                       ranges: Sequence[tuple[float, float]],
                       field: str = "geometry.joint_ranges[{k}]") -> list[Check]:
    """Checks (for :func:`ikseries.reach.raise_first_unreachable`) that each joint angle (deg)
    lies in its inclusive range; the message names the TOML entry to widen (``field``, with
    ``{k}`` the servo's index).

    A non-finite angle also fails (its message then shows ``nan``); geometries put their
    reach checks first so that such targets are reported by reach instead.
    """
    checks = []
    for k, (a, name, (lo, hi)) in enumerate(zip(angles, servo_names, ranges)):
        a = np.ravel(a)
        with np.errstate(invalid="ignore"):
            out = ~((a >= lo - ANGLE_SLACK_DEG) & (a <= hi + ANGLE_SLACK_DEG))
        checks.append((out, lambda i, a=a, name=name, lo=lo, hi=hi, where=field.format(k=k):
                       f"{name} angle {a[i]:.6g} deg must be within [{lo:g}, {hi:g}] deg ({where})"))
    return checks


def geometry_record(geometry) -> dict:
    """The fields of ``geometry`` for a robot record: its dataclass fields, without the joint
    conventions that have their defaults (tuples stay tuples; JSON writes them as lists)."""
    d = dataclasses.asdict(geometry)
    if isinstance(geometry, JointConventions):
        for key, default in geometry.convention_defaults().items():
            if getattr(geometry, key) == default:
                del d[key]
    return d
