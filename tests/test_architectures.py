"""The Architecture interface: registry, option checks, timing from pure data equal to the
built cores' timing."""
import dataclasses

import pytest

from ikseries.architecture import build_target
from ikseries.hdl.architectures import (STREAM_RULES, Architecture, BuildTarget, Timing, architecture_class,
                                        architecture_names)
from ikseries.hdl.architectures.cordic import CordicIterative, CordicPipelined
from ikseries.hdl.architectures.folded import Folded
from ikseries.hdl.architectures.modulo import Modulo
from ikseries.hdl.architectures.pipelined import Pipelined
from ikseries.hdl.architectures.shared import Shared

POLYNOMIAL = [Pipelined(), Modulo(3), Modulo(8, "ice40"), Modulo(5, "ecp5", primitives=True),
              Modulo(6, "ice40", primitives=True), Folded(1, "ice40"), Folded(1, "ice40", primitives=True),
              Folded(2, "none"), Shared(3, 1, "ecp5"), Shared(3, 1, "ice40", primitives=True)]


def test_every_architecture_is_registered_by_its_name():
    assert architecture_names() == ["cordic", "cordic-iterative", "folded", "modulo", "pipelined", "shared"]
    for name in architecture_names():
        cls = architecture_class(name)
        assert issubclass(cls, Architecture) and cls.name == name


def test_unknown_architecture_name():
    with pytest.raises(ValueError, match=r"^architecture must be one of cordic, cordic-iterative, folded, modulo, "
                                         r"pipelined, shared, not 'systolic'$"):
        architecture_class("systolic")


@pytest.mark.parametrize("arch", POLYNOMIAL, ids=lambda a: a.describe())
def test_timing_from_pure_data_is_the_built_cores(arch, small_plan, robot):
    """timing() needs no elaboration and agrees with the evaluator and the exported core; the
    benches read the core's handshake from the manifest, so it must be the architecture's too."""
    from ikseries.hdl.export import stream_rule
    t = arch.timing(small_plan)
    ev = arch.evaluator(small_plan)
    core = arch.build(small_plan, build_target(robot))
    assert (t.latency, t.initiation_interval) == (ev.latency, ev.initiation_interval)
    assert (t.latency, t.initiation_interval) == (core.latency, core.initiation_interval)
    assert t.stream_rule in STREAM_RULES and t.legs == arch.legs
    assert stream_rule(core) == t.stream_rule
    assert getattr(core, "dsp_registers", None) == (arch.dsp if getattr(arch, "primitives", False) else None)


def test_stream_rules_and_rates(small_plan):
    assert Pipelined().timing(small_plan).stream_rule == "pipelined"
    assert Modulo(4).timing(small_plan).stream_rule == "modulo"
    assert Folded(1).timing(small_plan).stream_rule == "folded"
    t = Shared(6, 1).timing(small_plan)
    assert t.refresh_hz(48e6) == pytest.approx(48e6 / (6 * t.initiation_interval))
    assert t.latency_counts == "clock" and Modulo(4).timing(small_plan).latency_counts == "enable"
    assert Modulo(4).timing(small_plan).initiation_interval == 4


def test_cordic_architectures_time_their_solver(robot):
    from ikseries.fit.baselines.cordic import CordicPlan
    from verilog_hashes import SIZED
    cp = CordicPlan(robot, dataclasses.replace(SIZED, rot_iters=3, xy_iters=3, uv_iters=3, law_iters=3))
    for arch in (CordicPipelined(), CordicIterative(cp.longest_loop)):
        t, core = arch.timing(cp), arch.build(cp, BuildTarget(1000, 48e6))
        assert (t.latency, t.initiation_interval) == (core.latency, core.initiation_interval)
    with pytest.raises(ValueError, match=rf"^interval must be an integer >= {cp.longest_loop} \(the longest loop "
                                         rf"of this design\), not 2$"):
        CordicIterative(2).timing(cp)


@pytest.mark.parametrize("make, msg", [
    (lambda: Modulo(0), r"^interval must be an integer >= 1, not 0$"),
    (lambda: Modulo(True), r"^interval must be an integer >= 1, not True$"),
    (lambda: Modulo(4, "xc7", primitives=True), r"^dsp must be one of ice40, ecp5 with primitives \(the families "
                                                r"whose DSP primitives are instantiated\), not 'xc7'$"),
    (lambda: Folded(1, None, primitives=True), r"^dsp must be one of ice40, ecp5 with primitives \(the families "
                                               r"whose DSP primitives are instantiated\), not None$"),
    (lambda: Modulo(4, "ecp5", primitives="yes"), r"^primitives must be true or false, not 'yes'$"),
    (lambda: Folded(0), r"^multipliers must be an integer >= 1, not 0$"),
    (lambda: Folded(1, "virtex"), r"^dsp must be None, 'none' or one of ice40, ecp5, xc7, not 'virtex'$"),
    (lambda: Shared(0), r"^legs must be an integer >= 1, not 0$"),
    (lambda: CordicIterative(1.5), r"^interval must be an integer >= 1, not 1.5$"),
    (lambda: Timing(3, 1, "systolic"), r"^stream_rule must be one of pipelined, modulo, folded, buffered, not 'systolic'$"),
])
def test_option_errors(make, msg):
    with pytest.raises(ValueError, match=msg):
        make()


