"""Architecture choice: which evaluator (pipelined, folded, shared by all legs) a build uses.

``hardware.architecture = "auto"`` takes the smallest configuration that refreshes every
leg at least ``hardware.min_refresh_hz`` times a second at ``hardware.clock_hz``, trying in
order of size: a folded evaluator with 1 multiplier, with 2, then (one leg only) the
modulo-scheduled evaluator with initiation intervals 16, 8, 4, 2 (:class:`ModuloEvaluator`:
the dataflow pipelined, its multiplications shared) and the fully pipelined evaluator. A robot with ``legs > 1`` always gets a :class:`RobotCore` (one folded
evaluator time-multiplexed over the legs).

``hardware.architecture = "fastest"`` takes the fastest configuration whose Yosys cell counts fit
``hardware.fit_device`` (a part of :data:`ikseries.constraints.devices.PARTS`, with its
capacities): it builds every configuration of :data:`FASTEST_ORDER` (the
pipelined and modulo-scheduled evaluators for one leg; folded, shared by the legs when
``legs > 1``, with 4, 2 and 1 multipliers), sorts them by refresh rate, fastest first (fewer multipliers first at equal
rates), and synthesises each in turn for the device until one fits. A configuration slower than
``hardware.min_refresh_hz`` is rejected without synthesis. Fitting by cell counts is an estimate
before place-and-route (routing or packing can still fail on a nearly full device).

Rates come from the built component's ``initiation_interval`` property, never from a formula here.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from amaranth._unused import MustUse

from .constraints.devices import dsp_size, part as device_part
from .hdl.leg import LegCore
from .hdl.shared import RobotCore

__all__ = ["ArchitectureError", "Candidate", "Choice", "Tried", "AUTO_ORDER", "FASTEST_ORDER", "candidates",
           "choose_architecture", "synth_candidate"]

#: initiation intervals of the modulo-scheduled evaluator that "auto" and "fastest" try
MODULO_INTERVALS = (16, 8, 4, 2)
#: what "auto" tries, smallest first: (architecture, multipliers or initiation interval);
#: "modulo" and "pipelined" only for one leg
AUTO_ORDER = (("folded", 1), ("folded", 2), *(("modulo", ii) for ii in MODULO_INTERVALS), ("pipelined", None))
#: what "fastest" tries (then sorted by the built cores' rates)
FASTEST_ORDER = (("pipelined", None), *(("modulo", ii) for ii in reversed(MODULO_INTERVALS)),
                 ("folded", 4), ("folded", 2), ("folded", 1))

#: synthesis for "fastest": (candidate, its core, synthesis target) -> Yosys counts by category
SynthFunction = Callable[["Candidate", object, str], dict]


class ArchitectureError(ValueError):
    """No configuration allowed by the robot description meets its refresh rate."""


@dataclass(frozen=True)
class Candidate:
    """One configuration: ``architecture`` is "pipelined", "modulo", "folded" (one leg) or
    "shared"; ``interval`` the initiation interval of a "modulo" one."""
    architecture: str
    multipliers: int | None
    dsp: str | None
    legs: int
    interval: int | None = None

    def describe(self) -> str:
        if self.architecture == "pipelined":
            return "pipelined (one target per cycle)"
        d = "full-width" if self.dsp == "none" else "{} {}x{} DSP".format(self.dsp, *dsp_size(self.dsp))
        if self.architecture == "modulo":
            return f"modulo-scheduled pipeline, one target per {self.interval} cycles ({d})"
        k = f"{self.multipliers} multiplier{'s' if self.multipliers != 1 else ''}"
        what = f"folded evaluator shared by {self.legs} legs" if self.architecture == "shared" else "folded"
        return f"{what}, {k} ({d})"

    def build(self, robot, plan):
        """The core of this configuration for ``robot`` and its fitted ``plan``."""
        dsp = None if self.dsp in (None, "none") else dsp_size(self.dsp)
        if self.architecture == "shared":
            return RobotCore(plan, self.legs, robot.pwm_period_ticks, robot.clock_hz,
                             multipliers=self.multipliers, dsp=dsp)
        if self.architecture == "folded":
            return LegCore(plan, robot.pwm_period_ticks, multipliers=self.multipliers, dsp=dsp)
        if self.architecture == "modulo":
            prim = "ecp5" if getattr(robot, "dsp_primitives", False) and self.dsp == "ecp5" else None
            return LegCore(plan, robot.pwm_period_ticks, interval=self.interval, dsp=dsp, dsp_registers=prim)
        return LegCore(plan, robot.pwm_period_ticks)


@dataclass(frozen=True)
class Tried:
    """One candidate tried: its rate and, for "fastest", its Yosys counts and why it was rejected."""
    candidate: Candidate
    initiation_interval: int
    refresh_hz: float
    counts: dict | None = None    # Yosys counts by category on the fit device (None: not synthesised)
    rejected: str | None = None   # why it was not taken (None: taken, or met the rate)

    def record(self) -> dict:
        t = self.candidate
        return {"architecture": t.architecture, "multipliers": t.multipliers, "description": t.describe(),
                "initiation_interval": self.initiation_interval, "refresh_hz": self.refresh_hz,
                "counts": self.counts, "rejected": self.rejected}


@dataclass(frozen=True)
class Choice:
    """The chosen configuration, its core, and every candidate tried with its rate."""
    candidate: Candidate
    core: object               # LegCore or RobotCore
    refresh_hz: float
    reason: str
    tried: tuple               # (Tried, ...) in the order tried, the chosen one last
    fit_device: str | None = None   # "fastest": the device (hardware.fit_device) it fits

    def record(self) -> dict:
        """JSON-ready description for the manifest and the report."""
        c = self.candidate
        rec = {"architecture": c.architecture, "multipliers": _multipliers(c, self.core), "dsp": c.dsp,
               "legs": c.legs, "initiation_interval_asked": c.interval,
               "description": c.describe(), "reason": self.reason,
               "latency_cycles": self.core.latency, "initiation_interval": self.core.initiation_interval,
               "refresh_hz": self.refresh_hz, "tried": [t.record() for t in self.tried]}
        if self.fit_device is not None:
            dev = device_part(self.fit_device)
            rec["fit_device"] = {"name": self.fit_device, "part": dev.part, "capacity": dev.capacities}
        return rec


def candidates(robot) -> list[Candidate]:
    """The configurations the robot description allows, in the order they are tried."""
    if robot.architecture == "auto":
        order = AUTO_ORDER
    elif robot.architecture == "fastest":
        order = FASTEST_ORDER
    elif robot.architecture == "folded":
        order = (("folded", robot.multipliers),)
    elif robot.architecture == "modulo":
        order = (("modulo", robot.interval),)
    else:
        order = (("pipelined", None),)
    out = []
    for arch, k in order:
        if robot.legs > 1:
            if arch in ("pipelined", "modulo"):
                continue
            arch = "shared"
        if arch == "modulo":
            out.append(Candidate(arch, None, robot.dsp, robot.legs, interval=k))
        else:
            out.append(Candidate(arch, k, None if arch == "pipelined" else robot.dsp, robot.legs))
    return out


def _size_rank(cand: Candidate) -> tuple:
    """Orders configurations by size: folded (fewest multipliers first), modulo-scheduled
    (longest interval first), pipelined."""
    if cand.architecture == "modulo":
        return (1, -cand.interval)
    return (2, 0) if cand.architecture == "pipelined" else (0, cand.multipliers)


def _multipliers(cand: Candidate, core) -> int | None:
    """The multipliers of a configuration (a modulo-scheduled core sizes its own)."""
    if cand.architecture == "modulo":
        return core.evaluator.multipliers
    return cand.multipliers


def _discard(obj, seen=None) -> None:
    """Mark a core built only for its rate, and the elaboratables it holds, as used: Amaranth
    warns (UnusedElaboratable) about every one when it is garbage-collected unelaborated."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, (list, tuple)) or isinstance(obj, dict):
        for v in (obj.values() if isinstance(obj, dict) else obj):
            _discard(v, seen)
    elif isinstance(obj, MustUse):
        obj._MustUse__used = True
        for v in vars(obj).values():
            _discard(v, seen)


