"""Amaranth simulation of the generated RTL against the golden model."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from amaranth.sim import Simulator

from helpers import all_ports, signed_cell_plan, simulate_bit_exact, tiny_grid_plan, tiny_piecewise_plan, tiny_plan
from ikseries.hdl.evaluator import PlanEvaluator, lut_groups, lut_rom_init, stored_field
from ikseries.hdl.leg import LegCore
from ikseries.hdl.pwm import ServoPWM
from ikseries.sim import golden
from ikseries.sim.targets import corner_targets, random_targets


@pytest.mark.parametrize("seed", range(3))
def test_evaluator_exhaustive_at_small_widths(seed):
    """Every port value (in range and clamped out-of-range) of a tiny plan, bit for bit."""
    plan = tiny_plan(seed)
    core = PlanEvaluator(plan)
    res = simulate_bit_exact(core, plan, all_ports(plan))
    assert set(res.latencies.tolist()) == {core.latency}


@pytest.mark.parametrize("seed, shift", [(0, 2), (1, 1), (2, 3)])
def test_evaluator_piecewise_exhaustive(seed, shift):
    """A piecewise plan (index / mask of input a, its coefficients from lut nodes sharing the
    cell index: one ROM), every port value, bit for bit, at the latency property; then with
    random backpressure and input gaps (a stall must hold the ROM read like a register)."""
    plan = tiny_piecewise_plan(seed, shift)
    core = PlanEvaluator(plan)
    assert plan.count("lut") > 1 and len(lut_groups(plan)) == 1
    t = all_ports(plan)
    res = simulate_bit_exact(core, plan, t)
    assert set(res.latencies.tolist()) == {core.latency} == {plan.depth}
    res = simulate_bit_exact(core, plan, t, ready_prob=0.5, valid_prob=0.6, seed=seed)
    assert res.latencies.min() == core.latency


def test_evaluator_grid_exhaustive():
    """A two-port grid plan (cells of a x cells of the signed b, the table address from both
    cell numbers), every port value, bit for bit, at the latency property, also under random
    backpressure."""
    plan = tiny_grid_plan(1, (1, 3))[0]
    core = PlanEvaluator(plan)
    assert len(lut_groups(plan)) == 1 and plan.count("index") == 2
    t = all_ports(plan)
    res = simulate_bit_exact(core, plan, t)
    assert set(res.latencies.tolist()) == {core.latency} == {plan.depth}
    simulate_bit_exact(core, plan, t, ready_prob=0.5, valid_prob=0.6, seed=3)


def test_evaluator_signed_cells_exhaustive():
    """index / mask of a signed input (negative cells, low bits of negative values) as outputs
    and as lut indices; a table whose first entries the index never takes."""
    plan = signed_cell_plan()
    core = PlanEvaluator(plan)
    res = simulate_bit_exact(core, plan, all_ports(plan))
    assert set(res.latencies.tolist()) == {core.latency}


def test_lut_rom_init_packs_fields_low_first():
    """Per index the tables side by side (first lut in the low bits, each its stored field:
    the low bits of its two's complement, under top bits every reached entry shares); entries
    below the index's interval are 0."""
    plan = signed_cell_plan()
    groups = lut_groups(plan)
    assert len(groups) == 2
    for index, luts in groups.items():
        init, width = lut_rom_init(plan, index, luts)
        (li,) = luts
        n, ix = plan.nodes[li], plan.nodes[index]
        bits, top = stored_field(plan, li)
        assert width == bits and len(init) == ix.hi + 1
        for j, word in enumerate(init):
            if j >= ix.lo:
                assert word | top << bits == n.param[j] & ((1 << n.width) - 1)
            else:
                assert word == 0
    assert any(plan.nodes[i].lo > 0 for i in groups)   # the 900 entry is never stored
    plan = tiny_piecewise_plan(0)
    ((index, luts),) = lut_groups(plan).items()
    init, width = lut_rom_init(plan, index, luts)
    assert width == sum(stored_field(plan, i)[0] for i in luts)
    w0 = stored_field(plan, luts[0])[0]
    assert all((word & ((1 << w0) - 1)) == plan.nodes[luts[0]].param[j] & ((1 << w0) - 1)
               for j, word in enumerate(init))


def test_constant_top_bits_of_a_table_are_not_stored():
    """A table of negative entries stores no sign bit, one far from 0 not its common top
    bits; the evaluator rebuilds them by wiring, bit-exact."""
    from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 15, 4, False)])
    cell, _ = b.cell(b.input_nodes["a"], 2)
    neg = b.lut(cell, [-300, -200, -257, -290], 0)          # 10-bit signed: top bits 1 and ...
    far = b.lut(cell, [1000, 1010, 1003, 1015], 0)          # 10-bit unsigned: 11111xxxxx
    out = b.add(neg, far)
    plan = b.build([PlanOutput("y", out, out, "ticks", 1.0)])
    fields = {plan.nodes[li].param: stored_field(plan, li) for li in range(len(plan.nodes))
              if plan.nodes[li].op == "lut"}
    assert fields[(-300, -200, -257, -290)] == (9, 1)
    assert fields[(1000, 1010, 1003, 1015)] == (5, 0b11111)
    res = simulate_bit_exact(PlanEvaluator(plan), plan, all_ports(plan))
    assert set(res.latencies.tolist()) == {PlanEvaluator(plan).latency}


