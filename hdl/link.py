"""The controller's host link in hardware: frame receiver, frame transmitter, and both on a UART.

Frame format, CRC and command lengths come from :mod:`ikseries.hdl.protocol`.
"""
from __future__ import annotations

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import crc, data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from . import protocol as P
from .uart import UARTRx, UARTTx

__all__ = ["FrameReceiver", "FrameTransmitter", "Link", "frame_layout", "counters_layout", "crc_processor"]


def crc_processor() -> crc.Processor:
    """A byte-wide CRC generator of the protocol's :data:`~ikseries.hdl.protocol.CRC`."""
    p = P.CRC
    return crc.Algorithm(crc_width=p.width, polynomial=p.polynomial, initial_crc=p.initial,
                         reflect_input=p.reflect_input, reflect_output=p.reflect_output,
                         xor_output=p.xor_output)(data_width=8).create()


def frame_layout(max_payload: int) -> data.StructLayout:
    """A frame's command (or answer) code and payload length."""
    return data.StructLayout({"command": 8, "length": range(max_payload + 1)})


def counters_layout(bits: int = P.COUNTER_BITS) -> data.StructLayout:
    """The receiver's error counters (:data:`~ikseries.hdl.protocol.RECEIVER_COUNTERS`)."""
    return data.StructLayout({name: bits for name in P.RECEIVER_COUNTERS})


def _saturating_increment(m, counter, event):
    with m.If(event & (counter != (1 << len(counter)) - 1)):
        m.d.sync += counter.eq(counter + 1)


