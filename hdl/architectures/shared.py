"""One folded evaluator time-multiplexed over the legs of a robot, with a PWM bank."""
from __future__ import annotations

from ..shared import TABLE_LATENCY, RobotCore, table_in_use
from . import BuildTarget, Timing
from .folded import Folded
from .options import dsp_label, dsp_size, positive_int

__all__ = ["Shared"]


class Shared(Folded):
    """:class:`~.folded.Folded` shared by ``legs`` legs (:class:`~ikseries.hdl.shared.RobotCore`):
    each target carries its leg index, every leg's servos have their own PWM channels;
    ``channels``: the core's channel table (:class:`~ikseries.fit.channels.ChannelTable`, the
    left legs' mirror and the per-channel calibration), None for none."""

    name = "shared"

    def __init__(self, legs: int, multipliers: int = 1, dsp: str | None = None, channels=None,
                 primitives: bool = False):
        super().__init__(multipliers, dsp, primitives)
        self.legs = positive_int(legs, "legs")
        self.channels = channels

    def timing(self, plan) -> Timing:
        t = super().timing(plan)
        extra = TABLE_LATENCY if table_in_use(plan, self.channels) is not None else 0
        return Timing(t.latency + extra, t.initiation_interval + extra, "folded", self.legs)

    def build(self, plan, target: BuildTarget):
        return RobotCore(plan, self.legs, target.period, target.clock_hz, multipliers=self.multipliers,
                         dsp=dsp_size(self.dsp), channels=self.channels, dsp_registers=self._registers)

    def describe(self) -> str:
        k = self.multipliers
        return (f"folded evaluator shared by {self.legs} legs, {k} multiplier{'s' if k != 1 else ''} "
                f"({dsp_label(self.dsp)})")
