"""Architecture choice: which evaluator (pipelined, folded, shared by all legs) a build uses.

``hardware.architecture = "auto"`` takes the smallest configuration that refreshes every
leg at least ``hardware.min_refresh_hz`` times a second at ``hardware.clock_hz``, trying in
order of size: a folded evaluator with 1 multiplier, with 2, then (one leg only) the
modulo-scheduled evaluator with initiation intervals 16, 8, 4, 2 (the dataflow pipelined, its
multiplications shared) and the fully pipelined evaluator. A robot with ``legs > 1`` always gets
the shared architecture (one folded evaluator time-multiplexed over the legs).

``hardware.architecture = "fastest"`` takes the fastest configuration whose Yosys cell counts fit
``hardware.fit_device`` (a part of :data:`ikseries.constraints.devices.PARTS`, with its
capacities): it rates every configuration of :data:`FASTEST_ORDER` (the
pipelined and modulo-scheduled evaluators for one leg; folded, shared by the legs when
``legs > 1``, with 4, 2 and 1 multipliers), sorts them by refresh rate, fastest first (fewer
multipliers first at equal rates), and builds and synthesises each in turn for the device until
one fits. A configuration slower than
``hardware.min_refresh_hz`` is rejected without synthesis. Fitting by cell counts is an estimate
before place-and-route (routing or packing can still fail on a nearly full device).

Configurations are :class:`ikseries.hdl.architectures.Architecture` objects; rates come from their
``timing`` (pure schedule data, nothing elaborated), never from a formula here.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .constraints.devices import part as device_part
from .fit.cost import DEFAULT_COST_MODEL, CostModel
from .hdl.architectures import Architecture, BuildTarget
from .hdl.architectures.folded import Folded
from .hdl.architectures.modulo import Modulo
from .hdl.architectures.options import primitive_families
from .hdl.architectures.pipelined import Pipelined
from .hdl.architectures.shared import Shared
from .channels import channel_table
from .robot_parts import HardwareOptions

__all__ = ["ArchitectureError", "Choice", "Tried", "AUTO_ORDER", "FASTEST_ORDER", "candidates",
           "choose_architecture", "cost_model", "recorded_cost_model", "synth_candidate", "build_target"]

#: initiation intervals of the modulo-scheduled evaluator that "auto" and "fastest" try
MODULO_INTERVALS = (16, 8, 4, 2)
#: what "auto" tries, smallest first: (architecture, multipliers or initiation interval);
#: "modulo" and "pipelined" only for one leg
AUTO_ORDER = (("folded", 1), ("folded", 2), *(("modulo", ii) for ii in MODULO_INTERVALS), ("pipelined", None))
#: what "fastest" tries (then sorted by their rates)
FASTEST_ORDER = (("pipelined", None), *(("modulo", ii) for ii in reversed(MODULO_INTERVALS)),
                 ("folded", 4), ("folded", 2), ("folded", 1))

#: synthesis for "fastest": (architecture, its core, synthesis target) -> Yosys counts by category
SynthFunction = Callable[[Architecture, object, str], dict]


class ArchitectureError(ValueError):
    """No configuration allowed by the robot description meets its refresh rate."""


@dataclass(frozen=True)
class Tried:
    """One configuration tried: its rate and, for "fastest", its Yosys counts and why it was rejected."""
    candidate: Architecture
    initiation_interval: int
    refresh_hz: float
    counts: dict | None = None    # Yosys counts by category on the fit device (None: not synthesised)
    rejected: str | None = None   # why it was not taken (None: taken, or met the rate)

    def record(self) -> dict:
        t = self.candidate
        return {"architecture": t.name, "multipliers": t.multipliers, "description": t.describe(),
                "initiation_interval": self.initiation_interval, "refresh_hz": self.refresh_hz,
                "counts": self.counts, "rejected": self.rejected}


@dataclass(frozen=True)
class Choice:
    """The chosen configuration, its core, and every configuration tried with its rate."""
    candidate: Architecture
    core: object               # LegCore or RobotCore
    refresh_hz: float
    reason: str
    tried: tuple               # (Tried, ...) in the order tried, the chosen one last
    fit_device: str | None = None   # "fastest": the device (hardware.fit_device) it fits
    multipliers: int | None = None  # multiplier units of the chosen configuration

    def record(self) -> dict:
        """JSON-ready description for the manifest and the report."""
        c = self.candidate
        rec = {"architecture": c.name, "multipliers": self.multipliers, "dsp": c.dsp,
               "legs": c.legs, "initiation_interval_asked": c.interval if c.name == "modulo" else None,
               "description": c.describe(), "reason": self.reason,
               "latency_cycles": self.core.latency, "initiation_interval": self.core.initiation_interval,
               "refresh_hz": self.refresh_hz, "tried": [t.record() for t in self.tried]}
        if self.fit_device is not None:
            dev = device_part(self.fit_device)
            rec["fit_device"] = {"name": self.fit_device, "part": dev.part, "capacity": dev.capacities}
        return rec


def build_target(robot) -> BuildTarget:
    """What the robot's core drives: its PWM period at its clock."""
    return BuildTarget(robot.hardware.pwm_period_ticks, robot.hardware.clock_hz)