class FrameReceiver(wiring.Component):
    """Validated request frames out of a byte stream.

    Follows the receiving rules of ``docs/protocol.md``: hunts for SYNC; refuses a LEN above the
    largest request and a LEN the command does not take, or an unknown command, as soon as that
    byte arrives (a refused byte equal to SYNC starts the next frame); then takes LEN payload
    bytes and the CRC. Payload bytes go into a two-bank block RAM: the bank of the frame on
    ``o`` is read through ``rd_addr``/``rd_data`` while the next frame fills the other, so a
    frame is offered only once its CRC is good (an atomic multi-leg move is never half applied).

    Parameters
    ----------
    shape : ikseries.hdl.protocol.Shape
        The robot the request lengths are for.
    counter_bits : int
        Width of each error counter (default and most the status answer carries:
        :data:`~ikseries.hdl.protocol.COUNTER_BITS`).

    Attributes
    ----------
    i : In(stream.Signature(8))
        Received bytes; ready except in the cycle after a frame's last byte.
    framing_error, overrun : In(1)
        The UART's error pulses, counted.
    o : Out(stream.Signature(frame_layout(max_payload)))
        Good frames: command code and payload length. Held until taken.
    rd_addr : In(addr_bits)
        Payload byte index of the frame on ``o``.
    rd_data : Out(8)
        That byte, one cycle after ``rd_addr`` (a block RAM read). Valid while ``o.valid``.
    counters : Out(counters_layout(counter_bits))
        Saturating counts: ``crc``, ``bad_length``,
        ``unknown_command``, ``dropped`` (a good frame completed while ``o`` was still held),
        ``framing`` and ``overrun`` (pulses of the inputs); zero from reset.

    Latency
    -------
    ``o.valid`` rises two cycles after the frame's last CRC byte is taken.

    Throughput
    ----------
    One byte per cycle, except the cycle after each frame's last byte.
    """

    def __init__(self, shape: P.Shape, counter_bits: int = P.COUNTER_BITS):
        if not isinstance(shape, P.Shape):
            raise TypeError(f"shape must be an ikseries.hdl.protocol.Shape, not {shape!r}")
        if not isinstance(counter_bits, int) or isinstance(counter_bits, bool) or not 1 <= counter_bits <= P.COUNTER_BITS:
            raise ValueError(f"counter_bits must be an integer in [1, {P.COUNTER_BITS}], not {counter_bits!r}")
        self._shape = shape
        self._lengths = {c.code: sorted(P.request_lengths(c, shape)) for c in P.COMMANDS}
        self._max = P.max_request_payload(shape)
        self._addr_bits = max(1, (self._max - 1).bit_length())
        super().__init__({
            "i": In(stream.Signature(8)), "framing_error": In(1), "overrun": In(1),
            "o": Out(stream.Signature(frame_layout(self._max))),
            "rd_addr": In(self._addr_bits), "rd_data": Out(8),
            "counters": Out(counters_layout(counter_bits)),
        })

    @property
    def max_payload(self) -> int:
        return self._max

    @property
    def addr_bits(self) -> int:
        return self._addr_bits

    #: cycles from taking a frame's last byte to ``o.valid``
    latency = 2

    def _length_check(self, m, code, length):
        """(known, length_ok) of command byte ``code`` with payload length ``length``."""
        known, ok = Signal(), Signal()
        with m.Switch(code):
            for c, lengths in self._lengths.items():
                with m.Case(c):
                    m.d.comb += [known.eq(1), ok.eq(Cat(*(length == n for n in lengths)).any())]
        return known, ok

    def elaborate(self, platform):
        m = Module()
        m.submodules.crc = check = crc_processor()
        bank = 1 << self._addr_bits
        m.submodules.mem = mem = Memory(shape=8, depth=2 * bank, init=[])
        wr, rd = mem.write_port(), mem.read_port()
        wbank, rbank = Signal(), Signal()
        length = Signal(range(self._max + 1))
        command = Signal(8)
        index = Signal(range(self._max + 2))
        byte, take = self.i.payload, self.i.valid & self.i.ready
        known, length_ok = self._length_check(m, byte, length)
        events = {name: Signal(name=f"{name}_event") for name in ("crc", "bad_length", "unknown_command", "dropped")}
        m.d.comb += [rd.addr.eq(Cat(self.rd_addr, rbank)), self.rd_data.eq(rd.data),
                     wr.addr.eq(Cat(index[:self._addr_bits], wbank)), wr.data.eq(byte), check.data.eq(byte)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)

        def refuse(counter):
            m.d.comb += events[counter].eq(1)
            m.next = "hunt"
            with m.If(byte == P.SYNC):      # the refused byte may be the next frame's start
                m.d.comb += check.start.eq(1)
                m.next = "len"

        with m.FSM():
            with m.State("hunt"):
                m.d.comb += self.i.ready.eq(1)
                with m.If(take & (byte == P.SYNC)):
                    m.d.comb += check.start.eq(1)
                    m.next = "len"
            with m.State("len"):
                m.d.comb += self.i.ready.eq(1)
                with m.If(take):
                    with m.If(byte > self._max):
                        refuse("bad_length")
                    with m.Else():
                        m.d.comb += check.valid.eq(1)
                        m.d.sync += length.eq(byte)
                        m.next = "cmd"
            with m.State("cmd"):
                m.d.comb += self.i.ready.eq(1)
                with m.If(take):
                    with m.If(~known):
                        refuse("unknown_command")
                    with m.Elif(~length_ok):
                        refuse("bad_length")
                    with m.Else():
                        m.d.comb += check.valid.eq(1)
                        m.d.sync += [command.eq(byte), index.eq(0)]
                        m.next = "body"
            with m.State("body"):
                m.d.comb += self.i.ready.eq(1)
                with m.If(take):
                    m.d.comb += [check.valid.eq(1), wr.en.eq(index < length)]
                    m.d.sync += index.eq(index + 1)
                    with m.If(index == length + 1):     # the CRC's last byte
                        m.next = "check"
            with m.State("check"):      # the CRC register has taken the last byte
                with m.If(~check.match_detected):
                    m.d.comb += events["crc"].eq(1)
                with m.Elif(self.o.valid & ~self.o.ready):
                    m.d.comb += events["dropped"].eq(1)
                with m.Else():
                    m.d.sync += [self.o.valid.eq(1), self.o.payload.command.eq(command),
                                 self.o.payload.length.eq(length), rbank.eq(wbank), wbank.eq(~wbank)]
                m.next = "hunt"
        for name, event in events.items():
            _saturating_increment(m, self.counters[name], event)
        _saturating_increment(m, self.counters.framing, self.framing_error)
        _saturating_increment(m, self.counters.overrun, self.overrun)
        return m


