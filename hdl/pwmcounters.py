"""Servo PWM channels as one pulse counter each, loaded in order in a window of every period."""
from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .pwmbank import check_int

__all__ = ["ServoPWMCounters"]


class ServoPWMCounters(wiring.Component):
    """``channels`` servo PWM outputs for a caller that sends every channel's width once per
    period, in channel order, early in the period (the servo controller's engine pass).

    A period of ``period`` cycles has a load window, phases 0 .. ``lead - 1``, where every
    pin is low and the widths arrive, then the pulses: every channel with a nonzero width
    rises ``lead`` cycles after ``period_start`` (all together) and falls ``width`` cycles
    later. So widths sent in
    one window show in full in the same period, from one common edge: a pulse is never cut or
    stretched and channels sent together change together.

    Each channel is a ``width_bits + 1``-bit counter, not a width register and a comparator
    against a shared count (:class:`~ikseries.hdl.pwmbank.ServoPWMBank`, which needs a second
    register per channel to hold a width sent at any time until the period start): a load sets
    it to ``-width`` (the shared bus carries ``~width``, the counter adds it with carry in 1
    to its own 0), the pulses count it up to 0 and its sign bit is the pulse. One adder cell
    per bit does both, because the bus is 0 outside loads and a channel loads only while
    its counter rests at 0. On the iCE40 that is about one logic cell per bit and channel,
    against three for the width register, pending register and comparator of the bank.

    Parameters
    ----------
    period : int
        Period in clock cycles.
    width_bits : int
        Bits of a width.
    channels : int
        Channels, loaded 0, 1, ... ``channels - 1`` in every window.
    lead : int
        Cycles of the load window, ``1 <= lead < period``. Widths are shown up to
        ``max_width = period - lead`` cycles; a larger one is shown as ``max_width`` (the pulses
        end before the next window, so every counter is at rest there).

    Attributes
    ----------
    i : In(stream.Signature(StructLayout({"width": unsigned(width_bits)})))
        The next channel's width, ``i.ready`` high in the window only (phases ``0 .. lead - 1``
        after the first period start): the ``k``-th transfer of a window is channel
        ``k``'s; transfers beyond ``channels`` are ignored. A channel not loaded in a window
        shows no pulse in that period.
    pwm : Out(channels)
        The servo signals, registered (glitch-free); bit ``c`` is channel ``c``.
    period_start : Out(1)
        High for one cycle when a period starts (while ``phase`` is 1). From reset a quiet
        period passes first: no loads, no pulses, no ``period_start`` (the caller initialises
        meanwhile); the first period starts ``period + 1`` cycles after reset.
    phase : Out(range(2 ** bits))
        The period counter, 0 .. ``period - 1`` (``bits`` those of ``period - 1``).

    Latency
    -------
    A width sent in a window shows in the same period, ``lead`` cycles after ``period_start``
    (which is high while ``phase`` is 1: the pins follow the counters by one cycle).

    Throughput
    ----------
    One width per cycle in the window; every channel once per period.
    """

    def __init__(self, period: int, width_bits: int, channels: int, lead: int):
        check_int("period", period, 2)
        check_int("width_bits", width_bits, 1)
        check_int("channels", channels, 1)
        check_int("lead", lead, 1)
        if lead >= period:
            raise ValueError(f"lead must be < period={period}, not {lead!r}")
        self._period, self._w, self._n, self._lead = period, width_bits, channels, lead
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"width": unsigned(width_bits)}))),
            "pwm": Out(channels), "period_start": Out(1), "phase": Out((period - 1).bit_length()),
        })

    @property
    def period(self) -> int:
        return self._period

    @property
    def channels(self) -> int:
        return self._n

    @property
    def lead(self) -> int:
        return self._lead

    @property
    def max_width(self) -> int:
        """The widest pulse shown, ``period - lead`` cycles."""
        return self._period - self._lead

    def elaborate(self, platform):
        m = Module()
        p, w, n, lead = self._period, self._w, self._n, self._lead
        # the count resets to 0, like its wrap: a nonzero reset value would give some of its
        # flip-flops a set and others a reset, control sets an iCE40 logic block cannot mix
        # along the counter's carry chain (a start offset as the reset value cost the hexapod's
        # iCEBreaker top its clock: 22.5 MHz against 24)
        count = Signal(range(p))
        # high while count is period - 1, from a register: the counter's wrap, the end of the
        # pulses and the token's return take no comparator of the count in front of them
        last = Signal()
        m.d.sync += last.eq(count == (p - 2) % p)
        with m.If(last):
            m.d.sync += count.eq(0)
        with m.Else():
            m.d.sync += count.eq(count + 1)
        # the pulses' part of the period, from a register: it gates every channel's count. The
        # first period after reset is quiet: all of it runs as pulses of nothing (no loads), and
        # it does not start: only there is run high at count 0
        run = Signal(init=1)
        m.d.sync += self.period_start.eq((count == 0) & ~run)
        with m.If(count == lead - 1):
            m.d.sync += run.eq(1)
        with m.Elif(last):
            m.d.sync += run.eq(0)
        m.d.comb += [self.phase.eq(count), self.i.ready.eq(~run)]
        load = self.i.valid & ~run
        bus = self._bus(m, load)
        # channel k loads at the k-th transfer of the window: a token passed along on each
        token = Signal(n, init=1)
        with m.If(last):
            m.d.sync += token.eq(1)
        with m.Elif(load):
            m.d.sync += token.eq(token << 1)
        pins = []
        for c in range(n):
            # while it counts the bus is 0; while it loads it rests at 0: q + bus + 1 either way
            q = Signal(w + 1, name=f"pulse{c}")
            step = (load & token[c]) | (q[w] & run)
            with m.If(step):
                m.d.sync += q.eq(q + bus + 1)
            pin = Signal(name=f"pwm{c}")
            m.d.sync += pin.eq(q[w] & run)
            pins.append(pin)
        m.d.comb += self.pwm.eq(Cat(*pins))
        return m

    def _bus(self, m, load):
        """``~min(width, max_width)`` while loading, else 0 (``width_bits + 1`` bits)."""
        w, top = self._w, self.max_width
        width = self.i.payload.width
        if top < (1 << w) - 1:
            width = Mux(width > top, top, width)
        bus = Signal(w + 1)
        m.d.comb += bus.eq(Mux(load, ~width.as_unsigned()[:w] | (1 << w), 0))
        return bus
