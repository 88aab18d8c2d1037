"""The op table is the single source of every plan operation's meaning.

Every reader (plan, golden model, certifier, the pipelined, modulo and folded cores) takes an
operation from :data:`ikseries.fit.ops.OPS`: a throwaway op registered in the table runs through
all of them, and every op of the table is used by the tiny plans the cores are checked on.
"""
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers import (all_ports, check_exhaustively, signed_cell_plan, simulate_bit_exact, tiny_piecewise_plan,
                     tiny_plan)
from ikseries.fit import interval as ia
from ikseries.fit import ops
from ikseries.fit.certify import _plan_function
from ikseries.fit.plan import REGISTERED_OPS, Plan, PlanBuilder, PlanInput, PlanOutput
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.hdl.folded import FoldedEvaluator
from ikseries.hdl.modulo import ModuloEvaluator
from ikseries.sim import golden

DATA = Path(__file__).parent / "data"

# floor(a / 4) with two fractional bits fewer: a shift view of its own, no parameter
QUARTER = replace(ops.OPS["shr"], name="quarter", bounds=lambda a, frac, param, ideal, inputs: (
                      a[0].lo >> 2, a[0].hi >> 2),
                  integer=lambda n, x, ports: x[0] >> 2,
                  rounding=lambda n, a, e: e[0] + 0.75 * 2.0 ** -n.frac,
                  rtl=lambda n, x: x[0] >> 2, view=lambda n: (2, 0))
# a - b, registered logic (the folded ALU has no program for it)
SUB = replace(ops.OPS["add"], name="sub", bounds=lambda a, frac, param, ideal, inputs: (
                  a[0].lo - a[1].hi, a[0].hi - a[1].lo),
              integer=lambda n, x, ports: x[0] - x[1], real=lambda n, a, x, ports: x[0] - x[1],
              enclose=lambda n, nodes, x, inputs: x[0] - x[1], rtl=lambda n, x: x[0] - x[1])


def _new_op_plan(op_name, args_of):
    """``tiny_plan``'s inputs, ``op_name`` applied to ``args_of(b, a, bb)``, clamped and rounded."""
    inputs = [PlanInput("a", "mm", 2, 0, 12, 4, False), PlanInput("b", "deg", 1, -10, 9, 5, True)]
    b = PlanBuilder(inputs)
    a, bb = b.input_nodes["a"], b.input_nodes["b"]
    args, frac = args_of(b, a, bb)
    y = b.op(op_name, args, frac)
    acc = b.add(b.mul(y, b.const(0.7, 3)), b.const(1.25, 5))
    out = b.clamp(b.round(acc, 0), -20, 20)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0), PlanOutput("raw", y, y, "ticks", 1.0)])


def _check_everywhere(plan, want_raw, folded=True):
    """Intervals, rounding bound, the op's integer value ``want_raw(ports)``, JSON round trip,
    the certifier's enclosure of every node at every port point, and every core bit-exact."""
    check_exhaustively(plan)
    ports = all_ports(plan)
    raw = plan.outputs[1].node
    assert np.array_equal(golden.evaluate(plan, ports)[raw], want_raw(ports))
    assert Plan.from_json(json.loads(plan.dumps())).dumps() == plan.dumps()
    ideal = golden.evaluate_ideal(plan, ports)
    box = {i.name: ia.Interval(np.asarray(ports[i.name] * 2.0 ** -i.frac, dtype=np.float64),
                               np.asarray(ports[i.name] * 2.0 ** -i.frac, dtype=np.float64)) for i in plan.inputs}
    for k in plan.cone(plan.outputs[0].preround):
        e = _plan_function(plan, k)(box)
        v = np.broadcast_to(ideal[k], ports["a"].shape)
        assert np.all((e.lo <= v + 1e-12) & (v - 1e-12 <= e.hi)), plan.nodes[k].op
    simulate_bit_exact(PlanEvaluator(plan), plan, ports)
    simulate_bit_exact(ModuloEvaluator(plan, 2, dsp=(4, 4)), plan, ports)
    if folded:
        simulate_bit_exact(FoldedEvaluator(plan, multipliers=1, dsp=(4, 4)), plan, ports)


def test_a_view_op_registered_in_the_table_runs_through_every_reader(monkeypatch):
    monkeypatch.setitem(ops.OPS, "quarter", QUARTER)
    plan = _new_op_plan("quarter", lambda b, a, bb: ((bb,), b.frac(bb) - 2))
    assert [n.op for n in plan.nodes].count("quarter") == 1
    assert plan.stages()[plan.outputs[1].node] == plan.stages()[plan.nodes[plan.outputs[1].node].args[0]]
    _check_everywhere(plan, lambda p: np.clip(p["b"], -10, 9) >> 2)


