"""Test targets shared by every simulation: corners of the input ranges and random points."""
from __future__ import annotations

import itertools

import numpy as np

from ..fit.plan import Plan

__all__ = ["corner_targets", "random_targets"]


def _grid(plan: Plan, values_per_input) -> dict:
    combos = list(dict.fromkeys(itertools.product(*values_per_input)))
    return {i.name: np.array([c[k] for c in combos], dtype=np.int64) for k, i in enumerate(plan.inputs)}


def corner_targets(plan: Plan, port_extremes: bool = False) -> dict:
    """Every combination of each input's lo / hi (and 0 when inside the range); with
    ``port_extremes``, then every combination of each port's extreme values (out of range:
    the core clamps them to the range)."""
    out = _grid(plan, [sorted({i.lo, i.hi} | ({0} if i.lo <= 0 <= i.hi else set())) for i in plan.inputs])
    if port_extremes:
        ext = _grid(plan, [sorted(set(i.port_range)) for i in plan.inputs])
        out = {n: np.concatenate([out[n], ext[n]]) for n in out}
    return out


def random_targets(plan: Plan, n: int, rng) -> dict:
    """``n`` uniformly random in-range targets; ``rng`` is a seed or a numpy Generator."""
    rng = np.random.default_rng(rng)
    return {i.name: rng.integers(i.lo, i.hi + 1, n, dtype=np.int64) for i in plan.inputs}
