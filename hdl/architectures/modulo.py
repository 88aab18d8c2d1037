"""Modulo-scheduled evaluator: the dataflow pipelined, its multiplications shared."""
from __future__ import annotations

from ..leg import LegCore
from ..modulo import ModuloEvaluator, modulo_latency, modulo_schedule, modulo_stream_rule
from ..tables import default_registered_depth
from ...fit.cost import COSTS
from . import Architecture, BuildTarget, Timing
from .options import check_cost, check_primitives, dsp_label, dsp_size, offered_cost_model, positive_int

__all__ = ["Modulo"]


class Modulo(Architecture):
    """One target every ``interval`` cycles on ceil(multiplications / interval) multipliers
    per operand class (:class:`~ikseries.hdl.modulo.ModuloEvaluator`).

    Parameters
    ----------
    interval : int
        Initiation interval, >= 1.
    dsp : str or None
        DSP family whose block size splits wide products into limbs (None, "none": full width
        products; the evaluator's default 18 x 18).
    primitives : bool
        Products on the DSP family's instantiated primitives with their own registers (needs a
        ``dsp`` family that has them, see :mod:`ikseries.constraints`), and, on a family with a
        block RAM primitive (the ECP5's DP16KD), the tables deep enough for it on it with its
        output register: one more cycle per such table read (:class:`~ikseries.hdl.modulo.ModuloEvaluator`,
        ``registered_tables``).
    cost : str
        What the fitter minimises for it (:data:`ikseries.fit.cost.COSTS`):
        "multipliers", or "device" (needs a ``dsp`` family): the share of the family's reference
        part the plan takes, each multiplier shared by ``interval`` targets
        (:class:`~ikseries.fit.cost.DeviceCost`).
    """

    name = "modulo"

    def __init__(self, interval: int, dsp: str | None = None, primitives: bool = False, cost: str = COSTS[0]):
        self.interval = positive_int(interval, "interval")
        dsp_size(dsp)
        self.dsp, self.primitives = dsp, check_primitives(primitives, dsp)
        self.cost = check_cost(cost, dsp)

    @property
    def _registers(self) -> str | None:
        """The ``dsp_registers`` of the evaluator: the family, with primitives."""
        return self.dsp if self.primitives else None

    @property
    def _registered_depth(self) -> int | None:
        return default_registered_depth(self._registers)

    @property
    def _size(self):
        return dsp_size(self.dsp) or dsp_size("ecp5")   # the evaluator's default block

    def timing(self, plan) -> Timing:
        s = modulo_schedule(plan, self.interval, self._size, self._registered_depth)
        return Timing(modulo_latency(s), s.initiation_interval, modulo_stream_rule(s.initiation_interval))

    def evaluator(self, plan):
        return ModuloEvaluator(plan, self.interval, dsp=self._size, dsp_registers=self._registers)

    def build(self, plan, target: BuildTarget):
        return LegCore(plan, target.period, interval=self.interval, dsp=dsp_size(self.dsp),
                       dsp_registers=self._registers)

    def multiplier_units(self, plan) -> int:
        return modulo_schedule(plan, self.interval, self._size, self._registered_depth).units

    def cost_model(self):
        return offered_cost_model(self.cost, self.dsp, self.interval)

    def describe(self) -> str:
        return f"modulo-scheduled pipeline, one target per {self.interval} cycles ({dsp_label(self.dsp)})"

    def record(self) -> dict:
        # cost only where it is not the default: records of cores before it stay the same
        return {**super().record(), "primitives": self.primitives,
                **({"cost": self.cost} if self.cost != COSTS[0] else {})}
