"""CORDIC baseline: golden model vs the exact IK, range analysis, sizing, Amaranth RTL bit-exact."""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from amaranth.hdl import Const, Module, Mux, Signal, signed

from ikseries.fit.baselines import cordic as fc
from ikseries.fit.baselines.cordic import DEFAULT_DESIGN, CordicDesign, CordicPlan, IntervalOps
from ikseries.fit.plan import bits_for
from ikseries.fit.baselines.cordic_sizing import SizingError, measure_cordic, size_cordic
from ikseries.hdl.cordic import (AmaranthOps, CordicLegSolver, FoldedAmaranthOps, cordic_input_layout,
                                 cordic_output_layout)
from ikseries.hdl.evaluator import input_layout, output_layout
from ikseries.sim import cordic_golden
from ikseries.sim.amaranth_sim import simulate_leg
from ikseries.sim.targets import corner_targets, random_targets

#: ``size_cordic(load_preset("cylinder-leg"))`` on the 1,066,841 verification points
#: (bench/cordic_vs_poly.py re-sizes it; this copy keeps the RTL tests fast).
SIZED = CordicDesign(rot_iters=13, xy_iters=13, uv_iters=14, law_iters=13, len_frac=11, area_frac=3,
                     angle_frac=11, gain_frac=18, scale_frac=0)


def _targets(cp, n, seed):
    """Every corner (and out-of-range port extreme) plus ``n`` random in-range targets."""
    c = corner_targets(cp, port_extremes=True)
    r = random_targets(cp, n, seed)
    return {k: np.concatenate([c[k], r[k]]) for k in c}


def _random_points(robot, n, seed):
    rng = np.random.default_rng(seed)
    return {i.name: rng.integers(i.lo, i.hi + 1, n) for i in robot.workspace.inputs}


# -- golden model --------------------------------------------------------------------------
def test_golden_matches_exact_ik(robot):
    """The generous default design is far inside the tolerance: the model computes the IK."""
    cp = CordicPlan(robot, DEFAULT_DESIGN)
    pts = {k: np.clip(v, i.lo, i.hi) for (k, v), i in zip(_targets(cp, 4000, 1).items(), cp.inputs)}
    m = measure_cordic(robot, DEFAULT_DESIGN, pts)
    for s, e in m["servos"].items():
        assert e["total"] < 0.1, (s, e)


def test_golden_follows_the_joint_conventions():
    """The datapath computes the kinematic angles; with mirrored servos and horn offsets its
    pulses still follow the robot's (the calibration mapped to kinematic angles)."""
    import tomllib
    from ikseries.robot import parse_robot, preset_text
    d = tomllib.loads(preset_text("cylinder-leg"))
    d["geometry"].update(zero_offsets=[12.5, -3.5, 46.3], angle_directions=[-1, 1, -1])
    robot = parse_robot(d)
    cp = CordicPlan(robot, DEFAULT_DESIGN)
    pts = {k: np.clip(v, i.lo, i.hi) for (k, v), i in zip(_targets(cp, 2000, 2).items(), cp.inputs)}
    m = measure_cordic(robot, DEFAULT_DESIGN, pts)
    for s, e in m["servos"].items():
        assert e["total"] < 0.1, (s, e)


def test_sized_design_within_tolerance_on_fresh_points(robot):
    m = measure_cordic(robot, SIZED, _random_points(robot, 20000, 7))
    for s, e in m["servos"].items():
        assert e["total"] <= robot.fit.tolerance_pu, (s, e)


def test_too_few_iterations_exceed_tolerance(robot):
    """The error measure can fail: 6 iterations are far too few for +-0.5 pu."""
    m = measure_cordic(robot, dataclasses.replace(SIZED, law_iters=6), _random_points(robot, 5000, 3))
    assert m["servos"]["s3"]["total"] > robot.fit.tolerance_pu


def test_out_of_range_ports_are_clamped(robot):
    cp = CordicPlan(robot, SIZED)
    r, th, z = cp.inputs
    big = {r.name: [r.port_range[1]], th.name: [th.port_range[0]], z.name: [z.port_range[1]]}
    edge = {r.name: [r.hi], th.name: [th.lo], z.name: [z.hi]}
    assert cordic_golden.outputs(robot, cp, big) == cordic_golden.outputs(robot, cp, edge)


