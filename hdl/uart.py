"""8N1 UART receiver and transmitter with an integer clock divisor (cycles per bit)."""
from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["UARTRx", "UARTTx", "uart_divisor", "MIN_DIVISOR", "BAUD_TOLERANCE"]

#: fewest clock cycles per bit: the receiver samples mid-bit, (divisor - 1) // 2 cycles after the start edge
MIN_DIVISOR = 4
#: largest relative rate error :func:`uart_divisor` accepts; with the receiver's sampling point
#: a frame of 10 bits then drifts less than 0.2 bit, leaving room for the sender's own error
BAUD_TOLERANCE = 0.02


def _check_divisor(divisor):
    if not isinstance(divisor, int) or isinstance(divisor, bool) or divisor < MIN_DIVISOR:
        raise ValueError(f"divisor must be an integer >= {MIN_DIVISOR} clock cycles per bit, not {divisor!r}")


def uart_divisor(clock_hz: float, baud: float) -> int:
    """Clock cycles per bit for ``baud`` at ``clock_hz``, refused when the rate it gives is more
    than :data:`BAUD_TOLERANCE` off ``baud`` or the divisor is below :data:`MIN_DIVISOR`."""
    for name, v in (("clock_hz", clock_hz), ("baud", baud)):
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not v > 0:
            raise ValueError(f"{name} must be a positive number, not {v!r}")
    divisor = max(1, round(clock_hz / baud))
    if divisor < MIN_DIVISOR:
        raise ValueError(f"baud must be at most clock_hz / {MIN_DIVISOR} = {clock_hz / MIN_DIVISOR:g}, not {baud!r}")
    error = abs(clock_hz / divisor - baud) / baud
    if error > BAUD_TOLERANCE:
        raise ValueError(f"baud {baud:g} is {100 * error:.2f} % off at a {clock_hz:g} Hz clock (divisor {divisor} "
                         f"gives {clock_hz / divisor:g}); the limit is {100 * BAUD_TOLERANCE:g} %")
    return divisor


