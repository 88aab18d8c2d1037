"""Reachability checks shared by the geometries: name the first bad target and why.

A geometry's ``ik`` computes, per target, masks of what makes it unreachable (out of the
reach of a link pair, a joint beyond its range, ...) and hands them to
:func:`raise_first_unreachable`, which raises one :class:`~ikseries.kinematics.UnreachableError`
for the first bad target in C order, with the reason of the first failing check there.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from .kinematics import UnreachableError, _fmt_point

__all__ = ["raise_first_unreachable", "joint_range_checks", "ANGLE_SLACK_DEG"]

#: Joint ranges are inclusive up to this slack (deg), so that a pose exactly on a range end
#: (e.g. a right-angled knee at 0 deg) is not rejected for a rounding error.
ANGLE_SLACK_DEG = 1e-9

Check = tuple[np.ndarray, Callable[[int], str]]


def raise_first_unreachable(names: Sequence[str], coords: Sequence[np.ndarray],
                            checks: Sequence[Check]) -> None:
    """Raise for the first target failing any check; return if every target passes.

    Parameters
    ----------
    names : sequence of str
        Input names, for the message (``target (x=.., y=..)``).
    coords : sequence of ndarray
        Input coordinate arrays, all of one shape.
    checks : sequence of (mask, reason)
        ``mask`` is True where a target fails; ``reason(i)`` gives the message tail for the
        flat index ``i``. Checks are tried in order at the first failing target.

    Raises
    ------
    UnreachableError
        ``target (x=.., ...) is unreachable: <reason>`` (one line).
    """
    if not checks:
        return
    masks = [np.ravel(m) for m, _ in checks]
    bad = np.logical_or.reduce(masks)
    if not np.any(bad):
        return
    i = int(np.flatnonzero(bad)[0])
    point = [np.ravel(c)[i] for c in coords]
    why = next(reason for m, (_, reason) in zip(masks, checks) if m[i])
    raise UnreachableError(f"target {_fmt_point(names, point)} is unreachable: {why(i)}")


def joint_range_checks(angles: Sequence[np.ndarray], servo_names: Sequence[str],
                       ranges: Sequence[tuple[float, float]]) -> list[Check]:
    """Checks that each joint angle (deg) lies in its inclusive range.

    A non-finite angle also fails (its message then shows ``nan``); geometries put their
    reach checks first so that such targets are reported by reach instead.
    """
    checks = []
    for a, name, (lo, hi) in zip(angles, servo_names, ranges):
        a = np.ravel(a)
        with np.errstate(invalid="ignore"):
            out = ~((a >= lo - ANGLE_SLACK_DEG) & (a <= hi + ANGLE_SLACK_DEG))
        checks.append((out, lambda i, a=a, name=name, lo=lo, hi=hi:
                       f"{name} angle {a[i]:.6g} deg must be within [{lo:g}, {hi:g}] deg"))
    return checks