class FrameTransmitter(wiring.Component):
    """Answer frames onto a byte stream: ``SYNC LEN CMD PAYLOAD CRC_HI CRC_LO``.

    An answer is a header on ``i`` (answer code and payload length), then its payload bytes,
    pulled one at a time: ``index`` says which byte ``data`` must carry next.

    Parameters
    ----------
    max_payload : int
        Largest answer payload (default: the protocol's largest answer).

    Attributes
    ----------
    i : In(stream.Signature(frame_layout(max_payload)))
        Answer headers; taken when the previous frame's last byte is on ``o``.
    data : In(stream.Signature(8))
        Payload bytes of the answer being sent, byte ``index`` first.
    index : Out(range(max_payload))
        Index of the payload byte wanted on ``data``.
    o : Out(stream.Signature(8))
        Frame bytes, registered.

    Latency
    -------
    SYNC is on ``o`` one cycle after the header is taken; each further byte one cycle after the
    previous one is taken (and, for payload bytes, ``data`` is valid), except CRC_HI: two cycles
    after the last covered byte is taken (the CRC takes bytes as they leave).

    Throughput
    ----------
    A frame of LEN payload bytes takes LEN + 6 cycles when ``o`` is always ready and ``data``
    always valid; the next header is taken in the cycle CRC_LO is taken.
    """

    def __init__(self, max_payload: int | None = None):
        top = max(max(P.answer_lengths(c)) for c in P.COMMANDS) if max_payload is None else max_payload
        if not isinstance(top, int) or isinstance(top, bool) or not 1 <= top <= P.MAX_PAYLOAD:
            raise ValueError(f"max_payload must be an integer in [1, {P.MAX_PAYLOAD}], not {max_payload!r}")
        self._max = top
        super().__init__({
            "i": In(stream.Signature(frame_layout(top))), "data": In(stream.Signature(8)),
            "index": Out(range(top)), "o": Out(stream.Signature(8)),
        })

    @property
    def max_payload(self) -> int:
        return self._max

    def elaborate(self, platform):
        m = Module()
        m.submodules.crc = gen = crc_processor()
        length = Signal(range(self._max + 1))
        command = Signal(8)
        free = ~self.o.valid | self.o.ready       # the output register can take a byte

        feed = Signal()     # o.payload is a frame byte the CRC covers (LEN, CMD, payload)
        # the CRC takes each covered byte as it leaves o, so it needs no multiplexer of its own
        m.d.comb += [gen.data.eq(self.o.payload), gen.valid.eq(self.o.valid & self.o.ready & feed)]

        def send(value, covered=True):
            m.d.sync += [self.o.valid.eq(1), self.o.payload.eq(value), feed.eq(covered)]

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.FSM():
            with m.State("idle"):
                m.d.comb += self.i.ready.eq(free)
                with m.If(self.i.valid & free):
                    send(P.SYNC, covered=False)
                    m.d.comb += gen.start.eq(1)
                    m.d.sync += [command.eq(self.i.payload.command), length.eq(self.i.payload.length)]
                    m.next = "len"
            with m.State("len"):
                with m.If(free):
                    send(length)
                    m.next = "cmd"
            with m.State("cmd"):
                with m.If(free):
                    send(command)
                    m.d.sync += self.index.eq(0)
                    m.next = "payload"
                    with m.If(length == 0):
                        m.next = "crc_hi"
            with m.State("payload"):
                m.d.comb += self.data.ready.eq(free)
                with m.If(self.data.valid & free):
                    send(self.data.payload)
                    m.d.sync += self.index.eq(self.index + 1)
                    with m.If(self.index == length - 1):
                        m.next = "crc_hi"
            with m.State("crc_hi"):
                with m.If(~self.o.valid):      # the last covered byte has left: the CRC is complete
                    send(gen.crc[8:], covered=False)
                    m.next = "crc_lo"
            with m.State("crc_lo"):
                with m.If(free):
                    send(gen.crc[:8], covered=False)
                    m.next = "idle"
        return m


