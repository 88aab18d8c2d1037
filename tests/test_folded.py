"""Folded evaluator (microcoded, k shared multipliers) against the golden model."""
import numpy as np
import pytest
from amaranth.sim import Simulator

from helpers import all_ports, signed_cell_plan, tiny_grid_plan, tiny_piecewise_plan, tiny_plan
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.hdl.folded import FoldedEvaluator
from ikseries.hdl.limbmul import LimbMultiplier, limb_split
from ikseries.hdl.schedule import WRITE_DELAY, compile_program, resolve_view
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_leg
from ikseries.sim.targets import corner_targets, random_targets


def run_back_to_back(core, targets):
    """Offer each target the cycle the previous output appears; check the timing exactly:
    ``o.valid`` rises ``latency`` cycles after the transfer and ``i.ready`` is high again
    in that cycle (so the initiation interval is ``latency``)."""
    names = list(targets)
    n = len(targets[names[0]])
    servos = [s for s, _ in core.o.payload.shape()]
    got = {s: [] for s in servos}

    async def bench(ctx):
        ctx.set(core.o.ready, 1)
        for k in range(n):
            assert ctx.get(core.i.ready)
            ctx.set(core.i.payload, {f: int(targets[f][k]) for f in names})
            ctx.set(core.i.valid, 1)
            await ctx.tick()
            ctx.set(core.i.valid, 0)
            await ctx.tick().repeat(core.latency - 2)
            assert not ctx.get(core.o.valid)
            await ctx.tick()
            assert ctx.get(core.o.valid)
            for s in servos:
                got[s].append(ctx.get(core.o.payload[s]))

    sim = Simulator(core)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return {s: np.array(v, dtype=np.int64) for s, v in got.items()}


def assert_bit_exact(plan, got, targets):
    exp = golden.outputs(plan, targets)
    for s in exp:
        assert np.array_equal(got[s], exp[s]), s


@pytest.mark.parametrize("seed, k, dsp", [
    (0, 1, None),        # full-width multiplier
    (0, 2, (4, 4)),      # 13 x 7-bit products in 3-bit limbs: 4 x 2 limb products each
    (1, 1, (5, 3)),      # asymmetric DSP, narrow
    (2, 3, (16, 16)),    # products fit one DSP
])
def test_folded_exhaustive_tiny_plan(seed, k, dsp):
    """Every port value (in range and clamped), bit for bit, with the exact latency."""
    plan = tiny_plan(seed)
    core = FoldedEvaluator(plan, multipliers=k, dsp=dsp)
    if dsp == (4, 4):
        assert core.program.limbs == (4, 2)
    assert core.initiation_interval == core.latency == core.program.steps + 1
    t = all_ports(plan)
    assert_bit_exact(plan, run_back_to_back(core, t), t)


@pytest.mark.parametrize("seed, k, dsp", [
    (0, 1, None),        # full-width multiplier
    (1, 2, (4, 4)),      # limb products
    (2, 2, (16, 16)),    # products fit one DSP
])
def test_folded_piecewise_exhaustive(seed, k, dsp):
    """A piecewise plan: index as a view, mask as an ALU and, one table-ROM lookup per lut
    node; every port value, bit for bit, with the exact latency and initiation interval."""
    plan = tiny_piecewise_plan(seed)
    core = FoldedEvaluator(plan, multipliers=k, dsp=dsp)
    prog = core.program
    assert prog.count("lut") == len(prog.tables) == plan.count("lut") > 1
    assert sum(o.alu == "and" for o in prog.ops) == plan.count("mask") == 1
    assert prog.lut_init()[:len(prog.tables[0])] == list(prog.tables[0])
    assert core.initiation_interval == core.latency == prog.steps + 1
    t = all_ports(plan)
    assert_bit_exact(plan, run_back_to_back(core, t), t)


def test_folded_grid_exhaustive():
    """A two-port grid plan: both cell numbers, the address (a shift and an ALU add) and the
    table-ROM lookups, every port value, bit for bit."""
    plan = tiny_grid_plan(2, (2, 2))[0]
    core = FoldedEvaluator(plan, multipliers=1, dsp=(16, 16))
    t = all_ports(plan)
    assert_bit_exact(plan, run_back_to_back(core, t), t)


def test_folded_signed_cells_exhaustive():
    """index / mask of a signed input as outputs and lut indices, a table whose first
    entries its index never takes (stored as 0)."""
    plan = signed_cell_plan()
    core = FoldedEvaluator(plan, multipliers=1, dsp=(3, 3))
    luts = [o for o in core.program.ops if o.kind == "lut"]
    assert [core.program.tables[o.table][0] for o in luts] == [-30, 0]
    t = all_ports(plan)
    assert_bit_exact(plan, run_back_to_back(core, t), t)


