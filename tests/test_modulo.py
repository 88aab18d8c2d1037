"""Partly folded (modulo-scheduled) evaluator against the golden model."""
import numpy as np
import pytest

from helpers import all_ports, simulate_bit_exact, tiny_grid_plan, tiny_piecewise_plan, tiny_plan
from ikseries.hdl.modulo import (BUFFER_LATENCY, CLAMP_LATENCY, MUL_LATENCY, REGISTERED_TABLE_LATENCY,
                                 TABLE_LATENCY, WIDE_MUL_LATENCY, ModuloEvaluator, modulo_schedule)
from ikseries.sim.targets import corner_targets, random_targets


@pytest.mark.parametrize("ii", [1, 2, 3, 5])
def test_every_port_value_bit_exact_at_each_initiation_interval(ii):
    plan = tiny_plan(3)
    core = ModuloEvaluator(plan, ii, dsp=None)
    assert core.initiation_interval == ii
    assert core.multipliers == -(-plan.count("mul") // ii)
    res = simulate_bit_exact(core, plan, all_ports(plan))
    assert np.all(res.latencies == core.latency)
    # back to back: one target every ii cycles
    assert np.all(np.diff(res.input_cycles) == ii)


def test_interval_one_buffers_its_outputs_instead_of_stalling():
    """At an interval of 1 the pipeline runs unconditionally (no enable on its registers) and
    its outputs wait in a FIFO: one buffer cycle more than the schedule, one target a cycle
    back to back, and under backpressure every target still arrives, in order, bit exact."""
    from amaranth.back import verilog
    plan = tiny_piecewise_plan(0)
    core = ModuloEvaluator(plan, 1)
    assert core.latency == core.schedule.latency + BUFFER_LATENCY
    res = simulate_bit_exact(core, plan, all_ports(plan))
    assert np.all(res.latencies == core.latency) and np.all(np.diff(res.input_cycles) == 1)
    simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.3, valid_prob=0.8, seed=5)
    stalling = verilog.convert(ModuloEvaluator(plan, 2), name="m", emit_src=False)
    assert "o__ready" in stalling.split("assign en =")[1].split(";")[0]
    assert "assign en =" not in verilog.convert(core, name="m", emit_src=False)


def test_interval_one_accepts_only_what_its_buffer_holds():
    """With ``o.ready`` low the core takes exactly as many targets as its FIFO has words
    (``latency + 1``), then drops ``i.ready``; released, it gives them all, bit exact."""
    from amaranth.sim import Simulator

    from ikseries.sim import golden
    plan = tiny_plan(1)
    core = ModuloEvaluator(plan, 1, dsp=None)
    ports = all_ports(plan)
    n = 3 * core.latency
    taken, out = [], []

    async def bench(ctx):
        ctx.set(core.o.ready, 0)
        for cycle in range(6 * core.latency + n):
            k = len(taken)
            ctx.set(core.i.valid, int(k < n))
            ctx.set(core.i.payload, {p: int(v[k % n]) for p, v in ports.items()})
            if cycle == 3 * core.latency:
                assert len(taken) == core.latency + 1
                ctx.set(core.o.ready, 1)
            if k < n and ctx.get(core.i.ready):
                taken.append(k)
            if ctx.get(core.o.valid) and ctx.get(core.o.ready):
                out.append(ctx.get(core.o.payload.y))
            await ctx.tick()

    sim = Simulator(core)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert len(out) == n
    assert out == list(golden.outputs(plan, {p: v[:n] for p, v in ports.items()})["y"])


@pytest.mark.parametrize("seed", [0, 1])
def test_piecewise_plan_bit_exact_with_backpressure(seed):
    plan = tiny_piecewise_plan(seed)
    core = ModuloEvaluator(plan, 4)
    simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.6, valid_prob=0.7, seed=seed)


def test_grid_plan_bit_exact_with_backpressure():
    """A two-port grid plan (the table address from both cell numbers)."""
    plan = tiny_grid_plan(0, (2, 2))[0]
    core = ModuloEvaluator(plan, 3)
    simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.6, valid_prob=0.7, seed=2)