def test_a_logic_op_registered_in_the_table_runs_through_every_reader_but_the_fixed_alu(monkeypatch):
    monkeypatch.setitem(ops.OPS, "sub", SUB)
    plan = _new_op_plan("sub", lambda b, a, bb: ((b.reinterpret(a, 1), bb), 1))
    node = plan.outputs[1].node
    assert plan.stages()[node] == max(plan.stages()[a] for a in plan.nodes[node].args) + 1   # registered
    _check_everywhere(plan, lambda p: np.clip(p["a"], 0, 12) - np.clip(p["b"], -10, 9), folded=False)
    with pytest.raises(ValueError, match="folded machine can compute .* add, mask, clamp\\), not 'sub'"):
        FoldedEvaluator(plan)


def test_an_op_missing_from_the_table_is_refused():
    plan = tiny_plan(0)
    with pytest.raises(ValueError, match="bad plan operation 'sub' with 2 operands"):
        PlanBuilder(plan.inputs).op("sub", (0, 1), 0)
    d = plan.to_json()
    next(nd for nd in d["nodes"] if len(nd["args"]) == 1)["op"] = "quarter"
    with pytest.raises(ValueError, match="bad plan operation 'quarter' with 1 operands"):
        Plan.from_json(d)


def test_every_op_of_the_table_is_used_by_the_plans_the_cores_are_checked_on():
    used = {n.op for p in (tiny_plan(0), tiny_piecewise_plan(0), signed_cell_plan()) for n in p.nodes}
    assert used == set(ops.OPS)
    assert REGISTERED_OPS == {"add", "mul", "clamp", "lut"}
    assert {n for n, o in ops.OPS.items() if o.wiring} == {"shr", "shl", "frac", "index", "mask"}


def _as_version_2(text: str) -> str:
    """A version 1 plan text as version 2 writes it (the depth no longer called latency)."""
    d = json.loads(text)
    d["version"], d["depth"] = 2, d.pop("latency")
    return json.dumps(d, indent=1, sort_keys=True) + "\n"


def test_plans_written_before_load_and_round_trip_to_the_same_text():
    """Plan JSON (version 1) written by the plan module before it read the op table
    (tests/data/plans_v1.json) loads, and is written again with nothing changed but the version
    and the name of the depth."""
    made = {"tiny_plan_2": tiny_plan(2), "tiny_piecewise_plan_1": tiny_piecewise_plan(1),
            "signed_cell_plan": signed_cell_plan(), "tiny_plan_0_dsp": tiny_plan(0, operand_bits=(4, 4))}
    # the builder since adds the rounding half where it waits for no product: one stage fewer
    shallower = {"tiny_piecewise_plan_1", "tiny_plan_0_dsp", "tiny_plan_2"}
    stored = json.loads((DATA / "plans_v1.json").read_text())
    assert set(stored) == set(made)
    for name, text in stored.items():
        assert json.loads(text)["version"] == 1
        assert Plan.from_json(json.loads(text)).dumps() == _as_version_2(text), name
        if name in shallower:
            assert made[name].depth == json.loads(text)["latency"] - 1, name
        else:
            assert made[name].dumps() == _as_version_2(text), name


def test_a_plan_of_an_unknown_version_or_a_wrong_depth_is_refused(plan):
    d = plan.to_json()
    with pytest.raises(ValueError, match=r"^plan version must be one of 1, 2, not 3$"):
        Plan.from_json({**d, "version": 3})
    with pytest.raises(ValueError, match=rf"^plan depth {plan.depth + 1} does not match the recomputed {plan.depth}$"):
        Plan.from_json({**d, "depth": plan.depth + 1})


def test_the_suite_plan_round_trips(plan):
    assert Plan.from_json(json.loads(plan.dumps())).dumps() == plan.dumps()


@pytest.mark.parametrize("op, value, msg", [
    ("clamp", 3, r"plan node \d+: the param of a clamp node must be a list, not 3"),
    ("shr", [1, 2], r"plan node \d+: the param of a shr node must be a number or a name, not \[1, 2\]"),
])
def test_a_param_of_the_wrong_json_form_is_refused(op, value, msg):
    d = tiny_plan(0).to_json()
    next(nd for nd in d["nodes"] if nd["op"] == op)["param"] = value
    with pytest.raises(ValueError, match=msg):
        Plan.from_json(d)


def test_an_op_of_an_unknown_kind_is_refused():
    with pytest.raises(ValueError, match="op neg: kind must be one of port, constant, logic, product, table, "
                                         "wiring, not 'alu'"):
        replace(ops.OPS["add"], name="neg", kind="alu")
