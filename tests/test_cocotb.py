"""cocotb tests of the exported leg-core Verilog on Icarus and Verilator.

Each simulator gets one build of ``leg_verilog(LegCore(small_plan, PWM_PERIOD))`` and runs the
three cocotb tests of :mod:`ikseries.sim.cocotb_leg.tests` (see there for what each checks; the
bench reads the design from the manifest the runner writes):

* test_back_to_back  - corner + 3000 random targets, one per cycle: bit-exact vs the golden
  model, in order, latency == core.latency for every target, one transfer per cycle;
* test_backpressure  - random i_valid gaps and o_ready backpressure: bit-exact, in order, none
  dropped or duplicated, stall rules, latency == core.latency + stall cycles;
* test_pwm           - PWM waveforms: period, high time == last transferred width, double
  buffering, hold, width >= period (constant high), low after reset.

Runtime (2 cores): Icarus ~25 s (the PWM test's ~5 periods dominate), Verilator ~20-35 s
(mostly the C++ build).

The same three tests also run on cores with an initiation interval II > 1: the folded leg top
(``LegCore(small_plan, PWM_PERIOD, multipliers=1, dsp=(16, 16))``, II = latency = 239 cycles) on
both simulators and the shared robot top (``RobotCore`` over the small plan, three legs) on
Icarus; with II = 239 the runner's default is 251 random targets (plus 20 corners) back to back
and half as many with backpressure, ~15-25 s per simulator.

The modulo-scheduled leg top (``LegCore(small_plan, PWM_PERIOD, interval=4)``: several targets
in flight, i_ready high when the phase counter is 0) runs them too on both simulators, with 1000
random targets: ~30 s on Icarus (which simulates the running modulo pipeline at a few thousand
cycles per second; the PWM test keeps it frozen while outputs wait for their edges), ~45 s on
Verilator (mostly the C++ build). At II = 1 the same core never stalls and queues its outputs
(stream rule ``buffered``), and runs them too on both simulators.
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
    assert res.latency == plan.depth


# ---- cores with an initiation interval > 1 -------------------------------------------------

@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_folded_leg_core_cocotb(simulator, small_plan, small_plan_file, tmp_path_factory):
    """The folded leg top (one multiplier, 16x16 DSP operands): every cocotb test, with the
    initiation interval passed to the bench (one target every II cycles, exact latency)."""
    from ikseries.hdl.leg import LegCore
    _skip_unless_available(simulator)
    core = LegCore(small_plan, PWM_PERIOD, multipliers=1, dsp=(16, 16))
    assert core.initiation_interval > 1
    build_dir = tmp_path_factory.mktemp(f"cocotb_{simulator}_folded")
    res = run(small_plan_file, PWM_PERIOD, simulator, build_dir, core=core)
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.latency, res.initiation_interval, res.top, res.stream_rule) == \
        (core.latency, core.initiation_interval, "leg", "folded")
    assert res.n_random >= 16


def test_robot_core_cocotb(small_plan, small_plan_file, tmp_path_factory):
    """The shared robot top (three legs on one folded evaluator) on Icarus: random legs returned
    on o_leg, bit-exact widths, exact latency, and the last leg's PWM waveforms."""
    from ikseries.hdl.shared import RobotCore
    _skip_unless_available("icarus")
    core = RobotCore(small_plan, 3, PWM_PERIOD, 48e6, multipliers=1, dsp=(16, 16))
    build_dir = tmp_path_factory.mktemp("cocotb_icarus_robot")
    res = run(small_plan_file, PWM_PERIOD, "icarus", build_dir, core=core)
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.top, res.legs, res.initiation_interval, res.stream_rule) == \
        ("robot", 3, core.initiation_interval, "folded")


@pytest.mark.parametrize("wrong", ["latency", "ii"])
def test_cocotb_bench_detects_wrong_folded_timing(wrong, small_plan, small_plan_file, tmp_path_factory):
    """Not vacuous for II > 1 either: a latency one cycle off, or an initiation interval one
    cycle off, fails the back-to-back test of the folded core."""
    from ikseries.hdl.leg import LegCore
    _skip_unless_available("icarus")
    core = LegCore(small_plan, PWM_PERIOD, multipliers=1, dsp=(16, 16))
    passed, msg, summary = _back_to_back_told_wrong(core, wrong, small_plan_file,
                                                    tmp_path_factory.mktemp(f"cocotb_icarus_folded_wrong_{wrong}"))
    assert not passed and ("latency" if wrong == "latency" else "initiation interval") in msg, summary


