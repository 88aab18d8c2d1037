"""The CORDIC leg solver baselines (cylinder-leg robots): pipelined and iterative.

Their "plan" is a :class:`~ikseries.fit.baselines.cordic.CordicPlan` (robot and design), not an
evaluation plan; they have no PWM stage: :meth:`build` gives the solver itself.
"""
from __future__ import annotations

from ..cordic import CordicLegSolver
from . import Architecture, BuildTarget, Timing
from .options import positive_int

__all__ = ["CordicPipelined", "CordicIterative"]


class CordicPipelined(Architecture):
    """Every CORDIC iteration and square-root step on its own register stage: one target per
    cycle."""

    name = "cordic"
    interval = 1

    def timing(self, plan) -> Timing:
        return Timing(plan.latency, self.interval, "pipelined" if self.interval == 1 else "modulo")

    def evaluator(self, plan):
        return CordicLegSolver(plan.robot, plan.design, self.interval)

    def build(self, plan, target: BuildTarget):
        return self.evaluator(plan)

    def multiplier_units(self, plan) -> None:
        return None

    def describe(self) -> str:
        return "CORDIC, pipelined (one target per cycle)"


class CordicIterative(CordicPipelined):
    """Each CORDIC and the square root on one set of registers, an iteration per cycle: the
    same values at the same latency, one target every ``interval`` cycles (at least the
    design's longest loop)."""

    name = "cordic-iterative"

    def __init__(self, interval: int):
        self.interval = positive_int(interval, "interval")

    def timing(self, plan) -> Timing:
        if self.interval < plan.longest_loop:
            raise ValueError(f"interval must be an integer >= {plan.longest_loop} (the longest loop of this "
                             f"design), not {self.interval!r}")
        return super().timing(plan)

    def describe(self) -> str:
        return f"CORDIC, iterative (one target per {self.interval} cycles)"
