"""Robot core: one folded evaluator shared by several legs, one PWM bank for all servos."""
import numpy as np
import pytest
from amaranth.hdl import Module
from amaranth.sim import Simulator

from helpers import tiny_plan
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.hdl.shared import RobotCore
from ikseries.sim import golden
from ikseries.sim.targets import random_targets


def three_servo_plan():
    """Two inputs, three non-negative outputs (pulse widths within a short period)."""
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("b", "mm", 0, -8, 7, 4, True)])
    a, bb = b.input_nodes["a"], b.input_nodes["b"]
    p = b.mul(a, bb)
    y1 = b.clamp(b.add(b.align(p, -2), b.const(12, 0)), 0, 30)
    y2 = b.clamp(b.add(b.mul(a, a), bb), 0, 30)
    y3 = b.clamp(b.align(b.add(b.reinterpret(b.align(p, -1), 0), b.const(20, 0)), -1), 1, 30)
    return b.build([PlanOutput(n, y, y, "ticks", 1.0) for n, y in (("s1", y1), ("s2", y2), ("s3", y3))])


def expected_pwm(n_cycles, period, per_group, loads, reset):
    """Exact servo signals of a PWM bank: ``loads`` = [(cycle, group, widths)] (a load at
    cycle t is applied from the first period start after t + 1: one in a period's last cycle
    waits a period more); output registered."""
    n = len(reset)
    trace = np.zeros((n_cycles, n), dtype=np.int64)
    for ch in range(n):
        for c in range(1, n_cycles):
            start = (c - 1) - (c - 1) % period
            w = reset[ch]
            for t, g, ws in loads:
                if t < start - 1 and g == ch // per_group:
                    w = ws[ch % per_group]
            trace[c, ch] = int((c - 1) % period < w)
    return trace


def run_robot(core, jobs, n_cycles, ready_prob=1.0, seed=0):
    """Offer ``jobs`` = [(leg, target dict)] in order; record o transfers and pwm every cycle."""
    rng = np.random.default_rng(seed)
    trace, outs = [], []

    async def bench(ctx):
        k = 0
        for c in range(n_cycles):
            if k < len(jobs):
                leg, tgt = jobs[k]
                ctx.set(core.i.valid, 1)
                ctx.set(core.i.payload, {"leg": leg, "target": tgt})
            else:
                ctx.set(core.i.valid, 0)
            ctx.set(core.o.ready, int(rng.random() < ready_prob))
            if k < len(jobs) and ctx.get(core.i.ready):
                k += 1
            if ctx.get(core.o.valid) and ctx.get(core.o.ready):
                outs.append((c, ctx.get(core.o.payload.leg),
                             {s: ctx.get(core.o.payload.widths[s]) for s in core.servos}))
            bits = ctx.get(core.pwm)
            trace.append([(bits >> j) & 1 for j in range(len(core.pwm))])
            await ctx.tick()

    sim = Simulator(core)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return np.array(trace), outs


def _golden_widths(plan, tgt):
    out = golden.outputs(plan, {k: np.array([v]) for k, v in tgt.items()})
    return {s: int(v[0]) for s, v in out.items()}


def test_robot_core_routes_legs_and_updates_at_period_start():
    """Widths reach only their leg's channels, all of a leg's servos switch at the same
    period start, never mid-pulse; untouched legs keep their reset width."""
    plan = three_servo_plan()
    period = 48
    core = RobotCore(plan, legs=3, period=period, clock_hz=1e6, multipliers=2, dsp=(3, 3),
                     reset_widths={"s2": 5})
    t = random_targets(plan, 4, 1)
    jobs = [(leg, {k: int(v[n]) for k, v in t.items()}) for n, leg in enumerate([2, 0, 2, 0])]
    n_cycles = 4 * core.latency + 3 * period
    trace, outs = run_robot(core, jobs, n_cycles)
    assert [leg for _, leg, _ in outs] == [2, 0, 2, 0]
    for (_, _, w), (_, tgt) in zip(outs, jobs):
        assert w == _golden_widths(plan, tgt)
    loads = [(c, leg, [w[s] for s in core.servos]) for c, leg, w in outs]
    exp = expected_pwm(n_cycles, period, 3, loads, [0, 5, 0] * 3)
    assert np.array_equal(trace, exp)
    assert trace[:, 4].any() and not trace[:, 3].any()   # leg 1 (never updated): its reset pulses only
    assert np.array_equal(trace[:, 3:6], expected_pwm(n_cycles, period, 3, [], [0, 5, 0] * 3)[:, 3:6])