@pytest.mark.parametrize("design", [DEFAULT_DESIGN, SIZED])
def test_no_register_overflows_at_corners(robot, design):
    """Every register value at every corner, port extreme and random target lies in its
    analysed range (the model raises otherwise), and the analysis is not wildly loose: the
    registers need at most 15 % more bits than the values seen (the loose ones: vectoring y
    registers and angle accumulators, bounded by the CORDIC norm / angle range)."""
    cp = CordicPlan(robot, design)
    out, observed = cordic_golden.evaluate(cp, _targets(cp, 3000, 2))
    assert len(observed) == cp.latency
    seen_bits = 0
    for st, seen, name in zip(cp.layout, observed, cp.stage_names):
        for k, (vmin, vmax) in seen.items():
            lo, hi = st[k]
            assert lo <= vmin <= vmax <= hi, (name, k)
            seen_bits += bits_for(vmin, vmax)[0]
    assert cp.register_bits() < 1.15 * seen_bits


def test_range_check_can_fail(robot):
    """A register narrower than the values it holds is reported."""
    cp = CordicPlan(robot, SIZED)
    k = cp.stage_names.index("d")
    cp.layout[k] = {**cp.layout[k], "d": (0, 1000)}
    with pytest.raises(OverflowError, match=r"CORDIC register d\.d \(stage \d+\) took \d+, "
                                             r"outside its analysed range \[0, 1000\]"):
        cordic_golden.evaluate(cp, random_targets(cp, 100, 1))


def test_golden_rejects_port_overflow(robot):
    cp = CordicPlan(robot, SIZED)
    with pytest.raises(ValueError, match=r"input r must fit its 9-bit port \[0, 511\], not 512"):
        cordic_golden.outputs(robot, cp, {"r": [512], "theta": [0], "z": [0]})


# -- the CORDIC building blocks over every quadrant / exact square roots -----------------------
def _run(build, ports):
    """Analyse ``build(ops, live)`` over port intervals, then run it in the int64 model."""
    ia = IntervalOps({k: (int(min(v)), int(max(v))) for k, v in ports.items()})
    build(ia)
    ops = cordic_golden.NumpyOps(ia.layout, {k: np.asarray(v, np.int64) for k, v in ports.items()})
    return build(ops)


def test_vectoring_atan2_and_hypot_every_quadrant():
    rng = np.random.default_rng(5)
    x, y = rng.integers(-4000, 4001, 5000), rng.integers(-4000, 4001, 5000)
    x[:4], y[:4] = [-4000, -4000, 0, 4000], [0, -1, 4000, 0]   # the +-180 deg edge and the axes
    n, A = 16, 12
    table = [round(math.degrees(math.atan(2.0 ** -i)) * 2 ** A) for i in range(n)]

    def build(ops):
        xs, ys = ops.shl(ops.port("x"), 8), ops.shl(ops.port("y"), 8)
        x2, y2, a = fc._vector_prerotate(ops, xs, ys, 90 << A)
        live = ops.stage("pre", {"x": x2, "y": y2, "a": a})
        return fc._vectoring(ops, live, n, table, [("x", "y", "a")], "v")

    out = _run(build, {"x": x, "y": y})
    ang = out["a"] * 2.0 ** -A
    assert np.max(np.abs(ang - np.degrees(np.arctan2(y, x)))) < 0.01
    assert np.max(np.abs(out["x"] / 256.0 / fc.cordic_gain(n) - np.hypot(x, y))) < 0.1


def test_rotation_every_quadrant():
    rng = np.random.default_rng(6)
    th = rng.integers(-90 * 16, 90 * 16 + 1, 3000)       # the datapath pre-rotates beyond +-90
    n, A = 16, 4
    table = [round(math.degrees(math.atan(2.0 ** -i)) * 2 ** (A + 8)) for i in range(n)]

    def build(ops):
        live = ops.stage("pre", {"x": ops.c(round(1000 * 2 ** 8 / fc.cordic_gain(n))), "y": ops.c(0),
                                 "a": ops.shl(ops.port("th"), 8)})
        return fc._rotate(ops, live, n, table, [("x", "y", "a")], "r")

    out = _run(build, {"th": th})
    t = np.radians(th / 16.0)
    assert np.max(np.abs(out["x"] / 256.0 - 1000 * np.cos(t))) < 0.2
    assert np.max(np.abs(out["y"] / 256.0 - 1000 * np.sin(t))) < 0.2


