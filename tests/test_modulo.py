"""Partly folded (modulo-scheduled) evaluator against the golden model."""
import numpy as np
import pytest

from helpers import all_ports, tiny_piecewise_plan, tiny_plan
from ikseries.hdl.modulo import MUL_LATENCY, ModuloEvaluator, modulo_schedule
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_leg
from ikseries.sim.targets import corner_targets, random_targets


def _check(core, plan, targets, **kw):
    res = simulate_leg(core, targets, **kw)
    want = golden.outputs(plan, targets)
    for s in want:
        assert np.array_equal(res.outputs[s], want[s]), s
    return res


@pytest.mark.parametrize("ii", [1, 2, 3, 5])
def test_every_port_value_bit_exact_at_each_initiation_interval(ii):
    plan = tiny_plan(3)
    core = ModuloEvaluator(plan, ii)
    assert core.initiation_interval == ii
    assert core.multipliers == -(-plan.count("mul") // ii)
    res = _check(core, plan, all_ports(plan))
    assert np.all(res.latencies == core.latency)
    # back to back: one target every ii cycles
    assert np.all(np.diff(res.input_cycles) == ii)


@pytest.mark.parametrize("seed", [0, 1])
def test_piecewise_plan_bit_exact_with_backpressure(seed):
    plan = tiny_piecewise_plan(seed)
    core = ModuloEvaluator(plan, 4)
    _check(core, plan, all_ports(plan), ready_prob=0.6, valid_prob=0.7, seed=seed)


def test_schedule_respects_the_multipliers_and_dependencies():
    plan = tiny_plan(1)
    for ii in (1, 2, 4):
        sch = modulo_schedule(plan, ii)
        slots = set()
        for i, n in enumerate(plan.nodes):
            if n.op == "mul":
                key = (sch.unit[i], sch.start[i] % ii)
                assert key not in slots
                slots.add(key)
                assert sch.ready[i] == sch.start[i] + MUL_LATENCY
            if sch.start[i] is not None:
                assert all(sch.ready[a] <= sch.start[i] for a in n.args)
    # more multipliers than needed never lengthen the schedule
    assert modulo_schedule(plan, 4, units=8).latency <= modulo_schedule(plan, 4).latency


def test_real_plan_random_targets_bit_exact(plan):
    core = ModuloEvaluator(plan, 6)
    targets = {k: np.concatenate([corner_targets(plan)[k], v])
               for k, v in random_targets(plan, 300, np.random.default_rng(5)).items()}
    res = _check(core, plan, targets)
    assert np.all(res.latencies == core.latency)


@pytest.mark.parametrize("kwargs, words", [
    ({"initiation_interval": 0}, "initiation_interval must be an integer >= 1, not 0"),
    ({"initiation_interval": 2, "units": 0}, "units must be None or an integer >= 1, not 0"),
    ({"initiation_interval": 1, "units": 1}, "units must be at least"),
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
    _check(core, plan, all_ports(plan))
