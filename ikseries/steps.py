"""The steps of ``ikseries build``, each returning a typed, immutable result.

:func:`fit` (plan, servo fits, sampled accuracy) -> :func:`core` (the chosen architecture's core
and its Verilog) -> :func:`simulate` (Amaranth, bit-exact against the golden model) ->
:func:`synthesise` (Yosys cell counts) -> :func:`cocotb` (the exported Verilog on Icarus and
Verilator). :mod:`ikseries.build` runs them around its output directory, and
:class:`ikseries.report.BuildReport` is made from their results. Each step raises
:class:`StepError` with one line when its result would not meet the robot's requirements.
"""
from __future__ import annotations

import contextlib
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import __version__
from .accuracy import measure
from .architecture import ArchitectureError, Choice, choose_architecture, cost_model
from .fit.fitter import FitError, fit_robot
from .fit.plan import Plan
from .hdl.export import leg_verilog, module_name, robot_verilog
from .hdl.shared import RobotCore
from .robot import robot_record
from .sim import golden
from .sim.amaranth_sim import simulate_leg, simulate_robot
from .sim.targets import corner_targets, random_targets

__all__ = ["StepError", "Fitted", "Core", "Simulation", "Synthesis", "CocotbRun", "Cocotb",
           "fit", "core", "simulate", "synthesise", "cocotb", "SIM_CYCLE_BUDGET", "COCOTB_N_RANDOM"]


class StepError(RuntimeError):
    """A step's result does not meet the robot's requirements (one line, for the user)."""


def _seconds_since(t0: float) -> float:
    return round(time.perf_counter() - t0, 1)


# -- fit ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Fitted:
    """The evaluation plan, the fit of each servo it was lowered from, and its sampled accuracy
    (:func:`ikseries.accuracy.measure`)."""
    plan: Plan
    servos: tuple
    accuracy: dict
    fit_s: float
    accuracy_s: float


def fit(robot, progress, jobs: int = 1) -> Fitted:
    """Fit ``robot``, minimising its architectures' cost model
    (:func:`ikseries.architecture.cost_model`), and measure the plan; refused unless the sampled
    error meets the tolerance."""
    t0 = time.perf_counter()
    progress(f"fitting {robot.name} (tolerance ±{robot.fit.tolerance_pu:g} pu)")
    try:
        plan, servos = fit_robot(robot, progress, cost_model=cost_model(robot), jobs=jobs)
    except (FitError, ArchitectureError) as e:
        raise StepError(str(e)) from None
    fit_s = _seconds_since(t0)
    plan.meta["robot_description"] = robot_record(robot)
    plan.meta["ikseries_version"] = __version__

    t0 = time.perf_counter()
    acc = measure(robot, plan)
    accuracy_s = _seconds_since(t0)
    plan.meta["accuracy"] = {"points": acc["points"],
                             "max_error_pu": {s: {k: v for k, v in w.items() if k != "at"}
                                              for s, w in acc["servos"].items()}}
    worst = max(acc["servos"].items(), key=lambda kv: kv[1]["total"])
    progress(f"accuracy on {acc['points']} points: worst {worst[0]} {worst[1]['total']:.3f} pu")
    if worst[1]["total"] > robot.fit.tolerance_pu:
        raise StepError(f"servo {worst[0]} misses the tolerance: {worst[1]['total']:.4f} pu > "
                        f"{robot.fit.tolerance_pu:g} pu at {worst[1]['at']}")
    return Fitted(plan, tuple(servos), acc, fit_s, accuracy_s)


# -- core ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Core:
    """The chosen architecture (:class:`ikseries.architecture.Choice`), its Verilog module
    name and text."""
    choice: Choice
    module: str
    verilog: str
    verilog_s: float

    @property
    def component(self):
        """The leg or robot core (an Amaranth component)."""
        return self.choice.core


def core(robot, plan: Plan, progress) -> Core:
    """Choose the architecture for ``robot`` (:func:`ikseries.architecture.choose_architecture`),
    build its core and export its Verilog."""
    try:
        choice = choose_architecture(robot, plan, progress=progress)
    except ArchitectureError as e:
        raise StepError(str(e)) from None
    c = choice.core
    progress(f"architecture: {choice.candidate.describe()}: latency {c.latency} cycles, a target every "
             f"{c.initiation_interval} cycles, every leg refreshed {choice.refresh_hz:,.0f} times/s")
    t0 = time.perf_counter()
    progress("exporting Verilog")
    name = module_name(robot.name)
    text = robot_verilog(c, name) if isinstance(c, RobotCore) else leg_verilog(c, name)
    return Core(choice, name, text, _seconds_since(t0))


