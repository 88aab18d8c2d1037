"""Size a CORDIC leg solver: the fewest iterations and narrowest formats meeting the tolerance.

The error is measured on the bit-exact model (``ikseries.sim.cordic_golden``) against the exact
pulse widths, on the same points as the polynomial design (``ikseries.accuracy.
verification_points``: >= 10**6 representable workspace points), as the emitted pulse width
minus the exact one, in pulse units, like ``ikseries.accuracy.measure``'s "total".

Search: starting from a design that meets the tolerance, each parameter in turn (iterations
first: they cost pipeline stages; then the formats) is bisected down to the smallest value that
still meets it with the others fixed; the sweep repeats until nothing changes. The result
meets the tolerance on every point, and lowering any single parameter by one breaks it (checked
by the sweep); it is a local minimum, not a global one over all parameter combinations.
Candidates are first screened on the worst points seen so far, and only survivors are
measured on the whole set.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from ...accuracy import verification_points
from ...sim import cordic_golden
from .cordic import DEFAULT_DESIGN, ITERATION_FIELDS, WIDTH_FIELDS, CordicDesign, CordicPlan

__all__ = ["SizingError", "measure_cordic", "size_cordic", "SEARCH_ORDER"]

SEARCH_ORDER = ("law_iters", "uv_iters", "xy_iters", "rot_iters",
                "angle_frac", "len_frac", "area_frac", "gain_frac", "scale_frac")
_SCREEN = 3000   # worst points per servo kept for screening


class SizingError(RuntimeError):
    """No CORDIC design within the search range meets the tolerance."""


def _reference(robot, points: dict) -> tuple:
    real = [np.asarray(points[i.name]) * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]
    return robot.pulses_pu(*real)


def measure_cordic(robot, design: CordicDesign, points: dict | None = None, reference=None) -> dict:
    """Max |emitted - exact| pulse width (pu) per servo on ``points`` (default: the
    verification points), and where it occurs."""
    points = verification_points(robot) if points is None else points
    reference = _reference(robot, points) if reference is None else reference
    err = cordic_golden.errors_pu(robot, design, points, reference)
    out = {}
    for s, e in err.items():
        j = int(np.argmax(np.abs(e)))
        out[s] = {"total": float(np.abs(e[j])),
                  "at": {i.name: float(points[i.name][j] * 2.0 ** -i.frac_bits) for i in robot.workspace.inputs}}
    return {"points": int(len(next(iter(points.values())))), "servos": out}


def _lowest(name: str, robot) -> int:
    if name in ITERATION_FIELDS:
        return 1
    if name == "angle_frac":
        return robot.workspace.inputs[1].frac_bits
    return 0


def size_cordic(robot, points: dict | None = None, start: CordicDesign = DEFAULT_DESIGN,
                margin_pu: float = 0.0, progress: Callable[[str], None] = lambda msg: None
                ) -> CordicDesign:
    """The smallest :class:`CordicDesign` (see the module docstring) whose max error on
    ``points`` (default: ``verification_points(robot)``) is within ``robot.fit.tolerance_pu -
    margin_pu`` for every servo.

    Raises
    ------
    SizingError
        If ``start`` itself does not meet the tolerance.
    ValueError
        For a negative ``margin_pu`` or one that leaves no tolerance.
    """
    if isinstance(margin_pu, bool) or not isinstance(margin_pu, (int, float)) \
            or not 0 <= margin_pu < robot.fit.tolerance_pu:
        raise ValueError(f"margin_pu must be in [0, {robot.fit.tolerance_pu:g}) pu, not {margin_pu!r}")
    if not isinstance(start, CordicDesign):
        raise TypeError(f"start must be a CordicDesign, not {start!r}")
    points = verification_points(robot) if points is None else points
    reference = _reference(robot, points)
    limit = robot.fit.tolerance_pu - margin_pu
    n = len(next(iter(points.values())))
    recent: list = []          # worst points of the last full evaluations
    screen = np.zeros(0, dtype=np.int64)
    evaluations = {"screened out": 0, "full": 0}

    def worst(err: dict, idx) -> float:
        return max(float(np.max(np.abs(e))) for e in err.values()) if len(idx) else 0.0

    def errors(design, idx):
        sub = {k: np.asarray(v)[idx] for k, v in points.items()}
        ref = tuple(np.asarray(r)[idx] for r in reference)
        return cordic_golden.errors_pu(robot, design, sub, ref)

    def meets(design) -> bool:
        nonlocal screen
        try:
            CordicPlan(robot, design)
        except OverflowError:      # too wide for the 63-bit model: not a candidate
            return False
        if worst(errors(design, screen), screen) > limit:
            evaluations["screened out"] += 1
            return False
        evaluations["full"] += 1
        err = errors(design, slice(None))
        bad = worst(err, range(n)) > limit
        # keep the worst points of every servo for screening the next candidates
        worst_idx = [np.argpartition(-np.abs(e), min(_SCREEN, n - 1))[:_SCREEN] for e in err.values()]
        recent.append(np.concatenate(worst_idx))
        del recent[:-8]
        screen = np.unique(np.concatenate(recent))
        return not bad

    if not meets(start):
        raise SizingError(f"the starting CORDIC design {start} does not meet the tolerance of "
                          f"{limit:g} pu; start from more iterations / wider formats")
    best = start
    changed = True
    sweep = 0
    while changed:
        changed = False
        sweep += 1
        for name in SEARCH_ORDER:
            lo, hi = _lowest(name, robot), getattr(best, name)
            while lo < hi:
                mid = (lo + hi) // 2
                if meets(dataclasses.replace(best, **{name: mid})):
                    hi = mid
                else:
                    lo = mid + 1
            if hi != getattr(best, name):
                best = dataclasses.replace(best, **{name: hi})
                changed = True
                progress(f"  sweep {sweep}: {name} = {hi}")
    progress(f"sized CORDIC design: {best.as_dict()} ({evaluations['full']} full evaluations on "
             f"{n:,} points, {evaluations['screened out']} candidates screened out)")
    return best