def _configuration(arch: str, k, hardware, legs: int, table: Callable[[], object]) -> Architecture:
    """Configuration ``(arch, k)`` of :data:`AUTO_ORDER` / :data:`FASTEST_ORDER` for the hardware
    options ``hardware`` of a robot of ``legs`` legs (``table()``: its channel table, read by
    the shared core only)."""
    prim = hardware.dsp_primitives and hardware.dsp in primitive_families()
    if legs > 1:
        return Shared(legs, k, hardware.dsp, table(), primitives=prim)
    if arch == "modulo":
        return Modulo(k, hardware.dsp, primitives=prim, cost=hardware.cost)
    if arch == "folded":
        return Folded(k, hardware.dsp, primitives=prim)
    # the DSP family is the pipelined core's only to price its products on (hardware.cost)
    return Pipelined(hardware.dsp if hardware.cost != DEFAULT_COST_MODEL.name else None, cost=hardware.cost)


def _candidates(hardware, legs: int, table: Callable[[], object]) -> list[Architecture]:
    if hardware.architecture == "auto":
        order = AUTO_ORDER
    elif hardware.architecture == "fastest":
        order = FASTEST_ORDER
    elif hardware.architecture == "folded":
        order = (("folded", hardware.multipliers),)
    elif hardware.architecture == "modulo":
        order = (("modulo", hardware.interval),)
    else:
        order = (("pipelined", None),)
    if legs > 1:       # the legs share one folded evaluator
        order = [o for o in order if o[0] == "folded"]
    if hardware.dsp_primitives:     # the pipelined core instantiates none (HardwareOptions refuses it)
        order = [o for o in order if o[0] != "pipelined"]
    return [_configuration(arch, k, hardware, legs, table) for arch, k in order]


def candidates(robot) -> list[Architecture]:
    """The configurations the robot description allows, in the order they are tried."""
    return _candidates(robot.hardware, robot.legs, lambda: channel_table(robot))


def cost_model(robot) -> CostModel:
    """The cost model (:mod:`ikseries.fit.cost`) the fit of ``robot`` minimises: the one its
    candidate architectures (:func:`candidates`) offer. The plan is fitted before "auto" or
    "fastest" picks among them, so they must agree."""
    return _agreed_model(candidates(robot), robot.hardware.architecture)


def _agreed_model(cands: list[Architecture], architecture: str) -> CostModel:
    models = {c.cost_model() for c in cands}
    if len(models) != 1:
        raise ArchitectureError(f"hardware.architecture = {architecture!r} tries architectures "
                                f"that price a plan differently ({', '.join(sorted({m.name for m in models}))}); "
                                "name one architecture")
    return models.pop()


def recorded_cost_model(hardware: dict, legs: int) -> CostModel:
    """The cost model of a robot record's hardware table ``hardware`` (``HardwareOptions.record``)
    for ``legs`` legs, without the rest of the robot: the fit key's (:func:`ikseries.robot.fit_record`).
    Only one leg's modulo-scheduled or pipelined core offers a model other than the default
    (``hardware.cost``), so no channel table is read; with more legs, the default."""
    if legs > 1:
        return DEFAULT_COST_MODEL
    options = HardwareOptions(**hardware)
    return _agreed_model(_candidates(options, legs, lambda: None), options.architecture)