def test_records_and_equality():
    assert Modulo(4, "ecp5").record() == {"architecture": "modulo", "multipliers": None, "dsp": "ecp5", "legs": 1,
                                          "interval": 4, "primitives": False,
                                          "description": "modulo-scheduled pipeline, one target per 4 cycles "
                                                         "(ecp5 18x18 DSP)"}
    assert Folded(2, "ice40") == Folded(2, "ice40") and Folded(2, "ice40") != Folded(1, "ice40")
    assert Shared(6, 1, "ice40").describe() == "folded evaluator shared by 6 legs, 1 multiplier (ice40 16x16 DSP)"


def test_every_architecture_offers_the_multiplier_count():
    """By default every architecture offers the multiplier count, the model the fit's cache key
    does not name (see ikseries.fit.cost); only modulo and pipelined offer another, the device
    model with cost="device", and the key then names it (tests/test_cost.py)."""
    from ikseries.fit.cost import DEFAULT_COST_MODEL, DeviceCost, MultiplierCount
    offering = {"modulo", "pipelined"}
    for name in architecture_names():
        assert (architecture_class(name).cost_model is Architecture.cost_model) == (name not in offering), name
    for arch in POLYNOMIAL:
        assert arch.cost_model() == DEFAULT_COST_MODEL == MultiplierCount()
    assert Modulo(4, "ecp5", cost="device").cost_model() == DeviceCost("ecp5-25f", 4)
    assert Pipelined("ice40", cost="device").cost_model() == DeviceCost("ice40-up5k", 1)


def test_cost_model_of_a_robot_is_its_candidates(robot, monkeypatch):
    from ikseries.architecture import ArchitectureError, cost_model
    from ikseries.fit.cost import CostModel, MultiplierCount
    from ikseries.robot import with_hardware
    fastest = with_hardware(robot, architecture="fastest", fit_device="ecp5-25f")
    assert cost_model(robot) == cost_model(with_hardware(robot, architecture="auto")) == MultiplierCount()

    class PerTableRead(CostModel):
        name = "table reads"

        def cost(self, plan, output):
            return 0.0
    monkeypatch.setattr(Folded, "cost_model", lambda self: PerTableRead())
    assert cost_model(robot) == MultiplierCount()       # pipelined only
    with pytest.raises(ArchitectureError, match=r"^hardware.architecture = 'fastest' tries architectures that "
                                                r"price a plan differently \(multipliers, table reads\); "
                                                r"name one architecture$"):
        cost_model(fastest)


def test_the_fitter_prices_structures_by_the_cost_model(small_robot, monkeypatch):
    """fit_robot hands its cost model to the fit context, and the structure search prices a
    candidate structure by it (the trial plan of the one servo, named "cost")."""
    import ikseries.fit.fitter as fitter
    from ikseries.fit.context import FitContext
    from ikseries.fit.cost import MultiplierCount
    from ikseries.fit.lowering import structure_cost
    from ikseries.fit.structure import feature_sets

    class Counting(MultiplierCount):
        def __init__(self):
            self.priced = []

        def cost(self, plan, output):
            self.priced.append(output)
            return 1000 + super().cost(plan, output)
    model = Counting()
    contexts = []
    monkeypatch.setattr(fitter, "_fit_attempts", lambda ctx, progress, certified, jobs: contexts.append(ctx))
    fitter.fit_robot(small_robot, cost_model=model)
    assert [c.cost_model for c in contexts] == [model]
    ctx = FitContext.for_robot(small_robot, 0.1, model)
    fs = feature_sets(ctx, 0)[0]
    terms = [(0,) * len(fs.names), (1,) + (0,) * (len(fs.names) - 1)]
    assert structure_cost(ctx, fs, terms) >= 1000 and model.priced == ["cost"]


def test_rating_and_building_a_core_schedule_it_once(small_plan, robot):
    """The rate, the multiplier count and the built core share one schedule per plan object."""
    from ikseries.fit.plan import Plan
    mod = Modulo(4, "ecp5")
    sch = mod.build(small_plan, build_target(robot)).evaluator.schedule
    assert mod.evaluator(small_plan).schedule is sch and mod.multiplier_units(small_plan) == sch.units
    fold = Folded(2, "ice40")
    assert fold.build(small_plan, build_target(robot)).evaluator.program is fold.program(small_plan)
    twin = Plan.from_json(small_plan.to_json())
    assert mod.evaluator(twin).schedule == sch and mod.evaluator(twin).schedule is not sch


def test_every_core_rate_is_its_timings(small_plan, robot):
    """The robot core's and the manifest's refresh rates are those of the architecture's timing."""
    from ikseries.hdl.export import core_timing
    target = build_target(robot)
    for arch in POLYNOMIAL:
        t, core = arch.timing(small_plan), arch.build(small_plan, target)
        assert core_timing(core) == t
        assert core_timing(core).refresh_hz(target.clock_hz) == target.clock_hz / (arch.legs * t.initiation_interval)
    shared = Shared(3, 1, "ecp5").build(small_plan, target)
    assert shared.refresh_hz == Shared(3, 1, "ecp5").timing(small_plan).refresh_hz(target.clock_hz)