@pytest.mark.parametrize("clamp", [(-100, 100), (0, 100), (0, 127), (-128, 127)])
@pytest.mark.parametrize("dsp", [None, (8, 8), (6, 5)])
def test_schedule_respects_the_multipliers_and_dependencies(dsp, clamp):
    plan = tiny_plan(1, clamp=clamp)
    for ii in (1, 2, 4):
        sch = modulo_schedule(plan, ii, dsp)
        slots = set()
        for i, n in enumerate(plan.nodes):
            if n.op == "mul":
                key = (sch.unit[i], sch.start[i] % ii)
                assert key not in slots
                slots.add(key)
                assert sch.ready[i] == sch.start[i] + sch.unit_latency[sch.unit[i]]
                wa, wb = (plan.nodes[a].width + (not plan.nodes[a].signed) for a in n.args)
                ua, ub = sch.operand_widths[sch.unit[i]]
                assert (wb <= ua and wa <= ub) if sch.swap[i] else (wa <= ua and wb <= ub)
            if sch.start[i] is not None:
                assert all(sch.ready[a] <= sch.start[i] for a in n.args)
            if n.op == "clamp":         # input clamps: in the input register; others two cycles
                assert (sch.start[i], sch.ready[i]) == (None, 1) if plan.nodes[n.args[0]].op == "input" \
                    else sch.ready[i] == sch.start[i] + _expected_clamp_cycles(plan, i)
        for (ua, ub), lat in zip(sch.operand_widths, sch.unit_latency):
            fits = dsp is None or (ua <= dsp[0] and ub <= dsp[1]) or (ua <= dsp[1] and ub <= dsp[0])
            assert lat == (MUL_LATENCY if fits else WIDE_MUL_LATENCY)


def _expected_clamp_cycles(plan, i):
    """One cycle when each limit the operand's interval crosses is 0 below or 2**k - 1 above."""
    x, (lo, hi) = plan.nodes[plan.nodes[i].args[0]], plan.nodes[i].param
    bit_tests = (x.lo >= lo or lo == 0) and (x.hi <= hi or (hi + 1) & hi == 0)
    return 1 if bit_tests else CLAMP_LATENCY


@pytest.mark.parametrize("clamp", [(0, 127), (0, 100), (-128, 127), (0, 31)])
def test_one_cycle_clamps_bit_exact(clamp):
    """Clamps whose reached limits are bit tests take one cycle; every port value, bit-exact."""
    plan = tiny_plan(3, clamp=clamp)
    out = next(i for i, n in enumerate(plan.nodes) if n.op == "clamp" and plan.nodes[n.args[0]].op != "input")
    core = ModuloEvaluator(plan, 2)
    assert core.schedule.ready[out] - core.schedule.start[out] == _expected_clamp_cycles(plan, out)
    simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.7, seed=4)


def test_grid_address_is_wiring():
    """The grid's cell address (row shifted left plus column, bits disjoint) takes no cycle."""
    plan = tiny_grid_plan(0, (2, 2))[0]
    sch = modulo_schedule(plan, 1)
    lut = next(i for i, n in enumerate(plan.nodes) if n.op == "lut")
    address = plan.nodes[lut].args[0]
    assert plan.nodes[address].op == "add" and sch.start[address] is None
    assert sch.ready[address] == max(sch.ready[a] for a in plan.nodes[address].args)


def _offset_cell_plan(offset: int):
    """A signed port v in [-16, 15] plus ``offset``, cut into cells of 4 values: a table per cell
    number times the offset inside the cell, plus a second table."""
    from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
    rng = np.random.default_rng(offset)
    b = PlanBuilder([PlanInput("v", "mm", 0, -16, 15, 6, True)])
    u = b.add(b.input_nodes["v"], b.const(float(offset), 0))
    cell, off = b.cell(u, 2)
    cells = b.nodes[cell].hi + 1
    p = b.mul(b.lut(cell, [float(x) for x in rng.integers(-50, 50, cells)], 0), off)
    out = b.add(p, b.lut(cell, [float(x) for x in rng.integers(-9, 9, cells)], 0))
    return b.build([PlanOutput("y", out, out, "ticks", 1.0)])


@pytest.mark.parametrize("registered", [None, True])
def test_a_table_index_offset_takes_no_adder(registered):
    """``v + 16`` cut into cells of 4: the tables are laid out for ``v``'s own cell number (a
    negative one wraps), so the addition is wiring; every port value bit-exact, registered
    tables or not. An offset that is no multiple of the cell keeps its adder."""
    plan = _offset_cell_plan(16)
    add = min(i for i, n in enumerate(plan.nodes) if n.op == "add")     # v + offset, built first
    core = ModuloEvaluator(plan, 1, registered_tables=registered)
    assert core.schedule.start[add] is None
    simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.7, seed=6)
    other = _offset_cell_plan(18)
    add = min(i for i, n in enumerate(other.nodes) if n.op == "add")
    assert modulo_schedule(other, 1).start[add] is not None