def _back_to_back_told_wrong(core, wrong, plan_file, build_dir):
    """(passed, message, summary) of the back-to-back test on Icarus (4 random targets) told a
    latency (``wrong="latency"``) or an initiation interval (``"ii"``) one cycle too long."""
    told = ({"latency": core.latency + 1} if wrong == "latency"
            else {"initiation_interval": core.initiation_interval + 1})
    bad = run(plan_file, PWM_PERIOD, "icarus", build_dir, core=core, n_random=4,
              testcase="test_back_to_back", **told)
    assert set(bad.tests) == {"test_back_to_back"}, bad.summary()
    return (*bad.tests["test_back_to_back"], bad.summary())


def _modulo_core(small_plan, interval: int = 4):
    """The modulo-scheduled leg top over the small plan (II = ``interval`` < latency)."""
    from ikseries.hdl.leg import LegCore
    core = LegCore(small_plan, PWM_PERIOD, interval=interval)
    assert core.architecture == "modulo" and 1 < core.initiation_interval < core.latency
    return core


@pytest.mark.parametrize("interval, rule", [(4, "modulo"), (1, "buffered")])
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_modulo_leg_core_cocotb(simulator, interval, rule, small_plan, small_plan_file, tmp_path_factory):
    """The modulo-scheduled leg top. At II = 4 (several targets in flight) every cocotb test
    with the phase rule (i_ready == en & phase 0, checked every cycle), 1000 random targets
    (plus corners) one every II cycles back to back at the exact latency, half as many with
    backpressure (latency + stalls), PWM waveforms (outputs held at o until their scheduled
    edge). At II = 1 the pipeline never stalls and buffers its outputs: the buffered rule
    (i_ready == fewer than latency + 1 targets in flight), with backpressure each output out
    at the first edge without a stall once it is ready."""
    from ikseries.hdl.leg import LegCore
    _skip_unless_available(simulator)
    core = _modulo_core(small_plan) if interval > 1 else LegCore(small_plan, PWM_PERIOD, interval=1)
    build_dir = tmp_path_factory.mktemp(f"cocotb_{simulator}_{rule}")
    res = run(small_plan_file, PWM_PERIOD, simulator, build_dir, core=core, n_random=1000)
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.latency, res.initiation_interval, res.stream_rule, res.top) == \
        (core.latency, interval, rule, "leg")


@pytest.mark.parametrize("wrong", ["latency", "ii"])
def test_cocotb_bench_detects_wrong_modulo_timing(wrong, small_plan, small_plan_file, tmp_path_factory):
    """Not vacuous for the modulo core: told a latency one cycle off, the back-to-back test fails
    on latency; told an initiation interval one cycle off, on the bench's phase (i_ready)."""
    _skip_unless_available("icarus")
    passed, msg, summary = _back_to_back_told_wrong(_modulo_core(small_plan), wrong, small_plan_file,
                                                    tmp_path_factory.mktemp(f"cocotb_icarus_modulo_wrong_{wrong}"))
    assert not passed and ("latency (expected" if wrong == "latency" else "i_ready") in msg, summary


def test_cocotb_bench_detects_wrong_buffered_latency(small_plan, small_plan_file, tmp_path_factory):
    """Not vacuous for the buffered core: told a latency one cycle long, back to back fails on
    latency."""
    from ikseries.hdl.leg import LegCore
    _skip_unless_available("icarus")
    core = LegCore(small_plan, PWM_PERIOD, interval=1)
    passed, msg, summary = _back_to_back_told_wrong(core, "latency", small_plan_file,
                                                    tmp_path_factory.mktemp("cocotb_icarus_buffered_wrong"))
    assert not passed and "latency (expected" in msg, summary


def test_build_notes_simulators_auto_skipped(monkeypatch, tmp_path):
    """The note mechanism remains for a real reason: "auto" skips a missing simulator and says so."""
    from ikseries import steps
    from ikseries.sim import runner
    monkeypatch.setattr(runner, "simulator_available", lambda s: (False, f"no {s} here"))
    msgs = []
    res = steps.cocotb(tmp_path / "plan.json", PWM_PERIOD, "auto", tmp_path, tmp_path, msgs.append)
    assert res.runs == () and res.record() == {}
    assert res.note == "cocotb skipped on icarus (no icarus here), verilator (no verilator here)"
    assert msgs == ["cocotb on icarus: skipped (no icarus here)", "cocotb on verilator: skipped (no verilator here)"]



