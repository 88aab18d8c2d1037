"""Architecture choice: which evaluator (pipelined, folded, shared by all legs) a build uses.

``hardware.architecture = "auto"`` takes the smallest configuration that refreshes every
leg at least ``hardware.min_refresh_hz`` times a second at ``hardware.clock_hz``, trying in
order of size: a folded evaluator with 1 multiplier, with 2, then (one leg only) the fully
pipelined evaluator. A robot with ``legs > 1`` always gets a :class:`RobotCore` (one folded
evaluator time-multiplexed over the legs). Rates come from the built component's
``initiation_interval`` property, never from a formula here.
"""
from __future__ import annotations

from dataclasses import dataclass

from .hdl.leg import LegCore
from .hdl.schedule import DSP_SIZES
from .hdl.shared import RobotCore

__all__ = ["ArchitectureError", "Candidate", "Choice", "AUTO_ORDER", "candidates", "choose_architecture"]

#: what "auto" tries, smallest first: (architecture, multipliers); "pipelined" only for one leg
AUTO_ORDER = (("folded", 1), ("folded", 2), ("pipelined", None))


class ArchitectureError(ValueError):
    """No configuration allowed by the robot description meets its refresh rate."""


@dataclass(frozen=True)
class Candidate:
    """One configuration: ``architecture`` is "pipelined", "folded" (one leg) or "shared"."""
    architecture: str
    multipliers: int | None
    dsp: str | None
    legs: int

    def describe(self) -> str:
        if self.architecture == "pipelined":
            return "pipelined (one target per cycle)"
        k = f"{self.multipliers} multiplier{'s' if self.multipliers != 1 else ''}"
        d = "full-width" if self.dsp == "none" else "{} {}x{} DSP".format(self.dsp, *DSP_SIZES[self.dsp])
        what = f"folded evaluator shared by {self.legs} legs" if self.architecture == "shared" else "folded"
        return f"{what}, {k} ({d})"

    def build(self, robot, plan):
        """The core of this configuration for ``robot`` and its fitted ``plan``."""
        dsp = None if self.dsp in (None, "none") else DSP_SIZES[self.dsp]
        if self.architecture == "shared":
            return RobotCore(plan, self.legs, robot.pwm_period_ticks, robot.clock_hz,
                             multipliers=self.multipliers, dsp=dsp)
        if self.architecture == "folded":
            return LegCore(plan, robot.pwm_period_ticks, multipliers=self.multipliers, dsp=dsp)
        return LegCore(plan, robot.pwm_period_ticks)


@dataclass(frozen=True)
class Choice:
    """The chosen configuration, its core, and every candidate tried with its rate."""
    candidate: Candidate
    core: object               # LegCore or RobotCore
    refresh_hz: float
    reason: str
    tried: tuple               # ((Candidate, initiation_interval, refresh_hz), ...)

    def record(self) -> dict:
        """JSON-ready description for the manifest and the report."""
        c = self.candidate
        return {"architecture": c.architecture, "multipliers": c.multipliers, "dsp": c.dsp, "legs": c.legs,
                "description": c.describe(), "reason": self.reason,
                "latency_cycles": self.core.latency, "initiation_interval": self.core.initiation_interval,
                "refresh_hz": self.refresh_hz,
                "tried": [{"architecture": t.architecture, "multipliers": t.multipliers,
                           "description": t.describe(), "initiation_interval": ii, "refresh_hz": hz}
                          for t, ii, hz in self.tried]}


def candidates(robot) -> list[Candidate]:
    """The configurations the robot description allows, in the order they are tried."""
    if robot.architecture == "auto":
        order = AUTO_ORDER
    elif robot.architecture == "folded":
        order = (("folded", robot.multipliers),)
    else:
        order = (("pipelined", None),)
    out = []
    for arch, k in order:
        if robot.legs > 1:
            if arch == "pipelined":
                continue
            arch = "shared"
        out.append(Candidate(arch, k, None if arch == "pipelined" else robot.dsp, robot.legs))
    return out


def _refresh_hz(core, robot) -> float:
    """Times per second every leg can get new widths (targets offered round-robin)."""
    if isinstance(core, RobotCore):
        return core.refresh_hz
    return robot.clock_hz / core.initiation_interval


def choose_architecture(robot, plan) -> Choice:
    """The first configuration of :func:`candidates` that meets ``robot.min_refresh_hz``.

    Raises :class:`ArchitectureError` (one line, naming the best rate reached) if none does.
    """
    tried = []
    for cand in candidates(robot):
        core = cand.build(robot, plan)
        hz = _refresh_hz(core, robot)
        tried.append((cand, core.initiation_interval, hz))
        if hz >= robot.min_refresh_hz:
            if robot.architecture == "auto":
                smaller = "; smaller ones: " + ", ".join(f"{t.describe()} {h:,.0f} Hz" for t, _, h in tried[:-1]) \
                    if len(tried) > 1 else ""
                reason = (f"auto: the smallest configuration that refreshes every leg at least "
                          f"{robot.min_refresh_hz:g} times a second at {robot.clock_hz / 1e6:g} MHz "
                          f"({hz:,.0f} Hz, initiation interval {core.initiation_interval} cycles){smaller}")
            else:
                reason = (f"hardware.architecture = {robot.architecture}: {hz:,.0f} Hz >= "
                          f"min_refresh_hz {robot.min_refresh_hz:g} Hz")
            return Choice(cand, core, hz, reason, tuple(tried))
    best, ii, hz = max(tried, key=lambda t: t[2])
    what = "the best rate of any architecture" if robot.architecture == "auto" else "the rate of hardware.architecture"
    raise ArchitectureError(
        f"hardware.min_refresh_hz must be at most {hz:.6g} Hz, {what} for {robot.name} at "
        f"{robot.clock_hz / 1e6:g} MHz with {robot.legs} leg{'s' if robot.legs != 1 else ''} "
        f"({best.describe()}, initiation interval {ii} cycles), not {robot.min_refresh_hz:g}")
