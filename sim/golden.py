"""Bit-exact integer model of an evaluation plan (numpy, vectorised).

This is exactly the arithmetic the generated hardware performs: the same
operations, in the same order, with the same truncations. ``evaluate_ideal``
runs the same dataflow in float64 with unrounded constants and exact shifts,
which separates the approximation error from the quantization error.
"""
from __future__ import annotations

import numpy as np

from ..fit.plan import Plan

__all__ = ["evaluate", "evaluate_ideal", "quantize_inputs", "outputs", "port_values"]


def quantize_inputs(plan: Plan, values: dict) -> dict:
    """Real input values -> port integers (rounded to nearest, clamped to the range)."""
    out = {}
    for i in plan.inputs:
        q = np.rint(np.asarray(values[i.name], dtype=np.float64) * 2.0 ** i.frac).astype(np.int64)
        out[i.name] = np.clip(q, i.lo, i.hi)
    return out


def port_values(plan, ints: dict) -> dict:
    """Port integers by input name as int64 arrays, checked against each port's range (for a
    :class:`Plan` or anything with such ``inputs``, e.g. a CORDIC plan)."""
    vals = {}
    for i in plan.inputs:
        v = np.asarray(ints[i.name], dtype=np.int64)
        lo, hi = i.port_range
        if v.size and (v.min() < lo or v.max() > hi):
            raise ValueError(f"input {i.name} must fit its {i.width}-bit port "
                             f"[{lo}, {hi}], not {int(v.min() if v.min() < lo else v.max())}")
        vals[i.name] = v
    return vals


def _last_use(plan: Plan, keep) -> list[int]:
    last = list(range(len(plan.nodes)))
    for i, n in enumerate(plan.nodes):
        for a in n.args:
            last[a] = i
    for k in keep:
        last[k] = len(plan.nodes)
    return last


def _run(plan: Plan, ints: dict, keep, step) -> dict:
    """Evaluate node by node with ``step``; returns {node: value} for ``keep`` (all if None)."""
    ports = port_values(plan, ints)
    keep = range(len(plan.nodes)) if keep is None else keep
    last = _last_use(plan, keep)
    vals: dict = {}
    for i, n in enumerate(plan.nodes):
        vals[i] = step(n, ports, vals)
        for a in set(n.args):
            if last[a] == i:
                del vals[a]
    return {k: vals[k] for k in keep}


def _int_step(n, ports, vals):
    op = n.op
    if op == "input":
        return ports[n.param]
    if op == "const":
        return np.int64(n.param)
    a = vals[n.args[0]]
    if op == "add":
        return a + vals[n.args[1]]
    if op == "mul":
        return a * vals[n.args[1]]
    if op == "shr":
        return a >> n.param
    if op == "shl":
        return a << n.param
    if op == "clamp":
        return np.clip(a, n.param[0], n.param[1])
    if op == "index":
        return a >> n.param
    if op == "mask":
        return a & ((1 << n.param) - 1)
    if op == "lut":
        return np.asarray(n.param, dtype=np.int64)[a]
    return a  # frac: same integer


def evaluate(plan: Plan, ints: dict, keep=None) -> dict:
    """Integer value of the nodes in ``keep`` (all if None) for port integers ``ints``."""
    return _run(plan, ints, keep, _int_step)


def evaluate_ideal(plan: Plan, ints: dict, keep=None) -> dict:
    """Real value of the nodes in ``keep`` in float64: unrounded constants, exact shifts."""
    nodes = plan.nodes

    def step(n, ports, vals):
        op = n.op
        if op == "input":
            return ports[n.param] * 2.0 ** -n.frac
        if op == "const":
            return n.ideal if n.ideal is not None else n.param * 2.0 ** -n.frac
        a = vals[n.args[0]]
        if op == "add":
            return a + vals[n.args[1]]
        if op == "mul":
            return a * vals[n.args[1]]
        if op == "clamp":
            return np.clip(a, n.param[0] * 2.0 ** -n.frac, n.param[1] * 2.0 ** -n.frac)
        if op == "frac":
            return a * 2.0 ** (nodes[n.args[0]].frac - n.frac)
        if op in ("index", "mask"):  # cells of 2**s integers of the argument
            cell = np.floor(a * 2.0 ** (nodes[n.args[0]].frac - n.param))
            return cell.astype(np.int64) if op == "index" else a - cell * 2.0 ** (n.param - nodes[n.args[0]].frac)
        if op == "lut":
            return np.asarray(n.ideal if n.ideal is not None else n.param, dtype=np.float64)[a] * (
                1.0 if n.ideal is not None else 2.0 ** -n.frac)
        return a  # shr, shl: exact in real arithmetic
    return _run(plan, ints, keep, step)


def outputs(plan: Plan, ints: dict) -> dict:
    """Output integers (PWM clock ticks) per servo name."""
    vals = evaluate(plan, ints, keep={o.node for o in plan.outputs})
    n = max(np.size(v) for v in ints.values()) if ints else 1
    return {o.name: np.broadcast_to(vals[o.node], (n,)).astype(np.int64) for o in plan.outputs}