_EXPORT_BOTH = """
import json, sys
from ikseries.fit.plan import Plan
from ikseries.hdl.export import leg_verilog
from ikseries.hdl.leg import LegCore
plan = Plan.from_json(json.load(open(sys.argv[1])))
for name, kw in (("pipelined", {}), ("folded", {"multipliers": 1, "dsp": (16, 16)})):
    open(sys.argv[2] + name + ".v", "w").write(leg_verilog(LegCore(plan, 128, **kw), "pw_core"))
"""


def test_piecewise_verilog_deterministic(tmp_path):
    """The exported Verilog of a piecewise leg core (pipelined and folded) is byte-identical
    when exported again in another process with another hash seed; the pipelined core holds
    its luts (one shared index) in one memory as wide as their stored fields together."""
    from ikseries.hdl.export import leg_verilog
    plan = tiny_piecewise_plan(0, clamp=(0, 100))
    (tmp_path / "plan.json").write_text(plan.dumps())
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    subprocess.run([sys.executable, "-c", _EXPORT_BOTH, str(tmp_path / "plan.json"), str(tmp_path / "other_")],
                   check=True, env=env, cwd=tmp_path)
    for name, kw in (("pipelined", {}), ("folded", {"multipliers": 1, "dsp": (16, 16)})):
        text = leg_verilog(LegCore(plan, 128, **kw), "pw_core")
        assert text == (tmp_path / f"other_{name}.v").read_text(), name
        mems = re.findall(r"reg \[(\d+):0\] (\w+) \[(\d+):0\];", text)
        if name == "pipelined":
            ((index, luts),) = lut_groups(plan).items()
            assert [(int(w) + 1, int(d) + 1) for w, _, d in mems] == [
                (sum(stored_field(plan, i)[0] for i in luts), plan.nodes[index].hi + 1)]
        else:
            assert {m for _, m, _ in mems} == {"microcode", "tables", "values"}


def test_leg_core_bit_exact_and_latency_full_plan(plan):
    """Thousands of random targets plus every corner through the real plan."""
    core = LegCore(plan, period=960000)
    t = {k: np.concatenate([c, r]) for (k, c), r in
         zip(corner_targets(plan).items(), random_targets(plan, 3000, 11).values())}
    res = simulate_bit_exact(core, plan, t)
    assert set(res.latencies.tolist()) == {core.latency} == {plan.depth}


def test_leg_core_under_backpressure_and_gaps(small_plan):
    core = LegCore(small_plan, period=960000)
    res = simulate_bit_exact(core, small_plan, random_targets(small_plan, 600, 5), ready_prob=0.5, valid_prob=0.6, seed=3)
    assert res.latencies.min() >= core.latency   # a stall delays every target in flight
    # input gaps alone never change the latency
    res = simulate_bit_exact(core, small_plan, random_targets(small_plan, 300, 6), valid_prob=0.6, seed=4)
    assert set(res.latencies.tolist()) == {core.latency}


def test_evaluator_rejects_bad_plan():
    with pytest.raises(TypeError, match="plan must be a Plan, not 'x'"):
        PlanEvaluator("x")