def multi_view_plan():
    """A product read through three different shifts, inputs read shifted and unshifted:
    the folded evaluator stores one view and derives the others."""
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("b", "mm", 0, -8, 7, 4, True)])
    a, bb = b.input_nodes["a"], b.input_nodes["b"]
    p = b.mul(a, bb)                                  # [-120, 105]
    s1, s2 = b.align(p, -2), b.align(p, -1)           # p >> 2, p >> 1
    y1 = b.mul(s1, a)
    y2 = b.add(b.reinterpret(s2, 0), bb)
    y3 = b.add(b.align(s2, 1), b.align(bb, 1))        # (p >> 1) << 2, b << 1
    return b.build([PlanOutput(n, y, y, "ticks", 1.0) for n, y in (("y1", y1), ("y2", y2), ("y3", y3))])


def test_folded_multi_view_plan_exhaustive():
    plan = multi_view_plan()
    prog = compile_program(plan, 1, (3, 3))
    assert prog.count("load") == 3 and sum(o.alu == "pass" for o in prog.ops) == 2
    core = FoldedEvaluator(plan, multipliers=1, dsp=(3, 3))
    t = all_ports(plan)
    assert_bit_exact(plan, run_back_to_back(core, t), t)


def test_views_match_golden_on_the_real_plan(plan):
    """Every wiring node equals (base >> a) << b of its resolved base."""
    t = random_targets(plan, 500, 2)
    vals = golden.evaluate(plan, t)
    for i, n in enumerate(plan.nodes):
        base, a, b = resolve_view(plan, i)
        assert plan.nodes[base].op not in ("shr", "shl", "frac")
        assert np.array_equal(np.broadcast_to(vals[i], (500,)),
                              np.broadcast_to((vals[base] >> a) << b, (500,))), i


def test_folded_real_plan_bit_exact(plan):
    """Corner and random targets through the cylinder-leg plan, 2 DSP-sized (16 x 16)
    limb multipliers, with random output backpressure."""
    core = FoldedEvaluator(plan, multipliers=2, dsp=(16, 16))
    prog = core.program
    assert prog.limbs == (2, 2) and prog.acc_width >= max(n.width for n in plan.nodes if n.op == "mul")
    # one issue per cycle: never faster than the operation count nor than the dependence
    # chains (operation latencies, write-back delay), and a list schedule never slower than
    # the two together
    done, chain = {}, 0
    for o in prog.ops:                     # dependency order; ASAP with the same latencies
        start = max([done[a] + 1 + WRITE_DELAY for a in o.args if a in done] + [0])
        done[o.out] = start + o.write - o.issue
        chain = max(chain, done[o.out] + 1 + WRITE_DELAY)
    assert prog.count("mul") + prog.count("alu") <= prog.steps
    assert max(chain, len(prog.ops)) <= prog.steps <= len(prog.ops) + chain
    corners = corner_targets(plan)
    rnd = random_targets(plan, 8, 7)
    t = {k: np.concatenate([corners[k], rnd[k]]) for k in corners}
    res = simulate_leg(core, t, ready_prob=0.7, seed=1)
    assert_bit_exact(plan, res.outputs, t)
    assert res.latencies.min() == core.latency


def test_folded_schedule_respects_resources(plan):
    for k, dsp in [(1, (16, 16)), (3, (18, 18)), (1, None)]:
        prog = compile_program(plan, k, dsp)
        issues = [o.issue for o in prog.ops if o.kind != "load"]
        writes = [o.write for o in prog.ops]
        assert len(set(issues)) == len(issues) and len(set(writes)) == len(writes)
        for u in range(k):
            starts = sorted(o.issue for o in prog.ops if o.kind == "mul" and o.unit == u)
            assert all(b - a >= prog.n_limbs for a, b in zip(starts, starts[1:]))
        producer = {o.out: o for o in prog.ops}
        for o in prog.ops:
            for a in o.args:
                assert a in prog.const_value or producer[a].write + WRITE_DELAY < o.issue
        if k == 1 and dsp == (16, 16):
            assert prog.steps >= prog.mul_busy_cycles   # one DSP: limb products bound the time
        # more multipliers never beyond one issue per cycle; folding is far smaller than a pipeline
    assert compile_program(plan, 2, (16, 16)).steps < compile_program(plan, 1, (16, 16)).steps


@pytest.mark.parametrize("make_plan, n", [(tiny_plan, 40), (tiny_piecewise_plan, 30)])
def test_folded_under_backpressure_and_gaps(make_plan, n):
    plan = make_plan(4)
    core = FoldedEvaluator(plan, multipliers=2, dsp=(4, 4))
    t = random_targets(plan, n, 3)
    res = simulate_leg(core, t, ready_prob=0.3, valid_prob=0.5, seed=9)
    assert_bit_exact(plan, res.outputs, t)
    assert res.latencies.min() == core.latency