@pytest.mark.parametrize("dsp", [(8, 8), (6, 5), (4, 4)])
def test_products_split_in_limbs_stay_bit_exact(dsp):
    """Small DSP sizes force most products onto limb-split multipliers (every port value)."""
    plan = tiny_plan(2)
    core = ModuloEvaluator(plan, 3, dsp=dsp)
    assert WIDE_MUL_LATENCY in core.schedule.unit_latency
    res = simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.8, seed=3)
    assert np.all(res.latencies >= core.latency)


def test_real_plan_random_targets_bit_exact(plan):
    core = ModuloEvaluator(plan, 6)
    targets = {k: np.concatenate([corner_targets(plan)[k], v])
               for k, v in random_targets(plan, 300, np.random.default_rng(5)).items()}
    res = simulate_bit_exact(core, plan, targets)
    assert np.all(res.latencies == core.latency)


@pytest.mark.parametrize("kwargs, words", [
    ({"initiation_interval": 0}, "initiation_interval must be an integer >= 1, not 0"),
    ({"initiation_interval": 2, "dsp": (18,)}, r"dsp must be None or a pair of signed operand widths >= 2 such as \(16, 16\), not \(18,\)"),
])
def test_bad_parameters(kwargs, words):
    with pytest.raises(ValueError, match=words):
        ModuloEvaluator(tiny_plan(0), **kwargs)


def test_leg_core_with_an_interval_is_modulo_scheduled():
    from ikseries.hdl.leg import LegCore
    plan = tiny_plan(2, clamp=(0, 100))
    core = LegCore(plan, 400, interval=3)
    assert core.architecture == "modulo" and core.initiation_interval == 3
    assert core.latency == core.evaluator.latency
    with pytest.raises(ValueError, match="multipliers must be None with interval"):
        LegCore(plan, 400, interval=3, multipliers=1)
    simulate_bit_exact(core, plan, all_ports(plan))


def test_ecp5_dsp_registers_instantiate_the_primitive_with_its_registers():
    """Every block product a MULT18X18D with input and output registers on the pipeline enable
    and the domain's reset (the Verilog is simulated with the primitive's model in
    test_cocotb.py)."""
    from amaranth.back import verilog
    plan = tiny_plan(2)
    core = ModuloEvaluator(plan, 2, dsp_registers="ecp5")
    text = verilog.convert(core, name="m", emit_src=False)
    n = text.count("MULT18X18D")
    assert n == core.multipliers and n > 0
    for reg in ("INPUTA", "INPUTB", "OUTPUT"):
        assert text.count(f'.REG_{reg}_CLK("CLK0")') == n
    assert ".CE0(en)" in text.replace(" ", "")
    options = r"^dsp_registers must be None, or 'ice40' with dsp=\(16, 16\) or 'ecp5' with dsp=\(18, 18\), not "
    with pytest.raises(ValueError, match=options + r"'ice40' with dsp=\(18, 18\)$"):
        ModuloEvaluator(plan, 2, dsp_registers="ice40")
    with pytest.raises(ValueError, match=options + r"'ecp5' with dsp=\(16, 16\)$"):
        ModuloEvaluator(plan, 2, dsp=(16, 16), dsp_registers="ecp5")
    with pytest.raises(ValueError, match=options + r"'xc7'$"):
        ModuloEvaluator(plan, 2, dsp=(16, 16), dsp_registers="xc7")


def test_ice40_dsp_registers_instantiate_sb_mac16_with_its_registers():
    """Every block product an SB_MAC16 with its input and product registers on the pipeline
    enable and the domain's reset (simulated with the primitive's model in test_cocotb.py)."""
    from amaranth.back import verilog
    plan = tiny_plan(2)
    core = ModuloEvaluator(plan, 2, dsp=(16, 16), dsp_registers="ice40")
    text = verilog.convert(core, name="m", emit_src=False).replace(" ", "")
    n = text.count("SB_MAC16#(")
    assert n == core.multipliers and n > 0
    for p in ("A_REG(1'h1)", "B_REG(1'h1)", "PIPELINE_16x16_MULT_REG2(1'h1)", "TOPOUTPUT_SELECT(2'h3)",
              "BOTOUTPUT_SELECT(2'h3)", ".CE(en)", ".IRSTTOP(rst)", ".IRSTBOT(rst)"):
        assert text.count(p) == n, p