def test_isqrt_is_exact_floor():
    rng = np.random.default_rng(7)
    hi = (1 << 40) - 1
    r = rng.integers(0, 1 << 20, 3000)
    x = np.concatenate([rng.integers(0, hi, 3000), r * r, r * r - 1, r * r + 2 * r, [0, 1, 2, 3, hi]])
    x = np.clip(x, 0, hi)

    def build(ops):
        return fc._isqrt(ops, {"x": ops.port("x")}, "x", "h", hi, "sq")

    out = _run(build, {"x": x})
    assert np.array_equal(out["h"], [math.isqrt(int(v)) for v in x])


# -- sizing ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sized_small(robot):
    pts = _random_points(robot, 20000, 11)
    return size_cordic(robot, pts), pts


def test_size_cordic_meets_tolerance_and_is_locally_minimal(robot, sized_small):
    design, pts = sized_small
    m = measure_cordic(robot, design, pts)
    assert max(e["total"] for e in m["servos"].values()) <= robot.fit.tolerance_pu
    assert CordicPlan(robot, design).register_bits() < CordicPlan(robot, DEFAULT_DESIGN).register_bits()
    for name in ("law_iters", "uv_iters", "len_frac", "angle_frac"):
        smaller = dataclasses.replace(design, **{name: getattr(design, name) - 1})
        m = measure_cordic(robot, smaller, pts)
        assert max(e["total"] for e in m["servos"].values()) > robot.fit.tolerance_pu, name


def test_size_cordic_rejects_a_failing_start(robot):
    with pytest.raises(SizingError, match="does not meet the tolerance of 0.5 pu"):
        size_cordic(robot, _random_points(robot, 500, 1), start=dataclasses.replace(SIZED, rot_iters=4))


@pytest.mark.parametrize("margin, msg", [(-0.1, "-0.1"), (0.5, "0.5"), (True, "True")])
def test_size_cordic_bad_margin(robot, margin, msg):
    with pytest.raises(ValueError, match=rf"margin_pu must be in \[0, 0.5\) pu, not {msg}$"):
        size_cordic(robot, _random_points(robot, 10, 1), margin_pu=margin)


# -- parameter errors -------------------------------------------------------------------------
@pytest.mark.parametrize("field, value, msg", [
    ("rot_iters", 0, "rot_iters must be an integer in 1..40, not 0"),
    ("law_iters", 41, "law_iters must be an integer in 1..40, not 41"),
    ("xy_iters", 12.0, "xy_iters must be an integer in 1..40, not 12.0"),
    ("uv_iters", True, "uv_iters must be an integer in 1..40, not True"),
    ("len_frac", -1, "len_frac must be an integer in 0..32, not -1"),
    ("area_frac", 33, "area_frac must be an integer in 0..32, not 33"),
    ("gain_frac", "8", "gain_frac must be an integer in 0..32, not '8'"),
])
def test_design_parameter_errors(field, value, msg):
    with pytest.raises(ValueError, match=f"^{msg}$".replace(".", r"\.")):
        dataclasses.replace(DEFAULT_DESIGN, **{field: value})


def test_plan_parameter_errors(robot):
    with pytest.raises(ValueError, match=r"^angle_frac must be >= the theta input's frac_bits \(3\), not 2$"):
        CordicPlan(robot, dataclasses.replace(SIZED, angle_frac=2))
    with pytest.raises(TypeError, match=r"^design must be a CordicDesign, not \{'rot_iters': 3\}$"):
        CordicLegSolver(robot, {"rot_iters": 3})
    with pytest.raises(TypeError, match=r"^robot must be a Robot with a CylinderLeg geometry, not 'leg'$"):
        CordicPlan("leg", SIZED)


def test_too_wide_design_is_refused(robot):
    with pytest.raises(OverflowError, match="needs more than 63 bits"):
        CordicPlan(robot, dataclasses.replace(SIZED, len_frac=32))


# -- RTL --------------------------------------------------------------------------------------
def _bit_exact(robot, core, targets, **drive):
    """Simulate ``core`` on ``targets``; every output equals the golden model's."""
    res = simulate_leg(core, targets, **drive)
    exp = cordic_golden.outputs(robot, core.plan, targets)
    for s in exp:
        assert np.array_equal(res.outputs[s], exp[s]), s
    return res


def test_rtl_bit_exact_with_golden(robot):
    core = CordicLegSolver(robot, SIZED)
    t = _targets(core.plan, 300, 21)
    res = _bit_exact(robot, core, t)
    assert set(res.latencies.tolist()) == {core.latency} == {core.plan.latency}
    assert core.latency == 86


