"""Servo calibration: each servo's map from its servo angle (deg) to a pulse width (pu).

A servo's angle is the one :mod:`ikseries.joints` defines (``direction * kinematic + offset``),
what a geometry's ``ik`` and ``angles`` return. Its pulse is one of

- linear: ``pulse = reference pulse + gain * (angle - reference angle) + trim``, the reference
  being the neutral pose (``[calibration]``'s ``neutral_pulse_pu``, or a servo's
  ``neutral_pulse_us``) or servo angle 0 (a servo's ``zero_pulse_us``), the gain in pu per degree
  of either sign (its sign is the direction);
- a table: ``pulse = piecewise-linear interpolation of [[angle, pulse], ...] + trim``, for a
  servo that is not linear; angles outside the table are refused
  (``CalibrationSpec.check_box`` in :mod:`ikseries.robot_parts`).

Every servo has its own pulse limits, the plan's output clamp. ``[calibration]`` gives the
defaults of every servo; ``[calibration.servos.<servo>]`` overrides them for one servo
(:class:`ServoOverride`).

The maps evaluate over any math namespace the certifier uses. On numpy arrays a table is
interpolated segment by segment (exact at its points); for the certifier it is written in
hinge form, ``p_0 + s_0 (a - a_0) + sum_k (s_k - s_{k-1}) (max(a, a_k) - a_k)`` over the inner
points ``a_k`` (the same function up to the rounding of its slopes ``s_k``), with ``max`` the
namespace's clamp (``ikseries.fit.interval.clamp``): where a cell's angle may cross a table
point, that clamp may switch and only the first-order forms apply, as for the plan's own
output clamp, and only the slope's change at the point widens the derivative's enclosure.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Callable, Sequence

import numpy as np

__all__ = ["LinearMap", "TableMap", "Calibration", "ServoOverride", "REFERENCES", "first_failure"]

#: the two references of a linear servo: field -> what it is
REFERENCES = {"zero_pulse_us": "the pulse at servo angle 0",
              "neutral_pulse_us": "the pulse at the neutral pose"}


@dataclass(frozen=True)
class LinearMap:
    """``pulse = pulse_pu + pu_per_degree * (angle - angle_deg) + trim_pu`` (pu, deg)."""
    angle_deg: float          # the reference angle
    pulse_pu: float           # the pulse there, trim excluded
    pu_per_degree: float      # signed: its sign is the servo's direction
    trim_pu: float = 0.0

    def pulse(self, angle, clamp: Callable | None = None):
        """The pulse of ``angle`` (an array, or a number of the certifier's namespaces)."""
        p = self.pulse_pu + self.pu_per_degree * (angle - self.angle_deg)
        return p + self.trim_pu if self.trim_pu else p

    def of_kinematic(self, direction: int, offset: float) -> "LinearMap":
        """The same pulses as a map of the kinematic angle ``(servo angle - offset) / direction``."""
        a = self.angle_deg - offset if direction == 1 else offset - self.angle_deg
        return LinearMap(float(a), self.pulse_pu, self.pu_per_degree * direction, self.trim_pu)


@dataclass(frozen=True)
class TableMap:
    """``pulse`` = piecewise-linear through ``points`` ((deg, pu), angles strictly increasing)
    + ``trim_pu``; outside the table the end segments extend (the box check refuses such
    angles on its grid)."""
    points: tuple[tuple[float, float], ...]
    trim_pu: float = 0.0

    @property
    def angle_range(self) -> tuple[float, float]:
        return self.points[0][0], self.points[-1][0]

    @property
    def slopes(self) -> np.ndarray:
        """pu per degree of each segment."""
        a, p = np.array(self.points).T
        return np.diff(p) / np.diff(a)

    def pulse(self, angle, clamp: Callable | None = None):
        """The pulse of ``angle``: on numpy arrays (``clamp`` None) by segment, exact at the
        table's points; else in hinge form (module docstring) with the namespace's ``clamp``."""
        p = self._segments(angle) if clamp is None else self._hinges(angle, clamp)
        return p + self.trim_pu if self.trim_pu else p

    def _segments(self, angle) -> np.ndarray:
        a = np.asarray(angle, dtype=np.float64)
        xs, ps = (np.array(c) for c in zip(*self.points))
        k = np.clip(np.searchsorted(xs, a, side="right") - 1, 0, len(xs) - 2)
        with np.errstate(invalid="ignore"):
            p = ps[k] + self.slopes[k] * (a - xs[k])
        return np.where(a == xs[-1], ps[-1], p)     # the last point is no segment's start

    def _hinges(self, angle, clamp: Callable):
        (a0, p0), s = self.points[0], self.slopes
        p = p0 + float(s[0]) * (angle - a0)
        for (ak, _), step in zip(self.points[1:-1], np.diff(s)):
            # max(a, a_k) - a_k: the clamp compares the angle itself, so a cell that only touches
            # a_k is not taken to cross it for the rounding of a difference
            p = p + float(step) * (clamp(angle, ak, np.inf) - ak)
        return p

    def of_kinematic(self, direction: int, offset: float) -> "TableMap":
        """The same pulses as a map of the kinematic angle (see :meth:`LinearMap.of_kinematic`)."""
        pts = ((a - offset if direction == 1 else offset - a, p) for a, p in self.points)
        return TableMap(tuple(sorted((float(a), p) for a, p in pts)), self.trim_pu)


@dataclass(frozen=True)
class Calibration:
    """The servo angle -> pulse (pu) map of every servo, in the geometry's servo order."""
    servos: tuple

    @classmethod
    def linear(cls, neutral_angles, directions, neutral_pulse_pu: float = 3000.0,
               pu_per_degree: float = 20.0) -> "Calibration":
        """One gain and neutral pulse for every servo: ``[calibration]`` without overrides."""
        return cls(tuple(LinearMap(float(n), neutral_pulse_pu, d * pu_per_degree)
                         for n, d in zip(neutral_angles, directions)))

    def pulse(self, k: int, angle, clamp: Callable | None = None):
        """Pulse of servo ``k`` at ``angle``: a numpy array (``clamp`` None) or a number of a
        math namespace whose ``clamp(x, lo, hi)`` is given (the certifier's)."""
        return self.servos[k].pulse(angle, clamp)

    def pulses(self, angles):
        """Pulse widths in pu for a sequence of per-servo angle arrays."""
        return tuple(m.pulse(np.asarray(a)) for m, a in zip(self.servos, angles))


# -- a servo's [calibration.servos.<servo>] table ---------------------------------------------
def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class ServoOverride:
    """One servo's calibration as given (µs); None: not given (the ``[calibration]`` default)."""
    zero_pulse_us: float | None = None
    neutral_pulse_us: float | None = None
    us_per_degree: float | None = None
    pulse_min_us: float | None = None
    pulse_max_us: float | None = None
    trim_us: float | None = None
    table: tuple[tuple[float, float], ...] | None = None

    @classmethod
    def parse(cls, t: dict, path: str) -> "ServoOverride":
        """Validate one servo's table (``path``: its TOML name, e.g. ``calibration.servos.s2``)."""
        names = [f.name for f in fields(cls)]
        extra = sorted(set(t) - set(names))
        if extra:
            raise ValueError(f"unknown field {path}.{extra[0]} (expected one of: {', '.join(sorted(names))})")
        for key in names[:-1]:
            unit = "us per degree" if key == "us_per_degree" else "us"
            if key in t and not _finite(t[key]):
                raise ValueError(f"{path}.{key} must be a finite number of {unit}, not {t[key]!r}")
        o = cls(**{k: float(t[k]) for k in names[:-1] if k in t},
                table=_parse_table(t["table"], f"{path}.table") if "table" in t else None)
        o._check(path)
        return o

    def _check(self, path: str) -> None:
        given = [k for k in REFERENCES if getattr(self, k) is not None]
        if self.table is not None:
            extra = [k for k in (*REFERENCES, "us_per_degree") if getattr(self, k) is not None]
            if extra:
                raise ValueError(f"{path}.table gives the pulse at every angle: drop {path}.{extra[0]}")
        elif len(given) != 1:
            raise ValueError(f"{path} must give exactly one of zero_pulse_us ({REFERENCES['zero_pulse_us']}) or "
                             f"neutral_pulse_us ({REFERENCES['neutral_pulse_us']}) or a table, not "
                             f"{'both' if given else 'neither'}")
        if self.us_per_degree == 0:
            raise ValueError(f"{path}.us_per_degree must be a nonzero finite number of us per degree (its sign "
                             f"is the direction), not {self.us_per_degree!r}")
        for key in ("pulse_min_us", "pulse_max_us"):
            v = getattr(self, key)
            if v is not None and not v > 0:
                raise ValueError(f"{path}.{key} must be > 0 us, not {v!r}")

    def record(self) -> dict:
        """The fields given (the TOML table's own), JSON-ready."""
        d = {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}
        if self.table is not None:
            d["table"] = [list(p) for p in self.table]
        return d


def _parse_table(value, path: str) -> tuple[tuple[float, float], ...]:
    """``table`` checked: at least 2 [deg, us] pairs of finite numbers, angles strictly increasing."""
    if not isinstance(value, (list, tuple)) or len(value) < 2:
        raise ValueError(f"{path} must be a list of at least 2 [deg, us] points, not {value!r}")
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, (list, tuple)) or len(p) != 2 or not all(_finite(v) for v in p):
            raise ValueError(f"{path}[{i}] must be [deg, us] with two finite numbers, not {p!r}")
        if out and not p[0] > out[-1][0]:
            raise ValueError(f"{path} angles must be strictly increasing, not {p[0]!r} deg after "
                             f"{out[-1][0]!r} deg ({path}[{i}])")
        if not p[1] > 0:
            raise ValueError(f"{path}[{i}] pulse must be > 0 us, not {p[1]!r}")
        out.append((float(p[0]), float(p[1])))
    return tuple(out)



def first_failure(masks: Sequence[np.ndarray]) -> tuple[int, int] | None:
    """(flat index, check) of the first failing point in C order and its first failing check."""
    masks = [np.ravel(m) for m in masks]
    if not masks:
        return None
    bad = np.logical_or.reduce(masks)
    if not np.any(bad):
        return None
    i = int(np.flatnonzero(bad)[0])
    return i, next(j for j, m in enumerate(masks) if m[i])
