"""Servo PWM generator with a double-buffered pulse width."""
from __future__ import annotations

from amaranth.hdl import Module, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["ServoPWM", "servo_channels"]


class ServoPWM(wiring.Component):
    """Fixed-period pulse generator for one hobby servo.

    A new width offered on ``i`` is stored (always accepted) and applied at the
    start of the next period, so a pulse is never truncated or stretched. The
    output is high for exactly ``width`` clock cycles at the start of each
    ``period``-cycle period; it is registered (glitch-free).

    Parameters
    ----------
    period : int
        Period in clock cycles (e.g. 20 ms * clock frequency).
    width_bits : int
        Width of the pulse-width input, in bits.
    reset_width : int
        Pulse width (cycles) from reset until the first width is applied;
        0 (the default) emits no pulses, which leaves a servo unpowered.

    Attributes
    ----------
    i : In(stream.Signature(unsigned(width_bits)))
        New pulse width in clock cycles. ``i.ready`` is always high. Widths of
        ``period`` or more give a constant high output.
    pwm : Out(1)
        The servo signal; low during and right after reset.
    period_start : Out(1)
        High for one cycle when a period starts (the cycle a new width takes effect).

    Latency
    -------
    The output changes one cycle after the internal counter; a width accepted
    at cycle c is applied at the first period start after c + 1 (a width accepted in the
    last cycle of a period waits one period more: the active width loads only from the
    stored one, so no multiplexer stands between the input and the comparator).

    Throughput
    ----------
    One width per cycle is accepted; only the last one before a period start is used.
    """

    def __init__(self, period: int, width_bits: int, reset_width: int = 0):
        if not isinstance(period, int) or isinstance(period, bool) or period < 2:
            raise ValueError(f"period must be an integer >= 2 cycles, not {period!r}")
        if not isinstance(width_bits, int) or isinstance(width_bits, bool) or width_bits < 1:
            raise ValueError(f"width_bits must be a positive integer, not {width_bits!r}")
        if not isinstance(reset_width, int) or not 0 <= reset_width < 2 ** width_bits:
            raise ValueError(f"reset_width must be an integer in [0, {2 ** width_bits - 1}], "
                             f"not {reset_width!r}")
        self._period = period
        self._width_bits = width_bits
        self._reset_width = reset_width
        super().__init__({
            "i": In(stream.Signature(unsigned(width_bits))),
            "pwm": Out(1),
            "period_start": Out(1),
        })

    @property
    def period(self) -> int:
        return self._period

    @property
    def reset_width(self) -> int:
        return self._reset_width

    def elaborate(self, platform):
        m = Module()
        count = Signal(range(self._period))
        pending = Signal(self._width_bits, init=self._reset_width)
        active = Signal(self._width_bits, init=self._reset_width)
        m.d.comb += self.i.ready.eq(1)
        with m.If(self.i.valid):
            m.d.sync += pending.eq(self.i.payload)
        last = count == self._period - 1
        with m.If(last):
            m.d.sync += [count.eq(0), active.eq(pending)]
        with m.Else():
            m.d.sync += count.eq(count + 1)
        # registered output: high for cycles 0 .. active-1 of the counter, one cycle later
        m.d.sync += [self.pwm.eq(count < active), self.period_start.eq(count == 0)]
        return m


def servo_channels(plan, reset_widths: dict | None) -> tuple[list[str], dict]:
    """The servo names of ``plan``'s outputs and the checked ``reset_widths`` per servo.

    Every output must be a non-negative pulse width (PWM generators count ticks), and
    ``reset_widths`` may only name those servos.
    """
    for o in plan.outputs:
        if plan.nodes[o.node].lo < 0:
            raise ValueError(f"plan output {o.name} must be a non-negative pulse width, but its "
                             f"range starts at {plan.nodes[o.node].lo}")
    servos = [o.name for o in plan.outputs]
    reset_widths = dict(reset_widths or {})
    unknown = sorted(set(reset_widths) - set(servos))
    if unknown:
        raise ValueError(f"reset_widths keys must be servos {servos}, not {unknown[0]!r}")
    return servos, reset_widths
