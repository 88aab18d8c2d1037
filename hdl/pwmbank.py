"""A bank of servo PWM generators sharing one period counter, loaded a group at a time."""
from __future__ import annotations

from amaranth.hdl import Cat, Module, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["ServoPWMBank", "check_int"]


def check_int(name, v, least):
    """Refuse ``v`` unless it is an integer (not a bool) of at least ``least``: the parameter
    check of the PWM and servo components."""
    if not isinstance(v, int) or isinstance(v, bool) or v < least:
        raise ValueError(f"{name} must be an integer >= {least}, not {v!r}")


class ServoPWMBank(wiring.Component):
    """``groups * per_group`` servo PWM channels with one shared period counter.

    Behaves like ``groups * per_group`` :class:`ikseries.hdl.pwm.ServoPWM` generators
    reset together (same period, same phase), for one counter instead of one per channel.
    A transfer on ``i`` stores new widths for every channel of one group (e.g. the servos
    of one leg); the stored widths are applied together at the next period start, so a
    pulse is never truncated or stretched and a group never shows a mix of old and new
    widths within one period.

    Parameters
    ----------
    period : int
        Period in clock cycles.
    width_bits : int
        Bits of a pulse width.
    groups, per_group : int
        Channel ``c`` is servo ``c % per_group`` of group ``c // per_group``.
    reset_widths : list of int, optional
        Width of every channel from reset until its first update (default 0: no pulse).
    in_order : bool
        The caller loads every group once, in order 0 .. ``groups - 1``, between two period
        starts (a :class:`~ikseries.hdl.servo.ServoController` pass does): the stored widths are
        then a shift register the loads shift into, ``i.payload.group`` is ignored and no group
        decoder is built (one LUT or two per group). Default False: any group at any time.
    phase : bool
        Give the period counter out on ``phase`` (default False: the port is absent).

    Attributes
    ----------
    i : In(stream.Signature(StructLayout({"group": range(groups), "widths": ArrayLayout(unsigned(width_bits), per_group)})))
        ``i.ready`` is always high.
    pwm : Out(groups * per_group)
        The servo signals, registered (glitch-free); bit ``c`` is channel ``c``.
    period_start : Out(1)
        High for one cycle when a period starts.
    phase : Out(range(2 ** bits))
        With ``phase=True`` only: the period counter, 0 .. ``period - 1``, then 0 again (``bits``
        those of ``period - 1``); ``period_start`` and the pins follow it by a cycle
        (``period_start`` is high while it is 1). Combinational from its flip-flops, for a
        caller's window in the period without a counter of its own.

    Latency
    -------
    The outputs follow the counter by one cycle; widths stored at cycle c are applied at
    the first period start after c + 1: a load in the last cycle of a period waits one period
    more (the active widths load only from the stored ones, so no multiplexer per bit stands
    between a transfer and the comparators).

    Throughput
    ----------
    One group per cycle; only the last load of a group before a period start is applied.
    """

    def __init__(self, period: int, width_bits: int, groups: int, per_group: int,
                 reset_widths: list[int] | None = None, in_order: bool = False, phase: bool = False):
        check_int("period", period, 2)
        check_int("width_bits", width_bits, 1)
        check_int("groups", groups, 1)
        check_int("per_group", per_group, 1)
        n = groups * per_group
        reset_widths = [0] * n if reset_widths is None else list(reset_widths)
        if len(reset_widths) != n or not all(isinstance(w, int) and 0 <= w < 2 ** width_bits
                                             for w in reset_widths):
            raise ValueError(f"reset_widths must be {n} integers in [0, {2 ** width_bits - 1}], "
                             f"not {reset_widths!r}")
        self._period, self._width_bits = period, width_bits
        self._groups, self._per_group, self._reset = groups, per_group, reset_widths
        self._in_order = bool(in_order)
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({
                "group": range(groups), "widths": data.ArrayLayout(unsigned(width_bits), per_group)}))),
            "pwm": Out(n),
            "period_start": Out(1), **({"phase": Out((period - 1).bit_length())} if phase else {}),
        })

    @property
    def period(self) -> int:
        return self._period

    @property
    def channels(self) -> int:
        return self._groups * self._per_group

    def elaborate(self, platform):
        m = Module()
        g, k = self._groups, self._per_group
        # count < active per channel: an up-counter against each active width. (A down-counter,
        # whose count < active is the carry out of active + ncount, takes a LUT less per bit
        # and channel, but its carry chains then start at the counter's flip-flops, a net of
        # every channel's loads: a hexapod core's bank limited the iCE40UP5K to 46 MHz, the
        # core alone reaches 59.)
        count = Signal(range(self._period))
        # high while count is period - 1, from a register: it enables every active width
        # register, a net of hundreds of loads that a comparator in front would lengthen
        # (period >= 2: count wraps from period - 1 to 0, never period - 1 twice in a row)
        last = Signal(name="last")
        m.d.sync += last.eq(count == self._period - 2)
        m.d.comb += self.i.ready.eq(1)
        with m.If(last):
            m.d.sync += count.eq(0)
        with m.Else():
            m.d.sync += count.eq(count + 1)
        bits, pendings = [], []
        for grp in range(g):
            load = self.i.valid & (self.i.payload.group == grp)
            for s in range(k):
                c = grp * k + s
                pending = Signal(self._width_bits, init=self._reset[c], name=f"pending{c}")
                active = Signal(self._width_bits, init=self._reset[c], name=f"active{c}")
                new = self.i.payload.widths[s]
                pendings.append(pending)
                if not self._in_order:
                    with m.If(load):
                        m.d.sync += pending.eq(new)
                with m.If(last):
                    m.d.sync += active.eq(pending)
                bit = Signal(name=f"pwm{c}")
                m.d.sync += bit.eq(count < active)
                bits.append(bit)
        if self._in_order:
            # a load shifts every group down one: after loads 0 .. groups - 1, group g holds
            # load g (no decoder: one enable for all)
            with m.If(self.i.valid):
                m.d.sync += [p.eq(pendings[c + k] if c + k < g * k else self.i.payload.widths[c % k])
                             for c, p in enumerate(pendings)]
        m.d.comb += self.pwm.eq(Cat(*bits))
        m.d.sync += self.period_start.eq(count == 0)
        if "phase" in self.signature.members:
            m.d.comb += self.phase.eq(count)
        return m
