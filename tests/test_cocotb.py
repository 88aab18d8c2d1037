"""cocotb tests of the exported leg-core Verilog on Icarus and Verilator.

Each simulator gets one build of ``leg_verilog(LegCore(small_plan, PWM_PERIOD))`` and runs the
three cocotb tests of :mod:`ikseries.sim.cocotb_leg` (see there for what each checks):

* test_back_to_back  - corner + 3000 random targets, one per cycle: bit-exact vs the golden
  model, in order, latency == core.latency for every target, one transfer per cycle;
* test_backpressure  - random i_valid gaps and o_ready backpressure: bit-exact, in order, none
  dropped or duplicated, stall rules, latency == core.latency + stall cycles;
* test_pwm           - PWM waveforms: period, high time == last transferred width, double
  buffering, hold, width >= period (constant high), low after reset.

Runtime (2 cores): Icarus ~25 s (the PWM test's ~5 periods dominate), Verilator ~20-35 s
(mostly the C++ build).
"""
from __future__ import annotations

import os

import pytest

from ikseries.sim.runner import run, simulator_available

# PWM period in clock cycles. The small plan's widths are ~42k..91k ticks: with 75000 some targets
# have all widths below the period (normal pulses) and some have a width >= the period (constant
# high), and the PWM test simulates only ~5 periods. The evaluator checks do not depend on it.
PWM_PERIOD = 75_000

COCOTB_TESTS = {"test_back_to_back", "test_backpressure", "test_pwm"}


def _skip_unless_available(simulator):
    """A missing simulator fails the test (the README's setup installs both), unless
    IKSERIES_ALLOW_MISSING_SIMULATORS=1, which turns that into a skip."""
    ok, why = simulator_available(simulator)
    if not ok:
        if os.environ.get("IKSERIES_ALLOW_MISSING_SIMULATORS") == "1":
            pytest.skip(why)
        pytest.fail(f"{simulator} is missing ({why}); install it or set IKSERIES_ALLOW_MISSING_SIMULATORS=1")


@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_leg_core_cocotb(simulator, small_plan_file, tmp_path_factory):
    _skip_unless_available(simulator)
    build_dir = tmp_path_factory.mktemp(f"cocotb_{simulator}_period{PWM_PERIOD}")
    res = run(small_plan_file, PWM_PERIOD, simulator, build_dir)
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()


def test_cocotb_bench_detects_wrong_latency(small_plan_file, tmp_path_factory):
    """The bench is not vacuous: told a latency one cycle off, the back-to-back test fails."""
    _skip_unless_available("icarus")
    build_dir = tmp_path_factory.mktemp("cocotb_icarus_wrong_latency")
    ok = run(small_plan_file, PWM_PERIOD, "icarus", build_dir, n_random=50,
             testcase="test_back_to_back")
    assert ok.ok, ok.summary()
    bad = run(small_plan_file, PWM_PERIOD, "icarus", build_dir, n_random=50,
              testcase="test_back_to_back", latency=ok.latency + 1)
    assert set(bad.tests) == {"test_back_to_back"}, bad.summary()
    passed, msg = bad.tests["test_back_to_back"]
    assert not passed and "latency" in msg, bad.summary()


def test_full_plan_on_icarus(plan, tmp_path_factory):
    """The real cylinder-leg plan (not just the small one) streams bit-exactly through its
    exported Verilog, with and without backpressure, at the latency property."""
    _skip_unless_available("icarus")
    d = tmp_path_factory.mktemp("cocotb_icarus_full_plan")
    plan_file = d / "plan.json"
    plan_file.write_text(plan.dumps())
    res = run(plan_file, 960_000, "icarus", d / "build", n_random=500,
              testcase="test_back_to_back,test_backpressure")
    assert set(res.tests) == {"test_back_to_back", "test_backpressure"}, res.summary()
    assert res.ok, res.summary()
    assert res.latency == plan.latency
