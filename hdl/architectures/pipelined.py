"""Fully pipelined evaluator: one register stage per registered plan operation."""
from __future__ import annotations

from ..evaluator import PlanEvaluator
from ..leg import LegCore
from . import Architecture, BuildTarget, Timing

__all__ = ["Pipelined"]


class Pipelined(Architecture):
    """Every operation on its own hardware (:class:`~ikseries.hdl.evaluator.PlanEvaluator`):
    one target per cycle, latency = the plan's pipeline depth."""

    name = "pipelined"

    def timing(self, plan) -> Timing:
        return Timing(plan.depth, 1, "pipelined")

    def evaluator(self, plan):
        return PlanEvaluator(plan)

    def build(self, plan, target: BuildTarget):
        return LegCore(plan, target.period)

    def multiplier_units(self, plan) -> int:
        return plan.count("mul")

    def describe(self) -> str:
        return "pipelined (one target per cycle)"