class Link(wiring.Component):
    """The host link on two pins: :class:`~ikseries.hdl.uart.UARTRx` into a
    :class:`FrameReceiver`, a :class:`FrameTransmitter` into a :class:`~ikseries.hdl.uart.UARTTx`.

    Parameters
    ----------
    shape : ikseries.hdl.protocol.Shape
        The robot (request lengths).
    divisor : int
        Clock cycles per bit (:func:`ikseries.hdl.uart.uart_divisor`).
    counter_bits : int
        The receiver's counter width.

    Attributes
    ----------
    rx : In(1)
        Serial input pin (from the host).
    tx : Out(1)
        Serial output pin (to the host), registered; idle high from reset.
    request, rd_addr, rd_data, counters
        The receiver's ``o``, ``rd_addr``, ``rd_data`` and ``counters``.
    answer, answer_data, answer_index
        The transmitter's ``i``, ``data`` and ``index``.

    Latency
    -------
    ``request.valid`` rises ``latency`` cycles (the UART receiver's plus the frame receiver's)
    after the start edge of the frame's last byte on ``rx``.

    Throughput
    ----------
    The line rate both ways (one byte per 10 bit times); answers wait while the UART sends.
    """

    def __init__(self, shape: P.Shape, divisor: int, counter_bits: int = P.COUNTER_BITS):
        self._rx, self._tx = UARTRx(divisor), UARTTx(divisor)
        self._receiver, self._transmitter = FrameReceiver(shape, counter_bits), FrameTransmitter()
        r, t = self._receiver, self._transmitter
        super().__init__({
            "rx": In(1, init=1), "tx": Out(1, init=1),
            "request": Out(stream.Signature(frame_layout(r.max_payload))), "rd_addr": In(r.addr_bits), "rd_data": Out(8),
            "counters": Out(counters_layout(counter_bits)),
            "answer": In(stream.Signature(frame_layout(t.max_payload))), "answer_data": In(stream.Signature(8)),
            "answer_index": Out(range(t.max_payload)),
        })

    @property
    def receiver(self) -> FrameReceiver:
        return self._receiver

    @property
    def transmitter(self) -> FrameTransmitter:
        return self._transmitter

    @property
    def latency(self) -> int:
        return self._rx.latency + self._receiver.latency

    def elaborate(self, platform):
        m = Module()
        rx, tx, r, t = self._rx, self._tx, self._receiver, self._transmitter
        m.submodules.uart_rx, m.submodules.uart_tx = rx, tx
        m.submodules.receiver, m.submodules.transmitter = r, t
        wiring.connect(m, rx.o, r.i)
        wiring.connect(m, t.o, tx.i)
        wiring.connect(m, r.o, wiring.flipped(self.request))
        wiring.connect(m, wiring.flipped(self.answer), t.i)
        wiring.connect(m, wiring.flipped(self.answer_data), t.data)
        m.d.comb += [rx.rx.eq(self.rx), self.tx.eq(tx.tx), r.framing_error.eq(rx.framing_error),
                     r.overrun.eq(rx.overrun), r.rd_addr.eq(self.rd_addr), self.rd_data.eq(r.rd_data),
                     self.counters.eq(r.counters), self.answer_index.eq(t.index)]
        return m
