"""One folded evaluator time-multiplexed over the legs of a robot, with a PWM bank."""
from __future__ import annotations

from ..shared import RobotCore
from . import BuildTarget, Timing
from .folded import Folded
from .options import dsp_label, dsp_size, positive_int

__all__ = ["Shared"]


class Shared(Folded):
    """:class:`~.folded.Folded` shared by ``legs`` legs (:class:`~ikseries.hdl.shared.RobotCore`):
    each target carries its leg index, every leg's servos have their own PWM channels."""

    name = "shared"

    def __init__(self, legs: int, multipliers: int = 1, dsp: str | None = None):
        super().__init__(multipliers, dsp)
        self.legs = positive_int(legs, "legs")

    def timing(self, plan) -> Timing:
        t = super().timing(plan)
        return Timing(t.latency, t.initiation_interval, "folded", self.legs)

    def build(self, plan, target: BuildTarget):
        return RobotCore(plan, self.legs, target.period, target.clock_hz, multipliers=self.multipliers,
                         dsp=dsp_size(self.dsp))

    def describe(self) -> str:
        k = self.multipliers
        return (f"folded evaluator shared by {self.legs} legs, {k} multiplier{'s' if k != 1 else ''} "
                f"({dsp_label(self.dsp)})")