def _refresh_hz(core, robot) -> float:
    """Times per second every leg can get new widths (targets offered round-robin)."""
    if isinstance(core, RobotCore):
        return core.refresh_hz
    return robot.clock_hz / core.initiation_interval


def choose_architecture(robot, plan, *, synth: SynthFunction | None = None,
                        progress: Callable[[str], None] | None = None) -> Choice:
    """The first configuration of :func:`candidates` that meets ``robot.min_refresh_hz``
    (for "fastest": the fastest of them whose Yosys counts fit ``robot.fit_device``).

    ``synth`` (``"fastest"`` only; default :func:`synth_candidate`) returns the Yosys counts
    of a candidate's core for a synthesis target; ``progress`` receives one-line messages.
    Raises :class:`ArchitectureError` (one line, naming the best rate reached, or for
    "fastest" the smallest configuration synthesised and what overflowed) if none does.
    """
    if robot.architecture == "fastest":
        return _choose_fastest(robot, plan, synth or synth_candidate, progress or (lambda msg: None))
    tried = []
    for cand in candidates(robot):
        core = cand.build(robot, plan)
        hz = _refresh_hz(core, robot)
        tried.append(Tried(cand, core.initiation_interval, hz))
        if hz < robot.min_refresh_hz:
            _discard(core)
            continue
        if robot.architecture == "auto":
            smaller = "; smaller ones: " + ", ".join(f"{t.candidate.describe()} {t.refresh_hz:,.0f} Hz"
                                                     for t in tried[:-1]) if len(tried) > 1 else ""
            reason = (f"auto: the smallest configuration that refreshes every leg at least "
                      f"{robot.min_refresh_hz:g} times a second at {robot.clock_hz / 1e6:g} MHz "
                      f"({hz:,.0f} Hz, initiation interval {core.initiation_interval} cycles){smaller}")
        else:
            reason = (f"hardware.architecture = {robot.architecture}: {hz:,.0f} Hz >= "
                      f"min_refresh_hz {robot.min_refresh_hz:g} Hz")
        return Choice(cand, core, hz, reason, tuple(tried))
    _rate_error(robot, max(tried, key=lambda t: t.refresh_hz))


