"""Bit-exact integer model of the CORDIC leg solver (numpy int64, vectorised).

It runs the same datapath description as the RTL (:func:`ikseries.fit.baselines.cordic.datapath`):
same operations, same order, same truncations, and the CORDIC gain compensation by the same
integer constants. Every pipeline register value is checked against the register's analysed
range (:attr:`CordicPlan.layout`): a value outside it would overflow the hardware register,
and raises :class:`OverflowError`.
"""
from __future__ import annotations

import numpy as np

from ..fit.baselines.cordic import CordicDesign, CordicPlan, OperatorOps, datapath
from .golden import port_values

__all__ = ["NumpyOps", "evaluate", "outputs", "errors_pu"]


class NumpyOps(OperatorOps):
    """Datapath back end over int64 arrays (exact: the analysis bounds every value < 2**62).

    ``observed`` collects, per register ``(stage, name)``, the (min, max) actually seen."""

    analysis = False

    def __init__(self, layout: list[dict], ports: dict, check: bool = True):
        self._layout = layout
        self._ports = ports
        self._check = check
        self._stage = 0
        self._checked: dict[int, tuple] = {}   # id(array) -> (array, lo, hi) already checked
        self.observed: list[dict] = []

    def port(self, name):
        return self._ports[name]

    def c(self, v):
        return np.int64(v)

    def mulc(self, a, c):
        return a * np.int64(c)

    def addsub(self, a, b, sub):
        return np.where(sub, a - b, a + b)

    def or_(self, a, b):
        return a | b

    def mux(self, c, a, b):
        return np.where(c, a, b)

    def clamp(self, a, lo=None, hi=None):
        return np.clip(a, lo, hi)

    def stage(self, name, vals, hints=None):
        bounds = self._layout[self._stage]
        seen = {}
        for k, v in vals.items():
            lo, hi = bounds[k]
            hit = self._checked.get(id(v))
            if hit is not None and hit[0] is v and hit[1] >= lo and hit[2] <= hi:
                seen[k] = (hit[1], hit[2])
                continue
            arr = np.asarray(v)
            vmin, vmax = (int(arr.min()), int(arr.max())) if arr.size else (lo, hi)
            if self._check and (vmin < lo or vmax > hi):
                raise OverflowError(f"CORDIC register {name}.{k} (stage {self._stage + 1}) took "
                                    f"{vmin if vmin < lo else vmax}, outside its analysed range [{lo}, {hi}]")
            self._checked[id(v)] = (v, vmin, vmax)
            seen[k] = (vmin, vmax)
        self.observed.append(seen)
        self._stage += 1
        return vals


def evaluate(cp: CordicPlan, ints: dict, check: bool = True) -> tuple[dict, list[dict]]:
    """Output ticks per servo and the observed (min, max) of every register, for port integers
    ``ints`` (one int array per input name). Raises OverflowError (with ``check``) if any
    register value leaves its analysed range."""
    ports = port_values(cp, ints)
    n = max(np.size(v) for v in ports.values())
    ports = {k: np.broadcast_to(v, (n,)) for k, v in ports.items()}
    ops = NumpyOps(cp.layout, ports, check)
    out = datapath(ops, cp)
    return {s: np.broadcast_to(out[s], (n,)).astype(np.int64) for s in cp.servos}, ops.observed


def outputs(robot, design: CordicDesign, ints: dict, chunk: int = 250_000) -> dict:
    """Output integers (PWM clock ticks) per servo for port integers ``ints`` (range-checked)."""
    cp = design if isinstance(design, CordicPlan) else CordicPlan(robot, design)
    n = max(np.size(v) for v in ints.values())
    parts = {s: [] for s in cp.servos}
    for start in range(0, n, chunk):
        o, _ = evaluate(cp, {k: np.broadcast_to(np.asarray(v), (n,))[start:start + chunk]
                             for k, v in ints.items()})
        for s in cp.servos:
            parts[s].append(o[s])
    return {s: np.concatenate(p) if p else np.zeros(0, np.int64) for s, p in parts.items()}


def errors_pu(robot, design, ints: dict, reference=None, chunk: int = 250_000) -> dict:
    """Signed error (pu) per servo of the emitted ticks against the exact pulse widths.

    ``reference`` (per-servo float pu arrays for ``ints``) may be passed to skip recomputing it.
    """
    if reference is None:
        real = [np.asarray(ints[i.name]) * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]
        reference = robot.pulses_pu(*real)
    out = outputs(robot, design, ints, chunk)
    tpp = robot.ticks_per_pu
    return {s: out[s] / tpp - np.asarray(reference[j]) for j, s in enumerate(robot.servos)}