class UARTRx(wiring.Component):
    """8N1 UART receiver.

    The pin goes through a two-flip-flop synchroniser. A low level starts a byte; the start bit
    is checked (a glitch shorter than half a bit is ignored) and every bit is sampled once, in
    its middle, ``(divisor - 1) // 2`` cycles after the start edge and then every ``divisor``
    cycles. A low stop bit drops the byte and pulses ``framing_error``; the receiver then waits
    for the line to go high (a break counts once). Right after the stop bit's middle it looks
    for the next start edge, which leaves half a bit for a sender that is up to
    :data:`BAUD_TOLERANCE` fast or slow.

    Parameters
    ----------
    divisor : int
        Clock cycles per bit (>= :data:`MIN_DIVISOR`); see :func:`uart_divisor`.
    buffered : bool
        Default True: a received byte waits in an output register of its own while the next one
        comes in. False: ``o.payload`` is the shift register itself (eight flip-flops less, each a
        logic cell of its own), for a consumer that takes every byte within a bit time.

    Attributes
    ----------
    rx : In(1)
        The serial input (idle high).
    o : Out(stream.Signature(8))
        Received bytes. Buffered, a byte stays valid until taken; a byte completed while the
        previous one is still not taken is lost and pulses ``overrun``. Unbuffered, a byte must be
        taken before the middle of the next start bit (at least one bit time after it came): if
        not, it is dropped there (the shift register takes the next byte's bits) and ``overrun``
        pulses.
    framing_error, overrun : Out(1)
        One-cycle pulses, registered.
    idle_tick : Out(1)
        A one-cycle pulse, registered, every ``divisor`` cycles while the receiver waits for a
        start bit (the first one bit time after a stop bit's middle; none during a break): a
        pause between bytes in bit times, for :class:`~ikseries.hdl.link.FrameReceiver`'s timeout.
    bit_strobe, bit_value : Out(1)
        ``bit_strobe`` is high (combinationally) in the cycle a data bit is sampled, least
        significant first, eight a byte, ``bit_value`` that bit: a CRC taken a bit at a time
        (:class:`~ikseries.hdl.link.SerialCRC`) has a byte's bits before the byte is on ``o``.
        A byte dropped for its stop bit has had its bits sampled too.

    Latency
    -------
    ``o.valid`` rises ``(divisor - 1) // 2 + 9 * divisor + 3`` cycles after the start edge on
    the pin (two synchroniser cycles, the stop bit's middle, one output register).

    Throughput
    ----------
    One byte per 10 bit times of the sender (back-to-back bytes at up to
    :data:`BAUD_TOLERANCE` rate error).
    """

    def __init__(self, divisor: int, buffered: bool = True):
        _check_divisor(divisor)
        self._divisor = divisor
        self._buffered = bool(buffered)
        super().__init__({"rx": In(1, init=1), "o": Out(stream.Signature(8)),
                          "framing_error": Out(1), "overrun": Out(1), "idle_tick": Out(1),
                          "bit_strobe": Out(1), "bit_value": Out(1)})

    @property
    def divisor(self) -> int:
        return self._divisor

    @property
    def latency(self) -> int:
        return (self._divisor - 1) // 2 + 9 * self._divisor + 3

    def elaborate(self, platform):
        m = Module()
        d = self._divisor
        pins = Signal(2, init=0b11)     # the synchroniser: idle high from reset
        m.d.sync += pins.eq(Cat(self.rx, pins[0]))
        line = pins[1]
        m.d.comb += self.bit_value.eq(line)
        timer = Signal(range(d))
        tick = timer == 0
        bit = Signal(range(8))
        shift = Signal(8)
        # free-running between bytes too, so that idle_tick measures pauses in bit times
        m.d.sync += [timer.eq(Mux(tick, d - 1, timer - 1)), self.framing_error.eq(0), self.overrun.eq(0),
                     self.idle_tick.eq(0)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        if not self._buffered:
            m.d.comb += self.o.payload.eq(shift)
        with m.FSM():
            with m.State("idle"):
                m.d.sync += self.idle_tick.eq(tick)
                with m.If(~line):
                    m.d.sync += timer.eq((d - 1) // 2 - 1)
                    m.next = "start"
            with m.State("start"):
                with m.If(tick):
                    m.d.sync += bit.eq(0)
                    m.next = "data"
                    with m.If(line):        # the start bit did not last half a bit: a glitch
                        m.next = "idle"
                    if not self._buffered:
                        with m.Elif(self.o.valid & ~self.o.ready):     # the shift register is needed
                            m.d.sync += [self.overrun.eq(1), self.o.valid.eq(0)]
            with m.State("data"):
                m.d.comb += self.bit_strobe.eq(tick)
                with m.If(tick):
                    m.d.sync += [shift.eq(Cat(shift[1:], line)), bit.eq(bit + 1)]
                    with m.If(bit == 7):
                        m.next = "stop"
            with m.State("stop"):
                with m.If(tick):
                    with m.If(~line):
                        m.d.sync += self.framing_error.eq(1)
                        m.next = "break"
                    if self._buffered:
                        with m.Elif(self.o.valid & ~self.o.ready):
                            m.d.sync += self.overrun.eq(1)
                            m.next = "idle"
                    with m.Else():
                        m.d.sync += self.o.valid.eq(1)
                        if self._buffered:
                            m.d.sync += self.o.payload.eq(shift)
                        m.next = "idle"
            with m.State("break"):
                with m.If(line):
                    m.next = "idle"
        return m


class UARTTx(wiring.Component):
    """8N1 UART transmitter.

    The byte is sent straight from ``i.payload``, which a stream holds until it is taken: the
    transmitter takes it when its stop bit starts, so it needs no shift register of its own.

    Parameters
    ----------
    divisor : int
        Clock cycles per bit (>= :data:`MIN_DIVISOR`).

    Attributes
    ----------
    i : In(stream.Signature(8))
        Bytes to send; a byte is taken in the first cycle of its stop bit.
    tx : Out(1)
        The serial output, registered; high (idle) from reset.
    bit_strobe, bit_value : Out(1)
        ``bit_strobe`` is high (combinationally) in the cycle a data bit goes onto ``tx`` (it is
        there from the next cycle), least significant first, eight a byte, ``bit_value`` that
        bit: a byte's bits have all been strobed when it is taken.

    Latency
    -------
    The start bit begins one cycle after a byte is valid while the line is idle, or right after
    the previous stop bit.

    Throughput
    ----------
    One byte per ``10 * divisor`` cycles when offered back to back (the next byte valid before
    the stop bit ends).
    """

    def __init__(self, divisor: int):
        _check_divisor(divisor)
        self._divisor = divisor
        super().__init__({"i": In(stream.Signature(8)), "tx": Out(1, init=1), "bit_strobe": Out(1),
                          "bit_value": Out(1)})

    @property
    def divisor(self) -> int:
        return self._divisor

    def elaborate(self, platform):
        m = Module()
        d = self._divisor
        busy = Signal()
        timer = Signal(range(d))
        bit = Signal(range(10))         # the bit on the line: 0 start, 1 .. 8 data, 9 stop
        tick = timer == 0
        with m.If(busy):
            m.d.sync += timer.eq(timer - 1)
            with m.If(tick):
                m.d.sync += [timer.eq(d - 1), bit.eq(bit + 1)]
                with m.If(bit == 8):
                    m.d.sync += self.tx.eq(1)
                    m.d.comb += self.i.ready.eq(1)
                with m.Elif(bit == 9):
                    m.d.sync += busy.eq(0)
                with m.Else():
                    m.d.comb += self.bit_strobe.eq(1)
                    m.d.sync += self.tx.eq(self.bit_value)
        m.d.comb += self.bit_value.eq(self.i.payload.bit_select(bit, 1))
        # the next byte starts right where the stop bit ends (or at once on an idle line)
        with m.If(self.i.valid & (~busy | (tick & (bit == 9)))):
            m.d.sync += [busy.eq(1), timer.eq(d - 1), bit.eq(0), self.tx.eq(0)]
        return m
