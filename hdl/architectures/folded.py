"""Folded evaluator: the whole plan as microcode on a few multipliers, one target at a time."""
from __future__ import annotations

from ..folded import FoldedEvaluator, folded_program
from ..leg import LegCore
from . import Architecture, BuildTarget, Timing
from .options import check_primitives, dsp_label, dsp_size, positive_int

__all__ = ["Folded"]


class Folded(Architecture):
    """The plan compiled to a program on ``multipliers`` DSP-sized multipliers
    (:class:`~ikseries.hdl.folded.FoldedEvaluator`): a new target once the previous one's
    widths have transferred.

    Parameters
    ----------
    multipliers : int
        Multiplier units, >= 1.
    dsp : str or None
        DSP family of the units (None, "none": full-width products).
    primitives : bool
        The units' limb products on the DSP family's instantiated primitives with their own
        registers (needs a ``dsp`` family that has them, see :mod:`ikseries.constraints`).
    """

    name = "folded"

    def __init__(self, multipliers: int = 1, dsp: str | None = None, primitives: bool = False):
        self.multipliers = positive_int(multipliers, "multipliers")
        dsp_size(dsp)
        self.dsp, self.primitives = dsp, check_primitives(primitives, dsp)

    @property
    def _registers(self) -> str | None:
        """The ``dsp_registers`` of the evaluator: the family, with primitives."""
        return self.dsp if self.primitives else None

    def program(self, plan):
        """The compiled program (pure data: steps, unit schedule, memories)."""
        return folded_program(plan, self.multipliers, dsp_size(self.dsp))

    def timing(self, plan) -> Timing:
        steps = self.program(plan).steps
        return Timing(steps + 1, steps + 1, "folded")

    def evaluator(self, plan):
        return FoldedEvaluator(plan, self.multipliers, dsp_size(self.dsp), self._registers)

    def build(self, plan, target: BuildTarget):
        return LegCore(plan, target.period, multipliers=self.multipliers, dsp=dsp_size(self.dsp),
                       dsp_registers=self._registers)

    def multiplier_units(self, plan) -> int:
        return self.multipliers

    def describe(self) -> str:
        k = self.multipliers
        return f"folded, {k} multiplier{'s' if k != 1 else ''} ({dsp_label(self.dsp)})"

    def record(self) -> dict:
        return {**super().record(), "primitives": self.primitives}
