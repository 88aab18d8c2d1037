"""Robot core: one folded evaluator time-multiplexed over identical legs, a PWM bank for all servos."""
from __future__ import annotations

from amaranth.hdl import Module, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.plan import Plan
from .architectures import Timing
from .evaluator import input_layout, output_layout
from .folded import FoldedEvaluator
from .pwm import servo_channels
from .pwmbank import ServoPWMBank

__all__ = ["RobotCore", "robot_input_layout", "robot_output_layout"]


def robot_input_layout(plan: Plan, legs: int) -> data.StructLayout:
    """A target for one leg: ``leg`` index and the plan's input fields under ``target``."""
    return data.StructLayout({"leg": range(legs), "target": input_layout(plan)})


def robot_output_layout(plan: Plan, legs: int) -> data.StructLayout:
    """Pulse widths (clock ticks) of one leg's servos: ``leg`` and ``widths.<servo>``."""
    return data.StructLayout({"leg": range(legs), "widths": output_layout(plan)})


class RobotCore(wiring.Component):
    """Inverse kinematics and servo signals for ``legs`` legs that share one plan.

    One :class:`FoldedEvaluator` serves every leg in turn: each input carries a leg index
    and that leg's tip target; the widths it yields are written to that leg's servo
    channels of a :class:`ServoPWMBank` (one period counter for all channels), which
    applies a leg's new widths together at the next PWM period start.

    Parameters
    ----------
    plan : Plan
        The plan of one leg; its outputs are pulse widths in clock ticks (never negative).
    legs : int
        Number of legs.
    period : int
        PWM period in clock cycles.
    clock_hz : float
        Clock frequency the core will run at; only used for ``refresh_hz``.
    multipliers, dsp
        As for :class:`FoldedEvaluator`.
    reset_widths : dict, optional
        Pulse width per servo name (the same for every leg) until its leg's first target.

    Attributes
    ----------
    i : In(stream.Signature(robot_input_layout(plan, legs)))
    o : Out(stream.Signature(robot_output_layout(plan, legs)))
        The widths of each evaluation with its leg; every transfer on ``o`` also loads
        them into the PWM bank (tie ``o.ready`` high if nothing listens).
    pwm : Out(legs * len(plan.outputs))
        Servo signals; bit ``leg * len(plan.outputs) + j`` drives servo ``j`` of ``leg``.
    period_start : Out(1)
        High for one cycle when a PWM period starts (widths take effect).

    Latency
    -------
    ``latency`` cycles from a target transfer on ``i`` to its widths on ``o`` (the
    evaluator's); the widths reach the servo signals at the next period start (the one
    after, for widths that arrive in a period's last cycle; see :class:`~ikseries.hdl.pwmbank.ServoPWMBank`).

    Throughput
    ----------
    One target every ``initiation_interval`` cycles while ``o.ready`` is high; every leg
    gets new widths ``refresh_hz`` times a second when targets are offered round-robin.
    """

    def __init__(self, plan: Plan, legs: int, period: int, clock_hz: float, *, multipliers: int = 1,
                 dsp: tuple[int, int] | None = None, reset_widths: dict | None = None):
        if not isinstance(legs, int) or isinstance(legs, bool) or legs < 1:
            raise ValueError(f"legs must be a positive integer, not {legs!r}")
        if isinstance(clock_hz, bool) or not isinstance(clock_hz, (int, float)) or not clock_hz > 0:
            raise ValueError(f"clock_hz must be a positive number, not {clock_hz!r}")
        self._evaluator = FoldedEvaluator(plan, multipliers, dsp)
        self._servos, reset_widths = servo_channels(plan, reset_widths)
        width_bits = max(plan.nodes[o.node].width for o in plan.outputs)
        self._bank = ServoPWMBank(period, width_bits, legs, len(self._servos),
                                  [reset_widths.get(s, 0) for s in self._servos] * legs)
        self._plan, self._legs, self._clock_hz = plan, legs, clock_hz
        super().__init__({
            "i": In(stream.Signature(robot_input_layout(plan, legs))),
            "o": Out(stream.Signature(robot_output_layout(plan, legs))),
            "pwm": Out(legs * len(self._servos)),
            "period_start": Out(1),
        })

    @property
    def evaluator(self) -> FoldedEvaluator:
        return self._evaluator

    @property
    def legs(self) -> int:
        return self._legs

    @property
    def servos(self) -> list[str]:
        return list(self._servos)

    @property
    def period(self) -> int:
        return self._bank.period

    @property
    def clock_hz(self) -> float:
        return self._clock_hz

    @property
    def latency(self) -> int:
        return self._evaluator.latency

    @property
    def initiation_interval(self) -> int:
        return self._evaluator.initiation_interval

    @property
    def timing(self) -> Timing:
        """The evaluator's latency and initiation interval, shared by the legs."""
        return Timing(self.latency, self.initiation_interval, "folded", self._legs)

    @property
    def refresh_hz(self) -> float:
        """Whole-robot IK refresh rate: every leg re-evaluated this many times per second."""
        return self.timing.refresh_hz(self._clock_hz)

    def elaborate(self, platform):
        m = Module()
        m.submodules.evaluator = ev = self._evaluator
        m.submodules.pwm_bank = bank = self._bank
        # the evaluator holds one evaluation at a time (its i.ready stays low until its
        # output transfers), so the leg of the evaluation in flight is one register
        leg = Signal(range(self._legs))
        m.d.comb += [ev.i.valid.eq(self.i.valid), ev.i.payload.eq(self.i.payload.target),
                     self.i.ready.eq(ev.i.ready)]
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += leg.eq(self.i.payload.leg)
        m.d.comb += [self.o.valid.eq(ev.o.valid), ev.o.ready.eq(self.o.ready),
                     self.o.payload.leg.eq(leg), self.o.payload.widths.eq(ev.o.payload)]
        m.d.comb += [bank.i.valid.eq(ev.o.valid & self.o.ready), bank.i.payload.group.eq(leg)]
        for j, s in enumerate(self._servos):
            m.d.comb += bank.i.payload.widths[j].eq(ev.o.payload[s])
        m.d.comb += [self.pwm.eq(bank.pwm), self.period_start.eq(bank.period_start)]
        return m