def test_robot_core_under_backpressure():
    plan = three_servo_plan()
    core = RobotCore(plan, legs=4, period=1000, clock_hz=1e6, multipliers=1, dsp=None)
    t = random_targets(plan, 10, 4)
    legs = [3, 1, 0, 2, 2, 3, 0, 1, 1, 0]
    jobs = [(leg, {k: int(v[n]) for k, v in t.items()}) for n, leg in enumerate(legs)]
    _, outs = run_robot(core, jobs, 40 * core.latency, ready_prob=0.3, seed=5)
    assert [leg for _, leg, _ in outs] == legs
    assert [w for _, _, w in outs] == [_golden_widths(plan, tgt) for _, tgt in jobs]


def test_hexapod_core_real_plan(plan):
    """Six legs of the cylinder-leg plan on two 16 x 16 limb multipliers: bit-exact widths
    per leg, and the whole robot refreshed well over 1000 times a second at 24 MHz."""
    core = RobotCore(plan, legs=6, period=480_000, clock_hz=24e6, multipliers=2, dsp=(16, 16))
    assert core.refresh_hz == 24e6 / (6 * core.initiation_interval)
    assert core.refresh_hz >= 1000
    assert len(core.pwm) == 18
    t = random_targets(plan, 6, 3)
    legs = [4, 0, 5, 1, 3, 2]
    jobs = [(leg, {k: int(v[n]) for k, v in t.items()}) for n, leg in enumerate(legs)]
    _, outs = run_robot(core, jobs, 6 * core.latency + 2)
    assert [leg for _, leg, _ in outs] == legs
    assert [w for _, _, w in outs] == [_golden_widths(plan, tgt) for _, tgt in jobs]
    assert [c for c, _, _ in outs] == [(n + 1) * core.latency for n in range(6)]


def bank_trace(bank, loads, n_cycles):
    """The pins of ``bank`` every cycle (a row of bits per cycle) for ``loads`` [(cycle, group, widths)]."""
    trace = []

    async def bench(ctx):
        todo = {c: (g, w) for c, g, w in loads}
        for c in range(n_cycles):
            ctx.set(bank.i.valid, c in todo)
            if c in todo:
                ctx.set(bank.i.payload, {"group": todo[c][0], "widths": todo[c][1]})
            bits = ctx.get(bank.pwm)
            trace.append([(bits >> j) & 1 for j in range(bank.channels)])
            await ctx.tick()

    sim = Simulator(bank)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return np.array(trace)


def test_pwm_bank_load_in_last_cycle_waits_a_period_and_reset_widths():
    bank = ServoPWMBank(period=10, width_bits=4, groups=2, per_group=2, reset_widths=[3, 0, 0, 7])
    loads = [(9, 1, [2, 4]), (14, 0, [5, 1]), (15, 0, [6, 2])]
    trace = bank_trace(bank, loads, 45)
    assert np.array_equal(trace, expected_pwm(45, 10, 2, loads, [3, 0, 0, 7]))
    # the last-cycle load waits a period; the last of two loads wins
    assert trace[11:21, 2].sum() == 0 and trace[21:31, 2].sum() == 2 and trace[21:31, 0].sum() == 6


