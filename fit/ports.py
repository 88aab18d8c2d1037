"""Input port formats of a robot's plan: the workspace box as integer port ranges."""
from __future__ import annotations

from .plan import PlanInput, bits_for

__all__ = ["plan_inputs"]


def plan_inputs(robot) -> list[PlanInput]:
    """One :class:`PlanInput` per robot input: its fractional bits, in-range integer bounds and
    the narrowest port holding them."""
    out = []
    for i in robot.workspace.inputs:
        w, signed = bits_for(i.lo, i.hi)
        out.append(PlanInput(i.name, i.unit, i.frac_bits, i.lo, i.hi, w, signed))
    return out