def test_rtl_under_backpressure_and_gaps(robot):
    core = CordicLegSolver(robot, SIZED)
    t = random_targets(core.plan, 150, 4)
    res = _bit_exact(robot, core, t, ready_prob=0.5, valid_prob=0.6, seed=3)
    assert res.latencies.min() == core.latency


@pytest.fixture(scope="module")
def iterative(robot):
    return CordicLegSolver(robot, SIZED, CordicLegSolver(robot, SIZED).longest_loop)


def test_iterative_rtl_bit_exact_with_golden_at_the_same_latency(robot, iterative):
    """Each loop on one set of registers: the pipelined core's values and latency, a target
    every ``longest_loop`` cycles (the square root's 17 steps here)."""
    core = iterative
    assert core.longest_loop == max(SIZED.rot_iters, SIZED.xy_iters, SIZED.uv_iters, SIZED.law_iters,
                                    fc.isqrt_stages(core.plan.layout[core.plan.stage_names.index("pq")]["pq"][1]))
    assert core.initiation_interval == core.longest_loop == 17
    t = _targets(core.plan, 120, 22)
    res = _bit_exact(robot, core, t)
    assert set(res.latencies.tolist()) == {core.latency} == {CordicLegSolver(robot, SIZED).latency}
    assert set(np.diff(res.input_cycles).tolist()) == {core.initiation_interval}


def test_iterative_rtl_under_backpressure_and_gaps(robot, iterative):
    core = iterative
    t = random_targets(core.plan, 60, 8)
    res = _bit_exact(robot, core, t, ready_prob=0.5, valid_prob=0.6, seed=5)
    assert res.latencies.min() == core.latency
    assert np.diff(res.input_cycles).min() >= core.initiation_interval


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_iterative_rtl_random_designs(robot, seed):
    """Seeded random designs (loops of 1 to 20 iterations, any formats) at an interval at or
    above the longest loop: bit-exact with the golden model under backpressure."""
    rng = np.random.default_rng(seed)
    d = CordicDesign(**{f: int(rng.integers(1, 21)) for f in fc.ITERATION_FIELDS},
                     len_frac=int(rng.integers(5, 14)), area_frac=int(rng.integers(0, 6)),
                     angle_frac=int(rng.integers(8, 14)), gain_frac=int(rng.integers(12, 21)),
                     scale_frac=int(rng.integers(0, 4)))
    core = CordicLegSolver(robot, d, CordicLegSolver(robot, d).longest_loop + int(rng.integers(0, 3)))
    res = _bit_exact(robot, core, _targets(core.plan, 40, seed), ready_prob=0.8, valid_prob=0.9, seed=seed)
    assert res.latencies.min() == core.latency


@pytest.mark.parametrize("ii", [0, 2, 16, True, 17.0, "17"])
def test_iterative_interval_errors(robot, ii):
    with pytest.raises(ValueError, match=rf"^initiation_interval must be 1 \(pipelined\) or an integer >= 17 "
                                         rf"\(the longest loop of this design\), not {re.escape(repr(ii))}$"):
        CordicLegSolver(robot, SIZED, ii)


def test_folded_ops_refuse_a_loop_longer_than_the_interval():
    m = Module()
    ia = IntervalOps({"x": (0, 15)})
    ia.stage("in", {"x": ia.port("x")})
    ops = FoldedAmaranthOps(m, Const(1), {"x": Signal(4)}, ia.layout, Signal(2), 3)
    live = ops.stage("in", {"x": ops.port("x")})
    with pytest.raises(ValueError, match=r"^initiation_interval must be >= the 4 iterations of loop 'r', not 3$"):
        ops.loop("r", 4, lambda ops, live, i: live, live)