@pytest.mark.parametrize("period, width_bits", [(10, 6), (37, 4), (16, 4), (2, 3)])
def test_pwm_bank_widths_of_every_size_against_the_period(period, width_bits):
    # widths wider and narrower than the period counter, up to all ones (constant high)
    top = (1 << width_bits) - 1
    rng = np.random.default_rng(period)
    reset = [top, 0, min(period, top), min(period - 1, top)]
    bank = ServoPWMBank(period=period, width_bits=width_bits, groups=2, per_group=2, reset_widths=reset)
    choices = sorted({0, 1, period - 1, period, period + 1, top} - set(range(top + 1, period + 2)))
    loads = [(int(t), int(t) % 2, [int(v) for v in rng.choice(choices, 2)])
             for t in sorted(rng.choice(6 * period, 8, replace=False))]
    n_cycles = 8 * period
    assert np.array_equal(bank_trace(bank, loads, n_cycles), expected_pwm(n_cycles, period, 2, loads, reset))


@pytest.mark.parametrize("per_group", [1, 2])
def test_pwm_bank_loaded_in_order_matches_the_addressed_one(per_group):
    # every period, loads of groups 0 .. groups - 1 in order at random cycles (the group field
    # garbage for the in-order bank): both banks give the same pins every cycle
    groups, period = 3, 12
    reset = [3, 0, 5, 1, 0, 7][:groups * per_group]
    rng = np.random.default_rng(per_group)
    banks = [ServoPWMBank(period, 4, groups, per_group, reset, in_order=o) for o in (False, True)]
    m = Module()
    m.submodules.a, m.submodules.b = banks
    loads = {}
    for p in range(6):
        cycles = sorted(rng.choice(period - 1, groups, replace=False))
        for g, c in enumerate(cycles):
            loads[p * period + int(c)] = (g, [int(v) for v in rng.integers(0, 16, per_group)])
    traces = [[], []]

    async def bench(ctx):
        for c in range(6 * period + 14):
            for b, bank in enumerate(banks):
                ctx.set(bank.i.valid, c in loads)
                if c in loads:
                    g, w = loads[c]
                    ctx.set(bank.i.payload, {"group": g if b == 0 else (g + 1) % groups, "widths": w})
                traces[b].append(ctx.get(bank.pwm))
            await ctx.tick()

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert traces[0] == traces[1] and len(set(traces[0])) > 3


@pytest.mark.parametrize("kw, msg", [
    ({"legs": 0}, "legs must be a positive integer, not 0"),
    ({"clock_hz": 0}, "clock_hz must be a positive number, not 0"),
    ({"clock_hz": "24e6"}, "clock_hz must be a positive number, not '24e6'"),
    ({"multipliers": 0}, "multipliers must be a positive integer, not 0"),
    ({"reset_widths": {"q": 1}}, "reset_widths keys must be servos ['s1', 's2', 's3'], not 'q'"),
    ({"period": 1}, "period must be an integer >= 2, not 1"),
])
def test_robot_core_parameter_errors(kw, msg):
    args = {"legs": 2, "period": 100, "clock_hz": 1e6, **kw}
    with pytest.raises(ValueError) as e:
        RobotCore(three_servo_plan(), **args)
    assert str(e.value) == msg


def test_robot_core_rejects_signed_outputs():
    plan = tiny_plan(3)
    lo = plan.nodes[plan.outputs[0].node].lo
    with pytest.raises(ValueError) as e:
        RobotCore(plan, legs=2, period=100, clock_hz=1e6)
    assert str(e.value) == f"plan output y must be a non-negative pulse width, but its range starts at {lo}"


@pytest.mark.parametrize("args, msg", [
    ((10, 4, 0, 2), "groups must be an integer >= 1, not 0"),
    ((10, 0, 1, 2), "width_bits must be an integer >= 1, not 0"),
    ((10, 4, 1, 2, [1]), "reset_widths must be 2 integers in [0, 15], not [1]"),
    ((10, 4, 1, 2, [1, 16]), "reset_widths must be 2 integers in [0, 15], not [1, 16]"),
])
def test_pwm_bank_parameter_errors(args, msg):
    with pytest.raises(ValueError) as e:
        ServoPWMBank(*args)
    assert str(e.value) == msg
