"""What a servo's evaluation costs the hardware that will run it: the model the fitter minimises.

The fitter tries candidate structures (variables, degrees, terms) per servo and keeps the
cheapest that meets the approximation budget. "Cheapest" is asked of a :class:`CostModel`, which
an architecture offers (:meth:`ikseries.hdl.architectures.Architecture.cost_model`): it is the
architecture that knows what a product, an addition or a table read costs it. The model prices
a trial plan holding the one servo (its coordinate stage included), built from the structure
alone before any coefficient is fitted.

A cost model that changes which structure is chosen changes the fitted plan, so it is part of
the fit. Every registered architecture offers :class:`MultiplierCount`, and the fit's cache key
(``ikseries.robot.Robot.fit_record``) does not name the model; an architecture offering another
one must add :meth:`CostModel.record` to that key (``tests/test_architectures.py`` fails until
it is considered).
"""
from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import ClassVar

__all__ = ["CostModel", "MultiplierCount", "DEFAULT_COST_MODEL"]


class CostModel(abc.ABC):
    """The price of evaluating one output of a plan on some hardware."""

    #: name in records and messages
    name: ClassVar[str]

    @abc.abstractmethod
    def cost(self, plan, output: str) -> float:
        """Cost of evaluating output ``output`` of ``plan``: every operation of its cone."""

    def record(self) -> dict:
        """JSON-ready description."""
        return {"cost_model": self.name}


@dataclass(frozen=True)
class MultiplierCount(CostModel):
    """One unit per multiplication (``mul`` operation) in the output's cone.

    Products dominate every polynomial architecture so far: the pipelined core spends a
    multiplier (a DSP block or a LUT array) on each, the modulo-scheduled core one multiplier
    issue slot per product and interval, the folded core one cycle of a multiplier unit;
    additions, shifts and clamps are cheap beside them.
    """
    name: ClassVar[str] = "multipliers"

    def cost(self, plan, output: str) -> float:
        node = next(o.node for o in plan.outputs if o.name == output)
        return sum(1 for i in plan.cone(node) if plan.nodes[i].op == "mul")


DEFAULT_COST_MODEL = MultiplierCount()