def test_iterative_square_root_exhaustive():
    """The iterative digit-by-digit root gives floor(sqrt(x)) for every x of a 10-bit range,
    targets back to back, and holds a value it only carries."""
    from amaranth.sim import Simulator
    xhi = 1023
    nb = fc.isqrt_stages(xhi)

    def build(ops):
        return ops.isqrt(ops.stage("in", {"x": ops.port("x"), "k": ops.port("k")}), "x", "h", xhi, "sq")

    ia = IntervalOps({"x": (0, xhi), "k": (0, 7)})
    build(ia)
    m = Module()
    x, k, phase = Signal(10), Signal(3), Signal(range(nb))
    m.d.sync += phase.eq(Mux(phase == nb - 1, 0, phase + 1))
    out = build(FoldedAmaranthOps(m, Const(1), {"x": x, "k": k}, ia.layout, phase, nb))
    res = []

    async def driver(ctx):                    # a new radicand every nb cycles, when phase is 0
        for v in range(xhi + 1):
            while ctx.get(phase) != 0:
                await ctx.tick()
            ctx.set(x, v)
            ctx.set(k, v & 7)
            await ctx.tick()

    async def reader(ctx):                    # each result in the cycle after its last iteration
        while ctx.get(phase) != 0:
            await ctx.tick()
        await ctx.tick().repeat(nb + 1)       # the "in" register, then iterations 0 .. nb - 1
        for _ in range(xhi + 1):
            res.append((ctx.get(out["h"]), ctx.get(out["k"])))
            await ctx.tick().repeat(nb)

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(driver)
    sim.add_testbench(reader)
    sim.run()
    assert res == [(math.isqrt(v), v & 7) for v in range(xhi + 1)]


def test_same_stream_interface_as_polynomial_evaluator(robot, small_plan):
    """Ports come from the workspace and the pulse format, not the fit: any plan of the robot
    has them (the small one is the cheapest)."""
    core = CordicLegSolver(robot, SIZED)
    assert cordic_input_layout(core.plan) == input_layout(small_plan)
    assert cordic_output_layout(core.plan) == output_layout(small_plan)


def test_stage_may_only_read_previous_stage():
    """The RTL back end refuses a register fed from an older stage (a skipped delay that the
    golden model could not see)."""
    m = Module()
    a = Signal(4)
    layout = [{"x": (0, 15)}, {"x": (0, 15), "y": (0, 15)}, {"z": (0, 15)}]
    ops = AmaranthOps(m, Signal(), {"a": a}, layout)
    s1 = ops.stage("one", {"x": ops.port("a")})
    s2 = ops.stage("two", {"x": s1["x"], "y": s1["x"]})
    with pytest.raises(AssertionError, match=r"stage 3 \(three\.z\) reads s1_one_x from stage 1"):
        ops.stage("three", {"z": ops.add(s2["y"], s1["x"])})


def test_flat_verilog_top_ports(robot):
    """The exported CORDIC top has one port per stream field, like the polynomial core's."""
    from ikseries.hdl.flat import FlatStreamTop, stream_verilog
    small = dataclasses.replace(SIZED, rot_iters=2, xy_iters=2, uv_iters=2, law_iters=2)
    text = stream_verilog(CordicLegSolver(robot, small), "cordic_solver")
    assert "module cordic_solver(" in text
    for port in ("input [8:0] i_r", "input [11:0] i_theta", "input [8:0] i_z", "output [16:0] o_s1",
                 "output [16:0] o_s3", "input i_valid", "output i_ready", "output o_valid", "input o_ready"):
        assert port in text, port
    with pytest.raises(TypeError, match=r"^core must be a stream component with i, o and latency, not 3$"):
        FlatStreamTop(3)


@pytest.mark.parametrize("c", [0, 1, 3, 7, 480, -480, 0b1011011101, 123457, -(1 << 20) + 3])
def test_csd_digits(c):
    d = fc.csd(c)
    assert sum(s * (1 << k) for s, k in d) == c
    ks = sorted(k for _, k in d)
    assert all(b - a >= 2 for a, b in zip(ks, ks[1:]))     # no adjacent non-zero digits
    assert len(d) <= (abs(c).bit_length() + 2) // 2


def test_shift_add_constant_multiply_is_exact():
    """The RTL's shift-add and ``*`` constant multiplies against the model, signed and unsigned."""
    from amaranth.sim import Simulator
    consts = [480, -480, 7, -3, 123457]
    m = Module()
    a_u, a_s = Signal(9), Signal(signed(12))
    ops = AmaranthOps(m, Signal(), {}, [])
    outs = [(a, c, ops.mulc(a, c)) for a in (a_u, a_s) for c in consts]
    probes = [Signal(signed(40), name=f"p{k}") for k in range(len(outs))]
    for p, (_, _, e) in zip(probes, outs):
        m.d.comb += p.eq(e)
    got = []

    async def bench(ctx):
        for vu, vs in [(0, 0), (511, -2048), (300, 2047), (1, -1)]:
            ctx.set(a_u, vu)
            ctx.set(a_s, vs)
            got.append([(vu if a is a_u else vs) * c - ctx.get(p) for p, (a, c, _) in zip(probes, outs)])

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    assert all(v == 0 for row in got for v in row)