def test_leg_core_on_dsp_primitives_has_a_fabric_twin_for_the_amaranth_simulator():
    from ikseries.hdl.leg import LegCore
    plan = tiny_plan(2, clamp=(0, 100))
    core = LegCore(plan, 400, interval=3, dsp=(18, 18), dsp_registers="ecp5")
    twin = core.simulation_model()
    assert core.dsp_registers == "ecp5" and twin.dsp_registers is None
    assert (twin.latency, twin.initiation_interval, twin.period) == (core.latency, 3, 400)
    plain = LegCore(plan, 400, interval=3)
    assert plain.simulation_model() is plain
    simulate_bit_exact(twin, plan, all_ports(plan))
    with pytest.raises(ValueError, match=r"^dsp_registers must be None without interval or multipliers \(the "
                                         r"pipelined evaluator instantiates no DSP primitives\), not 'ecp5'$"):
        LegCore(plan, 400, dsp_registers="ecp5")
    folded = LegCore(plan, 400, multipliers=1, dsp=(16, 16), dsp_registers="ice40")
    assert folded.dsp_registers == folded.evaluator.dsp_registers == "ice40"
    assert folded.simulation_model().evaluator.dsp_registers is None


@pytest.mark.parametrize("ii, backpressure", [(1, False), (1, True), (3, True)])
def test_registered_tables_take_one_more_cycle_and_stay_bit_exact(ii, backpressure):
    """With registered tables every table read takes REGISTERED_TABLE_LATENCY cycles in the
    schedule (pure data), the fabric twin (Memory read port + output register) has that
    timing, and the outputs stay bit-exact, back to back and under backpressure."""
    plan = tiny_piecewise_plan(1)
    plain, core = ModuloEvaluator(plan, ii), ModuloEvaluator(plan, ii, registered_tables=True)
    luts = [i for i, n in enumerate(plan.nodes) if n.op == "lut"]
    assert luts and plain.registered_tables is None and core.registered_tables == 1
    for ev, lat in ((plain, TABLE_LATENCY), (core, REGISTERED_TABLE_LATENCY)):
        assert all(ev.schedule.ready[i] == ev.schedule.start[i] + lat for i in luts)
    assert core.latency > plain.latency
    res = simulate_bit_exact(core, plan, all_ports(plan), ready_prob=0.6 if backpressure else 1.0,
                             valid_prob=0.7 if backpressure else 1.0, seed=ii)
    if not backpressure:
        assert np.all(res.latencies == core.latency) and np.all(np.diff(res.input_cycles) == ii)


def test_real_plan_with_registered_tables_random_targets_bit_exact(plan):
    core = ModuloEvaluator(plan, 1, registered_tables=True)
    res = simulate_bit_exact(core, plan, random_targets(plan, 300, np.random.default_rng(6)),
                             ready_prob=0.8, seed=6)
    assert np.all(res.latencies >= core.latency)