def _size_rank(cand: Architecture) -> tuple:
    """Orders configurations by size: folded (fewest multipliers first), modulo-scheduled
    (longest interval first), pipelined."""
    if cand.name == "modulo":
        return (1, -cand.interval)
    return (2, 0) if cand.name == "pipelined" else (0, cand.multipliers)


def _chosen(robot, plan, cand: Architecture, hz: float, reason: str, tried, fit_device=None, core=None) -> Choice:
    core = core if core is not None else cand.build(plan, build_target(robot))
    return Choice(cand, core, hz, reason, tuple(tried), fit_device, cand.multiplier_units(plan)
                  if cand.name in ("modulo", "folded", "shared") else None)


def choose_architecture(robot, plan, *, synth: SynthFunction | None = None,
                        progress: Callable[[str], None] | None = None) -> Choice:
    """The first configuration of :func:`candidates` that meets ``robot.hardware.min_refresh_hz``
    (for "fastest": the fastest of them whose Yosys counts fit ``robot.hardware.fit_device``).

    Rates come from each architecture's :meth:`~ikseries.hdl.architectures.Architecture.timing`
    (pure schedule data); only the chosen core (and, for "fastest", each one synthesised) is
    built. ``synth`` ("fastest" only; default :func:`synth_candidate`) returns the Yosys counts
    of a configuration's core for a synthesis target; ``progress`` receives one-line messages.
    Raises :class:`ArchitectureError` (one line, naming the best rate reached, or for
    "fastest" the smallest configuration synthesised and what overflowed) if none does.
    """
    if robot.hardware.architecture == "fastest":
        return _choose_fastest(robot, plan, synth or synth_candidate, progress or (lambda msg: None))
    tried = []
    for cand in candidates(robot):
        t = cand.timing(plan)
        hz = t.refresh_hz(robot.hardware.clock_hz)
        tried.append(Tried(cand, t.initiation_interval, hz))
        if hz < robot.hardware.min_refresh_hz:
            continue
        if robot.hardware.architecture == "auto":
            smaller = "; smaller ones: " + ", ".join(f"{t.candidate.describe()} {t.refresh_hz:,.0f} Hz"
                                                     for t in tried[:-1]) if len(tried) > 1 else ""
            reason = (f"auto: the smallest configuration that refreshes every leg at least "
                      f"{robot.hardware.min_refresh_hz:g} times a second at {robot.hardware.clock_hz / 1e6:g} MHz "
                      f"({hz:,.0f} Hz, initiation interval {t.initiation_interval} cycles){smaller}")
        else:
            reason = (f"hardware.architecture = {robot.hardware.architecture}: {hz:,.0f} Hz >= "
                      f"min_refresh_hz {robot.hardware.min_refresh_hz:g} Hz")
        return _chosen(robot, plan, cand, hz, reason, tried)
    _rate_error(robot, max(tried, key=lambda t: t.refresh_hz))


def _rate_error(robot, best: Tried):
    what = ("the rate of hardware.architecture" if robot.hardware.architecture in ("pipelined", "folded", "modulo")
            else "the best rate of any architecture")
    raise ArchitectureError(
        f"hardware.min_refresh_hz must be at most {best.refresh_hz:.6g} Hz, {what} for {robot.name} at "
        f"{robot.hardware.clock_hz / 1e6:g} MHz with {robot.legs} leg{'s' if robot.legs != 1 else ''} "
        f"({best.candidate.describe()}, initiation interval {best.initiation_interval} cycles), "
        f"not {robot.hardware.min_refresh_hz:g}")