# -- PWM -----------------------------------------------------------------------------------
def run_pwm(pwm, cycles, widths=()):
    """Sample pwm every cycle; ``widths`` = [(cycle, width)] offered on i at that cycle."""
    trace = []

    async def bench(ctx):
        todo = dict(widths)
        for c in range(cycles):
            if c in todo:
                ctx.set(pwm.i.valid, 1)
                ctx.set(pwm.i.payload, todo[c])
            else:
                ctx.set(pwm.i.valid, 0)
            trace.append(ctx.get(pwm.pwm))
            await ctx.tick()

    sim = Simulator(pwm)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return np.array(trace)


def pulses(trace):
    """(start, length) of every high run."""
    d = np.diff(np.concatenate([[0], trace, [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), (ends - starts).tolist()))


def test_pwm_low_until_first_width_then_exact_pulses():
    pwm = ServoPWM(period=20, width_bits=5)
    tr = run_pwm(pwm, 100, [(5, 7)])
    assert not tr[:21].any()           # the period running at the load keeps width 0
    assert pulses(tr) == [(21, 7), (41, 7), (61, 7), (81, 7)]


def test_pwm_width_change_applies_at_next_period_only():
    pwm = ServoPWM(period=20, width_bits=5, reset_width=4)
    # width 9 offered in the middle of a pulse, 2 in the middle of the next period
    tr = run_pwm(pwm, 80, [(3, 9), (30, 2)])
    assert pulses(tr) == [(1, 4), (21, 9), (41, 2), (61, 2)]


def test_pwm_width_offered_on_the_last_cycle_waits_a_period():
    pwm = ServoPWM(period=10, width_bits=4)
    tr = run_pwm(pwm, 40, [(8, 2), (9, 3)])
    assert pulses(tr) == [(11, 2), (21, 3), (31, 3)]


@pytest.mark.parametrize("kw, msg", [
    ({"period": 1, "width_bits": 4}, "period must be an integer >= 2 cycles, not 1"),
    ({"period": 10, "width_bits": 0}, "width_bits must be a positive integer, not 0"),
    ({"period": 10, "width_bits": 4, "reset_width": 16}, "reset_width must be an integer in [0, 15], not 16"),
])
def test_pwm_parameter_errors(kw, msg):
    with pytest.raises(ValueError) as e:
        ServoPWM(**kw)
    assert str(e.value) == msg


def test_leg_core_drives_pwm_with_its_outputs():
    """A transferred width reaches its servo's PWM output at the next period start:
    no pulse before, then exactly ``width`` high cycles per period."""
    plan = tiny_plan(3, clamp=(0, 100))
    period = 128
    core = LegCore(plan, period=period)
    every = all_ports(plan)
    y = golden.outputs(plan, every)["y"]
    k = int(np.flatnonzero((y > 5) & (y < 100))[0])   # a target whose width is inside the period
    ports = {n: int(v[k]) for n, v in every.items()}
    want = int(y[k])
    trace = []

    async def bench(ctx):
        ctx.set(core.o.ready, 1)
        ctx.set(core.i.valid, 1)
        ctx.set(core.i.payload, ports)
        for _ in range(3 * period):
            trace.append(ctx.get(core.pwm_y))
            await ctx.tick()
            ctx.set(core.i.valid, 0)

    sim = Simulator(core)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert 0 < want < period
    # the first period (already running at reset) carries no pulse; then one per period
    assert pulses(np.array(trace)) == [(period + 1, want), (2 * period + 1, want)]


def test_leg_core_parameter_errors():
    plan = tiny_plan(3, clamp=(0, 100))
    with pytest.raises(ValueError) as e:
        LegCore(plan, period=128, reset_widths={"q": 3})
    assert str(e.value) == "reset_widths keys must be servos ['y'], not 'q'"
    signed_plan = tiny_plan(3)   # output may be negative
    lo = signed_plan.nodes[signed_plan.outputs[0].node].lo
    assert lo < 0
    with pytest.raises(ValueError) as e:
        LegCore(signed_plan, period=128)
    assert str(e.value) == f"plan output y must be a non-negative pulse width, but its range starts at {lo}"