def test_ecp5_tables_on_dp16kd_with_its_output_register():
    """With dsp_registers="ecp5" and registered tables each ROM (the luts of one index) is on
    DP16KD blocks with REGMODE_A "OUTREG" cleared by the domain's reset (the timing is checked
    by simulation, test_cocotb.py); by default only tables of at least DP16KD_MIN_DEPTH words
    (where Yosys itself would use block RAM) are, so the tiny plan's stay unregistered fabric
    tables, as with registered_tables=False; on the iCE40 (no block RAM primitive) tables stay
    unregistered."""
    from amaranth.back import verilog
    from ikseries.constraints.ecp5 import DP16KD_MIN_DEPTH, dp16kd_shape
    from ikseries.hdl.evaluator import lut_groups, lut_rom_init
    plan = tiny_piecewise_plan(0)
    core = ModuloEvaluator(plan, 1, dsp_registers="ecp5", registered_tables=True)
    assert core.registered_tables == 1 and [p.name for p in core.primitives] == ["MULT18X18D", "DP16KD"]
    text = verilog.convert(core, name="m", emit_src=False)
    blocks = sum(-(-w // dp16kd_shape(len(init))[0])
                 for init, w in (lut_rom_init(plan, i, luts) for i, luts in lut_groups(plan).items()))
    assert text.count("DP16KD #(") == text.count('.REGMODE_A("OUTREG")') == blocks > 0
    assert text.count(".RSTA(rst)") == blocks
    default = ModuloEvaluator(plan, 1, dsp_registers="ecp5")
    assert default.registered_tables == DP16KD_MIN_DEPTH > max(len(lut_rom_init(plan, i, luts)[0])
                                                              for i, luts in lut_groups(plan).items())
    off = ModuloEvaluator(plan, 1, dsp_registers="ecp5", registered_tables=False)
    for ev in (default, off):
        assert "DP16KD" not in verilog.convert(ev, name="m", emit_src=False)
        assert [p.name for p in ev.primitives] == ["MULT18X18D"]
        assert ev.latency == ModuloEvaluator(plan, 1).latency < core.latency
    deep = ModuloEvaluator(plan, 1, registered_tables=4)      # only the tables of >= 4 words
    lut_lat = {deep.schedule.ready[i] - deep.schedule.start[i] for i, n in enumerate(plan.nodes) if n.op == "lut"}
    assert lut_lat <= {TABLE_LATENCY, REGISTERED_TABLE_LATENCY}
    ice = ModuloEvaluator(plan, 1, dsp=(16, 16), dsp_registers="ice40")
    assert ice.registered_tables is None and [p.name for p in ice.primitives] == ["SB_MAC16"]
    for bad in ("yes", 0):
        with pytest.raises(ValueError, match=r"^registered_tables must be None, True, False or an integer >= 1 "
                                             rf"\(the fewest words of a registered table\), not {bad!r}$"):
            ModuloEvaluator(plan, 1, registered_tables=bad)


def test_leg_core_twin_keeps_registered_tables():
    from ikseries.hdl.leg import LegCore
    plan = tiny_piecewise_plan(0, clamp=(0, 100))
    core = LegCore(plan, 400, interval=2, dsp=(18, 18), dsp_registers="ecp5", registered_tables=True)
    twin = core.simulation_model()
    assert twin.dsp_registers is None and twin.evaluator.registered_tables == 1 and twin.latency == core.latency
    assert LegCore(plan, 400, interval=2, dsp=(18, 18), dsp_registers="ecp5").simulation_model().evaluator \
        .registered_tables == 128
    assert [p.name for p in core.primitives] == ["MULT18X18D", "DP16KD"] and twin.primitives == ()
    simulate_bit_exact(twin, plan, all_ports(plan), ready_prob=0.7, seed=4)
    with pytest.raises(ValueError, match=r"^registered_tables must be None without interval \(only the "
                                         r"modulo-scheduled evaluator registers its tables\), not True$"):
        LegCore(plan, 400, registered_tables=True)


def test_schedule_puts_products_that_share_an_operand_on_one_multiplier():
    """Placement prefers the multiplier that already reads an operand: its input multiplexer
    does not grow (a*x and b*x on one unit, c*y and d*y on the other)."""
    from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
    b = PlanBuilder([PlanInput(n, "mm", 0, -100, 100, 8, True) for n in "xyabcd"])
    v = b.input_nodes
    # in this order the lowest free multiplier would pair d*y with a*x
    terms = [b.mul(v["a"], v["x"]), b.mul(v["c"], v["y"]), b.mul(v["d"], v["y"]), b.mul(v["b"], v["x"])]
    total = b.add(b.add(terms[0], terms[1]), b.add(terms[2], terms[3]))
    plan = b.build([PlanOutput("s", total, total, "ticks", 1.0)])
    sch = modulo_schedule(plan, 2, None)
    assert sch.units == 2
    ports = {}
    for i, n in enumerate(plan.nodes):
        if n.op == "mul":
            x, y = n.args[::-1] if sch.swap[i] else n.args
            ports.setdefault(sch.unit[i], (set(), set()))
            ports[sch.unit[i]][0].add(x)
            ports[sch.unit[i]][1].add(y)
    assert sorted(min(len(a), len(b)) for a, b in ports.values()) == [1, 1]
    simulate_bit_exact(ModuloEvaluator(plan, 2, dsp=None), plan,
                       {k: np.random.default_rng(5).integers(-128, 128, 300) for k in "xyabcd"})
