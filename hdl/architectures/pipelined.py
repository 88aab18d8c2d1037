"""Fully pipelined evaluator: one register stage per registered plan operation."""
from __future__ import annotations

from ..evaluator import PlanEvaluator
from ..leg import LegCore
from ...fit.cost import COSTS
from . import Architecture, BuildTarget, Timing
from .options import check_cost, dsp_size, offered_cost_model

__all__ = ["Pipelined"]


class Pipelined(Architecture):
    """Every operation on its own hardware (:class:`~ikseries.hdl.evaluator.PlanEvaluator`):
    one target per cycle, latency = the plan's pipeline depth.

    Parameters
    ----------
    dsp : str or None
        The DSP family its products are priced on with ``cost`` "device" (the core's products
        are the fabric's: synthesis maps them to the DSP blocks of the target); None: not named.
    cost : str
        What the fitter minimises for it (:data:`ikseries.fit.cost.COSTS`):
        "multipliers", or "device" (needs ``dsp``): the share of the family's reference part the
        plan takes (:class:`~ikseries.fit.cost.DeviceCost`, every product on its own DSP blocks).
    """

    name = "pipelined"

    def __init__(self, dsp: str | None = None, cost: str = COSTS[0]):
        dsp_size(dsp)
        self.dsp, self.cost = dsp, check_cost(cost, dsp)

    def cost_model(self):
        return offered_cost_model(self.cost, self.dsp, 1)

    def record(self) -> dict:
        # cost only where it is not the default: records of cores before it stay the same
        return {**super().record(), **({"cost": self.cost} if self.cost != COSTS[0] else {})}

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
