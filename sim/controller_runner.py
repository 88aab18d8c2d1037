"""Build and run the cocotb bench of the exported robot controller on Icarus or Verilator.

The Verilog of a :class:`~ikseries.hdl.controller.RobotController` (ports ``clk``, ``rst``,
``rx``, ``tx``, ``pwm``) is written into ``build_dir`` with a
:class:`~ikseries.sim.cocotb_controller.config.ControllerConfig` (plan, shape, divisor,
identity, fuzz seed and length) and simulated with :mod:`ikseries.sim.cocotb_controller.tests`
through the leg bench's machinery (:func:`ikseries.sim.runner.simulate`).

Example::

    from ikseries.sim.controller_runner import run_controller
    res = run_controller("plan.json", 2, 820, 48_000_000, 12e6, "icarus", "build/ctl")
    assert res.ok, res.summary()
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from .cocotb_controller.config import TESTS, ControllerConfig
from .runner import ICARUS_ARGS, SIMULATORS, VERILATOR_OPT, Simulation, _write_if_changed, simulate, simulator_available

__all__ = ["TEST_MODULE", "TOPLEVEL", "ControllerResult", "run_controller"]

TEST_MODULE = "ikseries.sim.cocotb_controller.tests"
TOPLEVEL = "robot_controller"


@dataclasses.dataclass(frozen=True)
class ControllerResult:
    """One simulator's run of the controller bench."""
    simulator: str
    run: Simulation

    @property
    def tests(self) -> dict:
        return self.run.tests

    @property
    def ok(self) -> bool:
        r = self.run
        return bool(r.tests) and r.exit_code == 0 and all(p for p, _ in r.tests.values())

    def summary(self) -> str:
        r = self.run
        lines = [f"{self.simulator}: build {r.build_s:.1f} s, simulation {r.test_s:.1f} s, "
                 f"exit code {r.exit_code}, results {r.results_xml}"]
        lines += [f"  {n}: {'PASS' if p else 'FAIL'}" + (f"\n    {m}" if m else "") for n, (p, m) in r.tests.items()]
        return "\n".join(lines)


def run_controller(plan_path, legs: int, period: int, clock_hz: int, baud: float, simulator: str, build_dir, *,
                   name: str = "cocotb robot", manifest: bytes = bytes(range(0xA0, 0xA8)), seed: int = 1,
                   fuzz_bytes: int = 300, testcase: str | None = None, waves: bool = False,
                   verilator_opt: str | None = VERILATOR_OPT) -> ControllerResult:
    """Export, build and simulate the controller of the plan at ``plan_path``; returns a
    :class:`ControllerResult` (does not raise on test failures). ``testcase``: comma-separated
    names of :data:`~ikseries.sim.cocotb_controller.config.TESTS` (None: all)."""
    from amaranth.back import verilog

    from ..fit.plan import Plan
    from ..hdl.controller import RobotController

    if simulator not in SIMULATORS:
        raise ValueError(f"simulator must be one of {SIMULATORS}, not {simulator!r}")
    ok, why = simulator_available(simulator)
    if not ok:
        raise RuntimeError(why)
    tests = None if testcase is None else tuple(t.strip() for t in testcase.split(","))
    if tests is not None and not set(tests) <= set(TESTS):
        raise ValueError(f"testcase must name tests from {', '.join(TESTS)}, not {testcase!r}")
    plan_path, build_dir = Path(plan_path).resolve(), Path(build_dir).resolve()
    build_dir.mkdir(parents=True, exist_ok=True)
    plan = Plan.from_json(json.loads(plan_path.read_text()))
    ctl = RobotController(plan, legs, period, clock_hz, baud, name=name, manifest=manifest)
    vfile = build_dir / f"{TOPLEVEL}.v"
    _write_if_changed(vfile, verilog.convert(ctl, name=TOPLEVEL, emit_src=False))
    config = ControllerConfig(str(plan_path), legs, period, int(clock_hz), ctl.divisor, name, manifest.hex(),
                              ctl.servo.lead, seed, fuzz_bytes, tests).write(build_dir / "bench.json")
    sim = simulate(simulator, build_dir, TOPLEVEL, vfile, TEST_MODULE, config, testcase, waves, verilator_opt,
                   icarus_args=ICARUS_ARGS)
    return ControllerResult(simulator, sim)
