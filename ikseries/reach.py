"""Reachability checks shared by the geometries: name the first bad target and why.

A geometry's ``ik`` computes, per target, masks of what makes it unreachable (out of the
reach of a link pair, a joint beyond its range: :func:`ikseries.joints.joint_range_checks`, ...)
and hands them to :func:`raise_first_unreachable`, which raises one
:class:`~ikseries.kinematics.UnreachableError` for the first bad target in C order, with the
reason of the first failing check there.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from .fit import interval as ia
from .joints import ANGLE_SLACK_DEG, Check
from .kinematics import UnreachableError, format_point

__all__ = ["raise_first_unreachable", "prove_box_reachable", "ReachUnprovenError", "REACH_MAX_CELLS", "check_no_wrap",
           "WRAP_JUMP_DEG"]


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
    raise UnreachableError(f"target {format_point(names, point)} is unreachable: {why(i)}")


# -- the whole workspace box ------------------------------------------------------------------
#: Interval cells :func:`prove_box_reachable` evaluates before it gives up.
REACH_MAX_CELLS = 50_000
#: Cells per input of its starting grid.
REACH_INITIAL_CELLS = 4


class ReachUnprovenError(ValueError):
    """Interval analysis could not establish that a whole box is reachable (nor find a point
    that is not) within its cell budget."""


def _cells_reachable(geometry, lo, hi) -> np.ndarray:
    """Per cell [lo, hi] (shape (N, n)): True where interval evaluation of ``geometry.angles``
    proves every point of the cell inside the formula's domain, every angle finite and (for a
    geometry with ``joint_ranges``) within those ranges: the servo angles of
    :mod:`ikseries.joints`, which ``angles`` returns, against the configured ranges."""
    with ia.lenient(), np.errstate(all="ignore"):
        angles = geometry.angles(ia.MATH, *ia.variables(lo, hi, order=0))
    ranges = getattr(geometry, "joint_ranges", None) or [(-np.inf, np.inf)] * len(angles)
    ok = np.ones(len(lo), dtype=bool)
    for a, (jlo, jhi) in zip(angles, ranges):
        a = ia.point(a) if not isinstance(a, ia.Interval) else a
        alo = np.broadcast_to(a.lo, ok.shape)
        ahi = np.broadcast_to(a.hi, ok.shape)
        # the joint check of ``ik`` has the same slack, so the two agree on a range end
        ok &= (np.isfinite(alo) & np.isfinite(ahi)
               & (alo >= jlo - ANGLE_SLACK_DEG) & (ahi <= jhi + ANGLE_SLACK_DEG))
    return ok


def _grid(lo, hi, per_axis: int) -> tuple[np.ndarray, np.ndarray]:
    """``per_axis`` equal cells along each side of the box [lo, hi]."""
    sides = [np.linspace(a, b, per_axis + 1) for a, b in zip(lo, hi)]
    idx = [g.ravel() for g in np.meshgrid(*(np.arange(per_axis),) * len(lo), indexing="ij")]
    cl = np.stack([s[i] for s, i in zip(sides, idx)], 1)
    ch = np.stack([s[i + 1] for s, i in zip(sides, idx)], 1)
    return cl, ch


def prove_box_reachable(geometry, lo, hi, *, max_cells: int = REACH_MAX_CELLS) -> int:
    """Establish that every target in the box [lo, hi] is reachable by ``geometry``.

    The box is covered by cells; on each, ``geometry.angles`` is evaluated in interval
    arithmetic (:mod:`ikseries.fit.interval`). A cell is proven when no operation leaves its
    domain (no square root of a negative, no ``acos`` beyond [-1, 1], no division by an
    interval holding 0, no ``atan2`` across its cut) and every joint lies within the
    geometry's ``joint_ranges``. An unproven cell's centre is checked by ``geometry.ik`` and
    the cell bisected along its relatively widest side.

    Parameters
    ----------
    geometry : object
        A geometry with ``angles(xp, *inputs)`` and ``ik(*inputs)``.
    lo, hi : sequence of float
        The box, one bound per input (``geometry.inputs`` order).
    max_cells : int
        Cells evaluated before giving up.

    Returns
    -------
    int
        Cells evaluated.

    Raises
    ------
    UnreachableError
        From ``geometry.ik``, naming a sampled target that is unreachable and why.
    ReachUnprovenError
        When the budget is spent (or a cell cannot be split) with cells still unproven.
    """
    box_lo, box_hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    width = np.where(box_hi > box_lo, box_hi - box_lo, 1.0)
    cl, ch = _grid(box_lo, box_hi, REACH_INITIAL_CELLS)
    evaluated = 0
    while len(cl):
        ok = _cells_reachable(geometry, cl, ch)
        evaluated += len(cl)
        cl, ch = cl[~ok], ch[~ok]
        if not len(cl):
            return evaluated
        geometry.ik(*(0.5 * (cl + ch)).T)       # raises for an unreachable centre
        axis = np.argmax((ch - cl) / width, axis=1)
        rows = np.arange(len(cl))
        mid = 0.5 * (cl[rows, axis] + ch[rows, axis])
        if evaluated + 2 * len(cl) > max_cells or np.any((mid <= cl[rows, axis]) | (mid >= ch[rows, axis])):
            c = 0.5 * (cl[0] + ch[0])
            raise ReachUnprovenError(
                f"could not establish that every target is reachable: after {evaluated} cells of "
                f"interval analysis {len(cl)} remain open, the first near "
                f"{format_point(geometry.inputs, c)}; keep the box clear of the reach and joint limits")
        lo2, hi1 = cl.copy(), ch.copy()
        hi1[rows, axis] = mid
        lo2[rows, axis] = mid
        cl, ch = np.concatenate([cl, lo2]), np.concatenate([hi1, ch])
    return evaluated


#: neighbouring grid targets whose servo angles differ by more than this (deg) straddle a wrap
#: (a jump of nearly a full turn; a pass through a singular pose jumps by about half a turn, and
#: is left to the reach proof and the singularity checks, which name it as such)
WRAP_JUMP_DEG = 270.0


def check_no_wrap(geometry, names: Sequence[str], shape: tuple[int, ...], coords: Sequence[np.ndarray],
                  angles: Sequence[np.ndarray]) -> None:
    """Fail (:class:`UnreachableError`, one line) where a servo angle wraps inside the box: two
    neighbouring targets of the grid (``coords``, flat in C order over ``shape``) whose angles
    differ by more than :data:`WRAP_JUMP_DEG`, a jump of a full turn no servo can follow and no
    polynomial can fit (the angle is continuous everywhere else)."""
    labels = getattr(geometry, "servo_names", geometry.servos)
    for s, label, a in zip(geometry.servos, labels, angles):
        grid = np.reshape(np.asarray(a, dtype=np.float64), shape)
        for axis in range(len(shape)):
            jump = np.abs(np.diff(grid, axis=axis)) > WRAP_JUMP_DEG
            if not np.any(jump):
                continue
            i = np.unravel_index(int(np.flatnonzero(jump)[0]), jump.shape)
            j = tuple(v + (k == axis) for k, v in enumerate(i))
            at = [np.ravel_multi_index(p, shape) for p in (i, j)]
            p, q = (format_point(names, [np.ravel(c)[n] for c in coords]) for n in at)
            raise UnreachableError(f"servo {s} ({label}) angle wraps inside the box: {grid[i]:.4g} deg at target "
                                   f"{p}, {grid[j]:.4g} deg at its neighbour {q} (a jump of a full turn no servo "
                                   "can follow); move the box off the angle's wrap")
