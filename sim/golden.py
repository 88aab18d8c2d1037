"""Bit-exact integer model of an evaluation plan (numpy, vectorised).

This is exactly the arithmetic the generated hardware performs: the same
operations, in the same order, with the same truncations. ``evaluate_ideal``
runs the same dataflow in float64 with unrounded constants and exact shifts,
which separates the approximation error from the quantization error. Each
operation's meaning in both is its entry of :data:`ikseries.fit.ops.OPS`.
"""
from __future__ import annotations

import numpy as np

from ..fit.ops import OPS
from ..fit.plan import Plan

__all__ = ["evaluate", "evaluate_ideal", "quantize_inputs", "outputs", "port_values", "robot_outputs"]


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
    return OPS[n.op].integer(n, [vals[a] for a in n.args], ports)


def evaluate(plan: Plan, ints: dict, keep=None) -> dict:
    """Integer value of the nodes in ``keep`` (all if None) for port integers ``ints``."""
    return _run(plan, ints, keep, _int_step)


def evaluate_ideal(plan: Plan, ints: dict, keep=None) -> dict:
    """Real value of the nodes in ``keep`` in float64: unrounded constants, exact shifts."""
    nodes = plan.nodes

    def step(n, ports, vals):
        return OPS[n.op].real(n, [nodes[a] for a in n.args], [vals[a] for a in n.args], ports)
    return _run(plan, ints, keep, step)


def outputs(plan: Plan, ints: dict) -> dict:
    """Output integers (PWM clock ticks) per servo name."""
    vals = evaluate(plan, ints, keep={o.node for o in plan.outputs})
    n = max(np.size(v) for v in ints.values()) if ints else 1
    return {o.name: np.broadcast_to(vals[o.node], (n,)).astype(np.int64) for o in plan.outputs}


def robot_outputs(plan: Plan, table, legs, ints: dict) -> dict:
    """Channel widths (ticks) per servo of a robot core for port integers ``ints`` addressed
    to ``legs`` (one leg index per target): the channel table's input mirror, the plan, the
    table's per-channel constants (:class:`ikseries.fit.channels.ChannelTable`; None: the plan's
    widths, a core without a table)."""
    if table is None:
        return outputs(plan, ints)
    return table.apply(legs, outputs(plan, table.mirror_inputs(plan, legs, ints)))