def _rate_error(robot, best: Tried):
    what = ("the rate of hardware.architecture" if robot.architecture in ("pipelined", "folded", "modulo")
            else "the best rate of any architecture")
    raise ArchitectureError(
        f"hardware.min_refresh_hz must be at most {best.refresh_hz:.6g} Hz, {what} for {robot.name} at "
        f"{robot.clock_hz / 1e6:g} MHz with {robot.legs} leg{'s' if robot.legs != 1 else ''} "
        f"({best.candidate.describe()}, initiation interval {best.initiation_interval} cycles), "
        f"not {robot.min_refresh_hz:g}")


def synth_candidate(cand: Candidate, core, target: str) -> dict:
    """Yosys counts by category (:func:`ikseries.synth.synth_counts`) of ``core`` for ``target``."""
    from .hdl.export import leg_verilog, robot_verilog
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
    dev = device_part(robot.fit_device)
    target, part, cap = dev.family, dev.part, dev.capacities
    built = []
    for cand in candidates(robot):
        core = cand.build(robot, plan)
        built.append((cand, core, _refresh_hz(core, robot)))
    # fastest first; at equal rates the one with fewer multipliers (the pipelined one has none)
    built.sort(key=lambda b: (-b[2], b[0].multipliers or 0))
    tried = []
    for cand, core, hz in built:
        if hz < robot.min_refresh_hz:
            _discard(core)
            tried.append(Tried(cand, core.initiation_interval, hz,
                               rejected=f"{hz:,.0f} Hz < hardware.min_refresh_hz {robot.min_refresh_hz:g} "
                                        f"(not synthesised)"))
            continue
        progress(f"fastest on {part}: synthesising {cand.describe()} ({hz:,.0f} Hz)")
        counts = synth(cand, core, target)
        over = dev.overflows(counts)
        if over:
            tried.append(Tried(cand, core.initiation_interval, hz, counts,
                               f"does not fit {part} by Yosys cell counts (before place-and-route): "
                               + ", ".join(f"{k} {u:,} > {a:,}" for k, (u, a) in over.items())))
            progress(f"fastest on {part}: {cand.describe()} rejected: {tried[-1].rejected}")
            continue
        tried.append(Tried(cand, core.initiation_interval, hz, counts))
        faster = "; faster ones rejected: " + "; ".join(f"{t.candidate.describe()}: {t.rejected}"
                                                       for t in tried[:-1]) if len(tried) > 1 else ""
        rest = built[len(tried):]
        slower = "; slower ones, not tried: " + ", ".join(f"{c.describe()} {h:,.0f} Hz" for c, _, h in rest) \
            if rest else ""
        for _, other, _ in rest:
            _discard(other)
        reason = (f"fastest: the fastest configuration whose Yosys cell counts fit {part} "
                  f"(hardware.fit_device = {robot.fit_device}; {_usage(counts, cap)}; an estimate before "
                  f"place-and-route, which can still fail on a nearly full device), refreshing every leg "
                  f"{hz:,.0f} times a second at {robot.clock_hz / 1e6:g} MHz (initiation interval "
                  f"{core.initiation_interval} cycles){faster}{slower}")
        return Choice(cand, core, hz, reason, tuple(tried), robot.fit_device)
    synthesised = [t for t in tried if t.counts is not None]
    if not synthesised:       # even the fastest is below the rate
        _rate_error(robot, tried[0])
    smallest = min(synthesised, key=lambda t: _size_rank(t.candidate))
    over = dev.overflows(smallest.counts)
    slower = [t for t in tried if t.counts is None]
    raise ArchitectureError(
        f"hardware.fit_device = {robot.fit_device}: no configuration fits {part} by Yosys cell counts "
        f"(before place-and-route); the smallest synthesised, {smallest.candidate.describe()} "
        f"({smallest.refresh_hz:,.0f} Hz), needs "
        + ", ".join(f"{k} {u:,} > {a:,}" for k, (u, a) in over.items())
        + (f"; slower ones are below hardware.min_refresh_hz {robot.min_refresh_hz:g}" if slower else ""))
