"""Accuracy of a plan against the reference IK on >= 10**6 representable workspace points.

Error split per servo (all in pulse units):
- approximation: the plan in exact arithmetic (float coefficients, no truncation) vs the reference;
- quantization: the integer accumulator before output rounding vs that exact-arithmetic value;
- rounding: the emitted tick count vs the accumulator before rounding;
- total: the emitted pulse width vs the reference pulse width.
"""
from __future__ import annotations

import numpy as np

from .sim import golden

__all__ = ["verification_points", "measure"]


def verification_points(robot, n_points: int = 1_000_000, n_face: int = 10_000, seed: int = 1,
                        grid_points: int = 640_000) -> dict:
    """Port integers: a dense grid + every face of the workspace box + random points, at
    least ``n_points`` in all (or every representable point if there are fewer).

    The grid has about ``grid_points`` points spread evenly over the axes (never finer than
    the port grid), e.g. 86 x 86 x 86 for a 3-input robot.
    """
    specs = robot.workspace.inputs
    rng = np.random.default_rng(seed)
    every = int(np.prod([i.hi - i.lo + 1 for i in specs], dtype=np.float64)) <= n_points
    per_axis = max(2, round(grid_points ** (1 / len(specs))))
    axes = []
    for i in specs:
        step = 1 if every else max(1, round((i.hi - i.lo) / (per_axis - 1)))
        axes.append(np.unique(np.append(np.arange(i.lo, i.hi + 1, step), i.hi)))
    grid = np.meshgrid(*axes, indexing="ij")
    cols = [[g.ravel()] for g in grid]
    for k, i in enumerate(specs):
        for v in (i.lo, i.hi):
            for j, s in enumerate(specs):
                cols[j].append(np.full(n_face, v) if j == k else rng.integers(s.lo, s.hi + 1, n_face))
    have = sum(len(a) for a in cols[0])
    n_random = 0 if every else max(0, n_points - have)   # else the grid holds every point
    for c, i in zip(cols, specs):
        c.append(rng.integers(i.lo, i.hi + 1, n_random))
    return {i.name: np.concatenate(c).astype(np.int64) for i, c in zip(specs, cols)}


def measure(robot, plan, points: dict | None = None, chunk: int = 200_000) -> dict:
    """Max |error| per servo and component, and where the total maximum occurs."""
    points = verification_points(robot) if points is None else points
    n = len(next(iter(points.values())))
    names = [o.name for o in plan.outputs]
    worst = {s: {"approximation": 0.0, "quantization": 0.0, "rounding": 0.0, "total": 0.0, "at": None}
             for s in names}
    keep = {o.node for o in plan.outputs} | {o.preround for o in plan.outputs}
    for start in range(0, n, chunk):
        ints = {k: v[start:start + chunk] for k, v in points.items()}
        real = [ints[i.name] * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]
        ref = robot.pulses_pu(*real)
        iv = golden.evaluate(plan, ints, keep)
        fv = golden.evaluate_ideal(plan, ints, {o.preround for o in plan.outputs})
        for k, o in enumerate(plan.outputs):
            tpp = o.ticks_per_pu
            pre_int = iv[o.preround] * 2.0 ** -plan.nodes[o.preround].frac
            out = iv[o.node].astype(np.float64)
            comp = {"approximation": fv[o.preround] / tpp - ref[k],
                    "quantization": (pre_int - fv[o.preround]) / tpp,
                    "rounding": (out - pre_int) / tpp,
                    "total": out / tpp - ref[k]}
            w = worst[o.name]
            for key, e in comp.items():
                m = float(np.max(np.abs(e)))
                if key == "total" and m > w["total"]:
                    j = int(np.argmax(np.abs(e)))
                    w["at"] = {i.name: float(real[q][j]) for q, i in enumerate(robot.workspace.inputs)}
                w[key] = max(w[key], m)
    return {"points": n, "servos": worst}
