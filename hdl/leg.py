"""Leg core: target stream in, pulse-width stream out, one PWM generator per servo."""
from __future__ import annotations

from amaranth.hdl import Module
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..constraints.devices import dsp_size, family_primitives
from ..fit.plan import Plan
from .evaluator import PlanEvaluator, input_layout, output_layout
from .folded import FoldedEvaluator
from .modulo import ModuloEvaluator
from .pwm import ServoPWM, servo_channels

__all__ = ["LegCore"]


class LegCore(wiring.Component):
    """IK evaluator for one leg feeding a PWM generator per servo.

    The evaluator is the fully pipelined :class:`PlanEvaluator` (one target per cycle); with
    ``multipliers`` given, a :class:`FoldedEvaluator` on that many multipliers (one target per
    ``initiation_interval`` cycles, far fewer resources); with ``interval`` given, a
    :class:`ModuloEvaluator` (the dataflow pipelined, its multiplications shared so that one
    target enters every ``interval`` cycles). The ports are the same.

    Parameters
    ----------
    plan : Plan
        Evaluation plan; its outputs are pulse widths in clock ticks.
    period : int
        PWM period in clock cycles.
    reset_widths : dict, optional
        Pulse width per servo from reset until the first target (default: no pulse).
    multipliers : int, optional
        None (default): the pipelined evaluator; an integer k >= 1: a folded evaluator
        with k multipliers.
    dsp : (int, int) or None
        DSP multiplier operand widths of the folded or modulo-scheduled evaluator (see
        :class:`FoldedEvaluator`); only with ``multipliers`` or ``interval``.
    interval : int, optional
        Initiation interval of a :class:`ModuloEvaluator` (not with ``multipliers``).
    dsp_registers : None, "ice40" or "ecp5", optional
        With ``interval`` or ``multipliers``: the modulo or folded evaluator's products on
        instantiated DSP primitives of that family with their own registers (see
        :class:`ModuloEvaluator`, :class:`FoldedEvaluator`).
    registered_tables : None, bool or int, optional
        With ``interval``: the modulo-scheduled evaluator's ``registered_tables`` (None: as
        ``dsp_registers`` implies, see :class:`ModuloEvaluator`).

    Attributes
    ----------
    i : In(stream.Signature(input_layout(plan)))
        Tip targets (port integers, see the interface manifest).
    o : Out(stream.Signature(output_layout(plan)))
        Pulse widths in clock ticks, one field per servo. Every transfer on ``o``
        also loads the widths into the PWM generators, which apply them together at
        the next period start (the generators share reset and period, so they run
        in step).
    pwm_<servo> : Out(1)
        Servo signals.

    Latency
    -------
    ``latency`` cycles from a target transfer on ``i`` to its widths on ``o``
    (equal to the evaluator's latency).

    Throughput
    ----------
    One target every ``initiation_interval`` cycles while ``o.ready`` is high (1 for the
    pipelined evaluator, ``interval`` for the modulo-scheduled one, the folded evaluator's
    latency otherwise).
    """

    def __init__(self, plan: Plan, period: int, reset_widths: dict | None = None, *,
                 multipliers: int | None = None, dsp: tuple[int, int] | None = None,
                 interval: int | None = None, dsp_registers: str | None = None,
                 registered_tables: bool | int | None = None):
        self._dsp_registers = dsp_registers
        if registered_tables is not None and interval is None:
            raise ValueError(f"registered_tables must be None without interval (only the modulo-scheduled "
                             f"evaluator registers its tables), not {registered_tables!r}")
        if dsp_registers is not None and interval is None and multipliers is None:
            raise ValueError(f"dsp_registers must be None without interval or multipliers (the pipelined "
                             f"evaluator instantiates no DSP primitives), not {dsp_registers!r}")
        if interval is not None:
            if multipliers is not None:
                raise ValueError(f"multipliers must be None with interval (a modulo-scheduled evaluator "
                                 f"sizes its multipliers itself), not {multipliers!r}")
            self._evaluator = ModuloEvaluator(plan, interval, dsp=dsp or dsp_size("ecp5"), dsp_registers=dsp_registers,
                                              registered_tables=registered_tables)
            registered_tables = self._evaluator.registered_tables or False     # the twin's, resolved
        elif multipliers is None:
            if dsp is not None:
                raise ValueError(f"dsp must be None for the pipelined evaluator (multipliers=None), not {dsp!r}")
            self._evaluator = PlanEvaluator(plan)
        else:
            if not isinstance(multipliers, int) or isinstance(multipliers, bool) or multipliers < 1:
                raise ValueError(f"multipliers must be None or an integer >= 1, not {multipliers!r}")
            self._evaluator = FoldedEvaluator(plan, multipliers, dsp, dsp_registers)
        self._args = (plan, period, reset_widths, dict(multipliers=multipliers, dsp=dsp, interval=interval,
                                                       registered_tables=registered_tables))
        self._servos, reset_widths = servo_channels(plan, reset_widths)
        layout = output_layout(plan)
        self._pwms = {s: ServoPWM(period, layout.members[s].width, reset_widths.get(s, 0))
                      for s in self._servos}
        super().__init__({
            "i": In(stream.Signature(input_layout(plan))),
            "o": Out(stream.Signature(layout)),
            **{f"pwm_{s}": Out(1) for s in self._servos},
        })

    @property
    def evaluator(self) -> PlanEvaluator | FoldedEvaluator | ModuloEvaluator:
        return self._evaluator

    @property
    def architecture(self) -> str:
        """"pipelined", "folded" or "modulo"."""
        if isinstance(self._evaluator, ModuloEvaluator):
            return "modulo"
        return "folded" if isinstance(self._evaluator, FoldedEvaluator) else "pipelined"

    @property
    def latency(self) -> int:
        return self._evaluator.latency

    @property
    def dsp_registers(self) -> str | None:
        """The family ("ice40", "ecp5") when the products run on its instantiated DSP primitives, else None."""
        return self._dsp_registers

    @property
    def primitives(self) -> tuple:
        """The vendor primitives the core instantiates (:class:`~ikseries.constraints.facts.Primitive`)."""
        if isinstance(self._evaluator, ModuloEvaluator):
            return self._evaluator.primitives
        return family_primitives(self._dsp_registers, "multiplier") if self._dsp_registers else ()

    def simulation_model(self) -> "LegCore":
        """A core the Amaranth simulator can run with the same ports, timing and values: this
        one, or with ``dsp_registers`` a twin whose DSP registers are fabric flip-flops and whose
        registered tables (if any) are ``Memory`` read ports with a fabric output register (the
        simulator cannot run an ``Instance``; the exported Verilog with the primitives is
        simulated by cocotb with the primitive's model)."""
        if self._dsp_registers is None:
            return self
        plan, period, widths, kw = self._args
        return LegCore(plan, period, widths, **kw)

    @property
    def initiation_interval(self) -> int:
        """Cycles from one accepted target to the next when ``o.ready`` stays high."""
        return self._evaluator.initiation_interval

    @property
    def servos(self) -> list[str]:
        return list(self._servos)

    @property
    def period(self) -> int:
        return next(iter(self._pwms.values())).period

    def elaborate(self, platform):
        m = Module()
        m.submodules.evaluator = ev = self._evaluator
        wiring.connect(m, wiring.flipped(self.i), ev.i)
        wiring.connect(m, ev.o, wiring.flipped(self.o))
        for s, pwm in self._pwms.items():
            m.submodules[f"pwm_{s}"] = pwm
            m.d.comb += [pwm.i.valid.eq(ev.o.valid & self.o.ready),
                         pwm.i.payload.eq(ev.o.payload[s]),
                         getattr(self, f"pwm_{s}").eq(pwm.pwm)]
        return m