def synth_candidate(cand: Architecture, core, target: str) -> dict:
    """Yosys counts by category (:func:`ikseries.synth.synth_counts`) of ``core`` for ``target``."""
    from .hdl.export import leg_verilog, robot_verilog
    from .hdl.shared import RobotCore
    from .synth import synth_counts
    name = "ikseries_fit"
    text = robot_verilog(core, name) if isinstance(core, RobotCore) else leg_verilog(core, name)
    with tempfile.TemporaryDirectory(prefix="ikseries-fit-") as tmp:
        path = Path(tmp) / f"{name}.v"
        path.write_text(text)
        return synth_counts(path, name, targets=[target])[target]["counts"]


def _usage(counts: dict, cap: dict) -> str:
    return ", ".join(f"{k} {counts.get(k, 0):,}/{v:,}" for k, v in cap.items())


def _choose_fastest(robot, plan, synth: SynthFunction, progress) -> Choice:
    dev = device_part(robot.hardware.fit_device)
    target, part, cap = dev.family, dev.part, dev.capacities
    rated = []
    for cand in candidates(robot):
        t = cand.timing(plan)
        rated.append((cand, t.initiation_interval, t.refresh_hz(robot.hardware.clock_hz)))
    # fastest first; at equal rates the one with fewer multipliers (the pipelined one has none)
    rated.sort(key=lambda r: (-r[2], r[0].multipliers or 0))
    tried = []
    for cand, ii, hz in rated:
        if hz < robot.hardware.min_refresh_hz:
            tried.append(Tried(cand, ii, hz, rejected=f"{hz:,.0f} Hz < hardware.min_refresh_hz "
                                                      f"{robot.hardware.min_refresh_hz:g} (not synthesised)"))
            continue
        progress(f"fastest on {part}: synthesising {cand.describe()} ({hz:,.0f} Hz)")
        core = cand.build(plan, build_target(robot))
        counts = synth(cand, core, target)
        over = dev.overflows(counts)
        if over:
            tried.append(Tried(cand, ii, hz, counts,
                               f"does not fit {part} by Yosys cell counts (before place-and-route): "
                               + ", ".join(f"{k} {u:,} > {a:,}" for k, (u, a) in over.items())))
            progress(f"fastest on {part}: {cand.describe()} rejected: {tried[-1].rejected}")
            continue
        tried.append(Tried(cand, ii, hz, counts))
        return _chosen(robot, plan, cand, hz, _fastest_reason(robot, part, cap, counts, ii, hz, tried,
                                                              rated[len(tried):]),
                       tried, robot.hardware.fit_device, core)
    _fastest_error(robot, dev, tried)


def _fastest_reason(robot, part, cap, counts, ii, hz, tried, rest) -> str:
    faster = "; faster ones rejected: " + "; ".join(f"{t.candidate.describe()}: {t.rejected}"
                                                   for t in tried[:-1]) if len(tried) > 1 else ""
    slower = "; slower ones, not tried: " + ", ".join(f"{c.describe()} {h:,.0f} Hz" for c, _, h in rest) \
        if rest else ""
    return (f"fastest: the fastest configuration whose Yosys cell counts fit {part} "
            f"(hardware.fit_device = {robot.hardware.fit_device}; {_usage(counts, cap)}; an estimate before "
            f"place-and-route, which can still fail on a nearly full device), refreshing every leg "
            f"{hz:,.0f} times a second at {robot.hardware.clock_hz / 1e6:g} MHz (initiation interval "
            f"{ii} cycles){faster}{slower}")


def _fastest_error(robot, dev, tried):
    synthesised = [t for t in tried if t.counts is not None]
    if not synthesised:       # even the fastest is below the rate
        _rate_error(robot, tried[0])
    smallest = min(synthesised, key=lambda t: _size_rank(t.candidate))
    over = dev.overflows(smallest.counts)
    slower = [t for t in tried if t.counts is None]
    raise ArchitectureError(
        f"hardware.fit_device = {robot.hardware.fit_device}: no configuration fits {dev.part} by Yosys cell counts "
        f"(before place-and-route); the smallest synthesised, {smallest.candidate.describe()} "
        f"({smallest.refresh_hz:,.0f} Hz), needs "
        + ", ".join(f"{k} {u:,} > {a:,}" for k, (u, a) in over.items())
        + (f"; slower ones are below hardware.min_refresh_hz {robot.hardware.min_refresh_hz:g}" if slower else ""))