@pytest.mark.parametrize("folded", [False, True])
def test_piecewise_plan_on_icarus(folded, tmp_path_factory):
    """A piecewise plan (index / mask, coefficients from lut tables) through the exported leg
    core, pipelined (one ROM read per pipeline stage, stalling with the others) and folded
    (table ROM in the microcode machine): all three cocotb tests, bit-exact against the golden
    model at the latency property. Widths are 0..100 ticks: with the pipelined core's 64-cycle
    period both pulses and constant high; the folded core needs a period >= 4 II (and
    >= 2 latency + 4), taken from its properties."""
    from helpers import tiny_piecewise_plan
    from ikseries.hdl.folded import FoldedEvaluator
    from ikseries.hdl.leg import LegCore
    _skip_unless_available("icarus")
    plan = tiny_piecewise_plan(1, clamp=(0, 100))
    period = 64
    if folded:
        probe = FoldedEvaluator(plan, 1, (16, 16))
        period = max(256, 4 * probe.initiation_interval, 2 * probe.latency + 4)
    core = LegCore(plan, period, multipliers=1 if folded else None, dsp=(16, 16) if folded else None)
    d = tmp_path_factory.mktemp(f"cocotb_icarus_piecewise_{'folded' if folded else 'pipelined'}")
    plan_file = d / "plan.json"
    plan_file.write_text(plan.dumps())
    res = run(plan_file, period, "icarus", d / "build", core=core, n_random=80 if folded else 1000)
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.latency, res.initiation_interval) == (core.latency, core.initiation_interval)


#: per family with a DSP primitive: its DSP size, the primitive and a parameter text every
#: registered instance carries, and the family's table primitive (block RAM) if it has one
DSP_PRIMITIVES = {"ecp5": ((18, 18), "MULT18X18D", '.REG_OUTPUT_CLK("CLK0")', "DP16KD"),
                  "ice40": ((16, 16), "SB_MAC16", ".PIPELINE_16x16_MULT_REG2(1'h1)", None)}


def _exported(build_dir) -> str:
    return next(build_dir.glob("*.v")).read_text()


@pytest.mark.parametrize("family", list(DSP_PRIMITIVES))
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_modulo_core_on_dsp_primitives_cocotb(simulator, family, small_plan, small_plan_file, tmp_path_factory):
    """The modulo core with its products on instantiated MULT18X18D (ECP5) or SB_MAC16 (iCE40)
    blocks, their own input and output registers (``dsp_registers``; single-block and
    limb-split products), on the ECP5 its tables on DP16KD block RAMs with their output
    register (``registered_tables``): the exported Verilog runs with the primitives' models and
    stays bit-exact at the latency of the fabric twin the Amaranth simulator runs."""
    from ikseries.hdl.leg import LegCore
    from ikseries.constraints.devices import primitive
    from ikseries.sim.runner import primitive_models
    _skip_unless_available(simulator)
    dsp, cell, registered, table = DSP_PRIMITIVES[family]
    # every table registered: the small plan's are shallower than DP16KD_MIN_DEPTH
    core = LegCore(small_plan, PWM_PERIOD, interval=3, dsp=dsp, dsp_registers=family,
                   registered_tables=table is not None)
    twin = core.simulation_model()
    assert core.evaluator.registered_tables == twin.evaluator.registered_tables == (1 if table else None)
    assert core.latency == twin.latency and core.initiation_interval == 3
    build_dir = tmp_path_factory.mktemp(f"cocotb_{simulator}_modulo_{family}_dsp")
    res = run(small_plan_file, PWM_PERIOD, simulator, build_dir, core=core, n_random=300)
    verilog = _exported(build_dir)
    # every instance registered; at least one per unit (a limb-split unit has one per limb pair)
    assert verilog.count(registered) == verilog.count(f"{cell} #(") >= max(2, core.evaluator.multipliers)
    assert primitive_models(verilog) == [primitive(c).model_path for c in (cell, table) if c]
    if table:      # every table block with its output register
        assert verilog.count(f"{table} #(") == verilog.count('.REGMODE_A("OUTREG")') > 0
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.latency, res.initiation_interval) == (core.latency, 3)


@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_robot_core_on_sb_mac16_primitives_cocotb(simulator, small_plan, small_plan_file, tmp_path_factory):
    """The shared robot top (three legs, one folded evaluator) with its limb products on an
    instantiated SB_MAC16 with its own registers: bit-exact on both simulators with the
    primitive's model, at the latency and initiation interval of the core with fabric
    registers."""
    from ikseries.hdl.shared import RobotCore
    _skip_unless_available(simulator)
    core = RobotCore(small_plan, 3, PWM_PERIOD, 48e6, multipliers=1, dsp=(16, 16), dsp_registers="ice40")
    twin = core.simulation_model()
    assert twin.dsp_registers is None and (twin.latency, twin.initiation_interval) == \
        (core.latency, core.initiation_interval)
    build_dir = tmp_path_factory.mktemp(f"cocotb_{simulator}_robot_sb_mac16")
    res = run(small_plan_file, PWM_PERIOD, simulator, build_dir, core=core)
    assert _exported(build_dir).count(DSP_PRIMITIVES["ice40"][2]) == 1
    print(res.summary())
    assert set(res.tests) == COCOTB_TESTS, res.summary()
    assert res.ok, res.summary()
    assert (res.top, res.legs, res.latency, res.initiation_interval) == \
        ("robot", 3, core.latency, core.initiation_interval)