def test_folded_matches_pipelined_interface():
    plan = tiny_plan(0)
    assert FoldedEvaluator(plan).signature == PlanEvaluator(plan).signature


@pytest.mark.parametrize("kw, exc, msg", [
    ({"multipliers": 0}, ValueError, "multipliers must be a positive integer, not 0"),
    ({"multipliers": True}, ValueError, "multipliers must be a positive integer, not True"),
    ({"dsp": (16,)}, ValueError,
     "dsp must be None or a pair of signed operand widths >= 2 such as (16, 16), not (16,)"),
    ({"dsp": (1, 16)}, ValueError,
     "dsp must be None or a pair of signed operand widths >= 2 such as (16, 16), not (1, 16)"),
])
def test_folded_parameter_errors(kw, exc, msg):
    with pytest.raises(exc) as e:
        FoldedEvaluator(tiny_plan(0), **kw)
    assert str(e.value) == msg


def test_folded_rejects_bad_plan():
    with pytest.raises(TypeError) as e:
        FoldedEvaluator("x")
    assert str(e.value) == "plan must be a Plan, not 'x'"


# -- limb multiplier -----------------------------------------------------------------------
@pytest.mark.parametrize("aw, bw, dsp", [(5, 4, (3, 3)), (6, 3, (4, 2)), (5, 5, None),
                                         (7, 4, (4, 4)), (8, 3, (3, 3)), (4, 8, (4, 4))])
def test_limb_multiplier_exhaustive(aw, bw, dsp):
    """Every signed operand pair, one pair per initiation interval, exact latency: both
    operands split (each product shifted into place), one split (Horner, the top limb first:
    2, 4 limbs of a, 3 of b) and no split."""
    mul = LimbMultiplier(aw, bw, dsp)
    pairs = [(a, b) for a in range(-2 ** (aw - 1), 2 ** (aw - 1)) for b in range(-2 ** (bw - 1), 2 ** (bw - 1))]
    got, when = [], []

    async def bench(ctx):
        cyc, k = 0, 0
        while len(got) < len(pairs):
            if k < len(pairs):
                ctx.set(mul.i.valid, 1)
                ctx.set(mul.i.payload, {"a": pairs[k][0], "b": pairs[k][1]})
            else:
                ctx.set(mul.i.valid, 0)
            if k < len(pairs) and ctx.get(mul.i.ready):
                when.append(cyc)
                k += 1
            if ctx.get(mul.o.valid):
                got.append(ctx.get(mul.o.payload))
                assert cyc - when[len(got) - 1] == mul.latency
            await ctx.tick()
            cyc += 1
        assert np.all(np.diff(when) == mul.initiation_interval)

    sim = Simulator(mul)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert got == [a * b for a, b in pairs]


def test_limb_split_signed_limbs():
    # 31-bit signed operands on 16 x 16 DSPs: two 15-bit limbs each (low unsigned, top signed)
    assert limb_split(31, 24, (16, 16)) == ((15, 15), (2, 2), (31, 31))
    assert limb_split(49, 35, (25, 18)) == ((24, 17), (2, 2), (49, 35))
    assert limb_split(20, 20, None) == ((19, 19), (1, 1), (20, 20))


@pytest.mark.parametrize("args, msg", [
    ((1, 4), "a_width must be an integer >= 2 (signed bits), not 1"),
    ((4, 4.0), "b_width must be an integer >= 2 (signed bits), not 4.0"),
    ((4, 4, (16, 0)), "dsp must be None or a pair of signed operand widths >= 2 such as (16, 16), not (16, 0)"),
    ((4, 4, None, 1), "product_width must be an integer >= 2 (signed bits), not 1"),
])
def test_limb_multiplier_parameter_errors(args, msg):
    with pytest.raises(ValueError) as e:
        LimbMultiplier(*args)
    assert str(e.value) == msg


def test_folded_exports_to_verilog_with_block_memories():
    """The value memory and the microcode ROM reach Verilog as initialised memories."""
    from amaranth.back import verilog
    core = FoldedEvaluator(tiny_plan(0), multipliers=2, dsp=(4, 4))
    text = verilog.convert(core, name="folded", emit_src=False)
    assert "module folded" in text
    assert text.count("reg [") >= 2 and "initial" in text   # memories with contents
    consts = sorted(core.program.const_value.values())
    assert len(consts) == core.program.n_consts and core.program.memory_init()[:len(consts)] != [0] * len(consts)