# -- Amaranth simulation --------------------------------------------------------------------
#: simulated cycles the verification run aims at for a core taking one target per
#: ``initiation_interval`` cycles (random targets: between 64 and 1000, plus the corners)
SIM_CYCLE_BUDGET = 40_000


@dataclass(frozen=True)
class Simulation:
    """The Amaranth verification run: targets, mismatches against the golden model, the
    latency and interval measured; for a robot core, the legs addressed and wrong legs."""
    targets: int
    mismatches: int
    latency: int
    interval: int | None
    seconds: float
    legs_addressed: tuple[int, ...] | None = None
    leg_mismatches: int | None = None

    def record(self) -> dict:
        out = {"simulator": "amaranth", "targets": self.targets, "mismatches": self.mismatches,
               "latency_cycles_measured": self.latency, "initiation_interval_measured": self.interval,
               "seconds": self.seconds}
        if self.legs_addressed is not None:
            out["legs_addressed"] = list(self.legs_addressed)
            out["leg_mismatches"] = self.leg_mismatches
        return out


def _verification_targets(plan: Plan, interval: int) -> dict:
    n_random = int(np.clip(SIM_CYCLE_BUDGET // interval, 64, 1000))
    return {k: np.concatenate([c, r]) for (k, c), r in
            zip(corner_targets(plan).items(), random_targets(plan, n_random, 7).values())}


def simulate(core, plan: Plan, progress, vcd=None) -> Simulation:
    """Amaranth simulation of ``core``: bit-exact against the golden model, latency measured,
    targets accepted back to back every ``initiation_interval`` cycles; a robot core gets each
    target addressed to a random leg and must return it with that leg and that leg's channel
    widths (its channel table applied, :func:`ikseries.sim.golden.robot_outputs`)."""
    ii = core.initiation_interval
    targets = _verification_targets(plan, ii)
    n = len(next(iter(targets.values())))
    t0 = time.perf_counter()
    shared = isinstance(core, RobotCore)
    if shared:
        legs = np.random.default_rng(11).integers(0, core.legs, n)
        res = simulate_robot(core.simulation_model(), legs, targets, vcd=vcd)
        leg_mismatches = int(np.count_nonzero(res.legs != legs))
    else:
        res = simulate_leg(core.simulation_model(), targets, vcd=vcd)
        leg_mismatches = 0
    exp = golden.robot_outputs(plan, core.channels, legs, targets) if shared else golden.outputs(plan, targets)
    mismatches = int(sum(np.count_nonzero(res.outputs[s] != exp[s]) for s in exp))
    lat = sorted(set(int(x) for x in res.latencies))
    gaps = sorted(set(int(x) for x in np.diff(res.input_cycles)))
    progress(f"amaranth simulation: {n} targets, {mismatches} mismatches"
             + (f", {leg_mismatches} wrong legs" if shared else "")
             + f", latency {lat} cycles, inputs every {gaps} cycles")
    if mismatches or leg_mismatches or lat != [core.latency] or gaps != [ii]:
        raise StepError(f"simulation disagrees with the golden model ({mismatches} mismatches, "
                        f"{leg_mismatches} wrong legs, latency {lat} vs {core.latency}, inputs every "
                        f"{gaps} cycles vs {ii}): please report this as a bug")
    return Simulation(n, mismatches, lat[0], gaps[0] if gaps else None, _seconds_since(t0),
                      tuple(sorted(set(int(x) for x in legs))) if shared else None,
                      leg_mismatches if shared else None)


# -- synthesis ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Synthesis:
    """Yosys cell counts per synthesis target (:func:`ikseries.synth.synth_counts`)."""
    targets: dict
    seconds: float


def synthesise(verilog: Path, module: str, family: str | None, workdir: Path, progress) -> Synthesis:
    """Yosys on ``verilog`` for ``family`` (the family of the vendor primitives it instantiates),
    or for every family when it instantiates none."""
    from .constraints.devices import FAMILIES
    from .synth import synth_counts
    t0 = time.perf_counter()
    counts = synth_counts(verilog, module, (family,) if family else tuple(FAMILIES), workdir=workdir,
                          progress=progress, jobs=2)
    return Synthesis(counts, _seconds_since(t0))


# -- cocotb -------------------------------------------------------------------------------
#: random targets of the build's cocotb back-to-back test on a pipelined core (fewer for a core
#: with an initiation interval > 1, see :func:`ikseries.sim.runner.default_n_random`)
COCOTB_N_RANDOM = 1000


@dataclass(frozen=True)
class CocotbRun:
    """One simulator's cocotb run of the exported Verilog (every test passed)."""
    simulator: str
    tests: tuple[str, ...]
    latency: int
    interval: int
    random_targets: int
    build_s: float
    test_s: float

    def record(self) -> dict:
        return {"tests": list(self.tests), "passed": True, "latency_cycles_measured": self.latency,
                "initiation_interval": self.interval, "random_targets": self.random_targets,
                "build_s": self.build_s, "test_s": self.test_s}


@dataclass(frozen=True)
class Cocotb:
    """The cocotb runs, and a note naming the simulators "auto" skipped (or None)."""
    runs: tuple[CocotbRun, ...]
    note: str | None
    seconds: float

    def record(self) -> dict:
        return {r.simulator: r.record() for r in self.runs}


@contextlib.contextmanager
def _output_to(log: Path):
    """Send this process's stdout/stderr file descriptors (and so the simulators') to ``log``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(log, "ab") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


def _simulators(simulators, progress) -> tuple[list[str], str | None]:
    """The simulators to run ("auto": every installed one) and the note on those "auto"
    skipped; a simulator named explicitly that is not installed is refused."""
    from .sim.runner import SIMULATORS, simulator_available
    chosen, skipped = [], []
    for s in (SIMULATORS if simulators == "auto" else simulators):
        ok, why = simulator_available(s)
        if ok:
            chosen.append(s)
        elif simulators != "auto":
            raise StepError(f"cannot run cocotb on {s}: {why}")
        else:
            skipped.append(f"{s} ({why})")
            progress(f"cocotb on {s}: skipped ({why})")
    return chosen, (f"cocotb skipped on {', '.join(skipped)}" if skipped else None)


def cocotb(plan_file: Path, period: int, simulators, workdir: Path, logdir: Path, progress,
           core=None, *, manifest_file: Path | None = None) -> Cocotb:
    """cocotb on the exported Verilog: bit-exact streaming with and without backpressure.

    ``simulators`` is a list of names, or "auto" for every installed one. The simulator
    output goes to ``logdir/cocotb_<simulator>.log``. ``core``: the leg or robot core to
    export (None: the pipelined ``LegCore``); ``manifest_file``: the build's manifest, which
    the bench reads the design from (None: the runner writes one).
    """
    from .sim.runner import default_n_random, run
    t0 = time.perf_counter()
    chosen, note = _simulators(simulators, progress)
    n_random = default_n_random(1 if core is None else core.initiation_interval, COCOTB_N_RANDOM)
    runs = []
    for sim in chosen:
        progress(f"cocotb on {sim}: building and simulating the exported Verilog")
        log = logdir / f"cocotb_{sim}.log"
        with _output_to(log):
            res = run(plan_file, period, sim, workdir / sim, n_random=n_random,
                      testcase="test_back_to_back,test_backpressure", core=core, manifest=manifest_file)
        failed = {t: m for t, (ok_, m) in res.tests.items() if not ok_}
        if not res.ok or failed:
            raise StepError(f"cocotb on {sim} failed (log: {log}): "
                            + "; ".join(f"{t}: {m}" for t, m in failed.items()).replace("\n", " "))
        progress(f"cocotb on {sim}: {', '.join(sorted(res.tests))} passed ({n_random} random targets "
                 f"plus corners back to back, half as many with backpressure), latency {res.latency} "
                 f"cycles, a target every {res.initiation_interval} cycles")
        runs.append(CocotbRun(sim, tuple(sorted(res.tests)), res.latency, res.initiation_interval, n_random,
                              round(res.build_s, 1), round(res.test_s, 1)))
    return Cocotb(tuple(runs), note, _seconds_since(t0))
