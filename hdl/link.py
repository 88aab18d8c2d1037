"""The controller's host link in hardware: frame receiver, frame transmitter, and both on a UART.

Frame format, CRC and command lengths come from :mod:`ikseries.hdl.protocol`.
"""
from __future__ import annotations

from amaranth.hdl import Cat, ClockDomain, ClockSignal, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from . import protocol as P
from .uart import UARTRx, UARTTx

__all__ = ["SerialCRC", "FrameReceiver", "FrameTransmitter", "Link", "frame_layout", "UPTIME_WORD",
           "CLAMPED_WORD"]


class SerialCRC(wiring.Component):
    """The protocol's CRC a bit per step, least significant bit of each byte first: the order
    the UART's bits cross the line, so it steps on the UART's own bit strobes
    (:class:`~ikseries.hdl.uart.UARTRx` and :class:`~ikseries.hdl.uart.UARTTx` ``bit_strobe``).

    Sixteen flip-flops, each with the LUT of its next value: no byte multiplexer, no count of
    the steps of a byte, and a frame byte is taken the cycle it comes.

    Parameters
    ----------
    params : ikseries.hdl.protocol.CRCParameters
        A reflected CRC (input and output) of whole bytes without output xor (so that the CRC
        over a message and its CRC, sent low byte first, is 0).

    Attributes
    ----------
    start : In(1)
        Load the initial value (wins over ``step``).
    step : In(1)
        Take ``bit``.
    bit : In(1)
        The next bit of the message.
    crc : Out(width)
        The register: the CRC of the bits taken so far (for whole bytes, the protocol's).

    Latency
    -------
    ``crc`` includes a bit one cycle after its step.

    Throughput
    ----------
    One bit per cycle.
    """

    def __init__(self, params: P.CRCParameters = P.CRC):
        if not (params.reflect_input and params.reflect_output) or params.xor_output or params.width % 8:
            raise ValueError("params must be a reflected CRC of whole bytes without output xor, "
                             f"not {params.name!r}")
        self._params = params
        super().__init__({"start": In(1), "step": In(1), "bit": In(1), "crc": Out(params.width, init=params.initial)})

    def elaborate(self, platform):
        m = Module()
        p = self._params
        # start always comes before the first step: no reset needed
        r = Signal(p.width, init=p.initial, reset_less=True)
        m.d.comb += self.crc.eq(r)
        poly = int(f"{p.polynomial:0{p.width}b}"[::-1], 2)      # the polynomial reflected
        feedback = r[0] ^ self.bit
        shifted = Cat(*((r[i + 1] if i + 1 < p.width else 0) ^ (feedback if (poly >> i) & 1 else 0)
                        for i in range(p.width)))
        with m.If(self.start):
            m.d.sync += r.eq(p.initial)
        with m.Elif(self.step):
            m.d.sync += r.eq(shifted)
        return m


def frame_layout(max_payload: int) -> data.StructLayout:
    """A frame's command (or answer) code and payload length."""
    return data.StructLayout({"command": 8, "length": range(max_payload + 1)})


def _write_domain(m):
    """A write clock domain on the falling edge of ``sync``, named ``"write"``.

    A block RAM port pair on one clock edge makes Yosys guard every non-transparent read port
    against a same-cycle write to its address with a bypass register and multiplexer (for a
    16-bit word, 19 flip-flops and 16 LUTs a port on iCE40): writing on the other edge leaves
    nothing to guard. The write's address, data and enable must settle in half a cycle.
    """
    m.domains.write = ClockDomain("write", clk_edge="neg", local=True, reset_less=True)
    m.d.comb += ClockSignal("write").eq(ClockSignal("sync"))
    return "write"


#: word of the uptime's low half in the counter memory (its high half is the next word)
UPTIME_WORD = len(P.RECEIVER_COUNTERS)
#: word of the controller's ``clamped`` count (the dispatcher's event), after the uptime
CLAMPED_WORD = UPTIME_WORD + 2
#: the counter whose scan slot ``clamped`` shares, a round each: both come at most once per
#: frame (a bad CRC) or per leg target (a clamp), far more than 16 cycles apart
_SHARED_WORD = P.RECEIVER_COUNTERS.index("crc")


def _counter_engine(m, events, period, clamped, counter_bits, write_domain):
    """Saturating counters of ``events`` (one-cycle pulses) and of ``clamped`` in a block RAM, one
    shared incrementer, and the uptime: pulses of ``period`` in words ``UPTIME_WORD`` and the
    next, low half first (the low word wraps into the high one; the pair saturates).

    A scan reads one word a cycle and, if its event is pending, writes it back incremented half a
    cycle after the next edge (on ``write_domain``, from registers: the read, the incrementer and
    the write in half a cycle made 28 MHz). Its eight slots serve words 0 .. 7 each round, but
    slot ``_SHARED_WORD`` serves that word and ``CLAMPED_WORD`` on alternate rounds: a counter's
    event may come once per 8 cycles and shows on the outside port 10 cycles later at most; the
    ``crc`` and ``clamped`` events once per 16 cycles, 18 cycles later at most (a carry into the
    uptime's high word 1 cycle after its low word: the scan reads it next). Returns the memory's
    read port for the outside. After a reset the first nine slots write zeros (the configured
    contents are zero too).
    """
    words = CLAMPED_WORD + 1
    low, high = UPTIME_WORD, UPTIME_WORD + 1
    assert len(events) == low and high == 7 and _SHARED_WORD == 0
    # a small memory: Yosys would build it of flip-flops, the very cells this saves
    m.submodules.counters = mem = Memory(shape=counter_bits, depth=words, init=[], attrs={"ram_style": "block"})
    wr, scan_rd, outside = mem.write_port(domain=write_domain), mem.read_port(), mem.read_port()
    slot = Signal(4)                            # a round of eight slots and which round
    held = Signal(range(words))                 # word read last cycle
    addr = Cat(slot[:3], slot[3] & (slot[:3] == _SHARED_WORD))    # CLAMPED_WORD is 8
    clearing = Signal(init=1)
    pending = Signal(words)
    high_full = Signal()        # the uptime's high word is all ones: its low word saturates too
    total = scan_rd.data + 1
    m.d.sync += [slot.eq(slot + 1), held.eq(addr)]
    # slots 0 .. 8 after reset write every word once (a second write would lose a counted event)
    with m.If(held == CLAMPED_WORD):
        m.d.sync += clearing.eq(0)
    hit = pending.bit_select(held, 1)
    over = total[counter_bits]
    # the incremented word's carry out is set only for an all-ones (saturated) word; the
    # clearing scan writes 1 for a pending event: an event waits at most 16 cycles, reset or not
    wraps = (held == low) & ~high_full
    carry = ~clearing & hit & over & wraps
    m.d.sync += [wr.addr.eq(held), wr.data.eq(Mux(clearing, hit, total[:counter_bits])),
                 wr.en.eq(clearing | (hit & (~over | wraps)))]
    m.d.comb += scan_rd.addr.eq(addr)
    with m.If(clearing):
        m.d.sync += high_full.eq(0)
    # the incremented word all ones: its read one below (the incrementer's sum then drives
    # only the write register, and shares its cells)
    with m.Elif((held == high) & hit & (scan_rd.data == (1 << counter_bits) - 2)):
        m.d.sync += high_full.eq(1)
    served = Cat(*(held == k for k in range(words)))
    m.d.sync += pending.eq((pending & ~served) | Cat(*events, period, carry, clamped))
    return outside


class FrameReceiver(wiring.Component):
    """Validated request frames out of a byte stream.

    Follows the receiving rules of ``docs/protocol.md``: hunts for SYNC; refuses a LEN above the
    largest request and a LEN the command does not take, or an unknown command, as soon as that
    byte arrives (a refused byte equal to SYNC starts the next frame); then takes LEN payload
    bytes and the CRC; a pause of more than ``RX_TIMEOUT_BYTES`` byte times (``timeout_ticks``
    pulses of ``tick`` without a byte) abandons the frame. Payload bytes go into a two-bank
    block RAM: the bank of the frame on ``o`` is read through ``rd_addr``/``rd_data`` while the
    next frame fills the other, so a frame is offered only once its CRC is good (an atomic
    multi-leg move is never half applied). The CRC is taken a bit at a time from the UART's bit
    strobes (``bit_strobe``, ``bit_value``), so a byte's bits are in it when the byte comes. The
    command/length check is a block RAM table and the error counters live in a block RAM too,
    with the controller's uptime (``period`` pulses) (Yosys gives it two copies, one a read
    port): four iCE40 block RAMs in all, written on the falling clock edge.

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
        Received bytes. While hunting a byte is taken at once; inside a frame in its second cycle
        (the length table's read). Bytes must come at least 4 cycles apart (a UART's come 40
        and more), so that no counter's events come closer than the counter engine serves them.
    bit_strobe, bit_value : In(1)
        The bits of the bytes on ``i`` as the UART samples them
        (:class:`~ikseries.hdl.uart.UARTRx` ``bit_strobe`` and ``bit_value``), least significant
        first: a byte's bits come before the byte, and the bits of the frame's next byte after
        it is taken. The CRC starts with the byte after SYNC.
    framing_error, overrun : In(1)
        The UART's error pulses, counted; at most one per 8 cycles each (a UART gives one per byte).
    tick : In(1)
        Pulses counted towards the timeout (:attr:`~ikseries.hdl.uart.UARTRx.idle_tick`: one per
        bit time of idle line); restarted by every byte taken.
    o : Out(stream.Signature(frame_layout(max_payload)))
        Good frames: command code and payload length. Held until taken.
    rd_addr : In(addr_bits)
        Payload byte index of the frame on ``o``.
    rd_data : Out(8)
        That byte, one cycle after ``rd_addr`` (a block RAM read). Valid while ``o.valid``.
    counter_addr : In(range(CLAMPED_WORD + 1))
        Index of an error counter in :data:`~ikseries.hdl.protocol.RECEIVER_COUNTERS`: ``crc``,
        ``framing``, ``overrun``, ``bad_length``, ``unknown_command``, ``dropped`` (a good frame
        completed while ``o`` still held the previous one, untaken by the end of the new one's
        CRC check); then the uptime's low and high words (:data:`UPTIME_WORD`), then the
        ``clamped`` count (:data:`CLAMPED_WORD`).
    period : In(1)
        Pulses counted in the uptime (the controller's PWM period starts; at most one per 8 cycles).
    clamped : In(1)
        Pulses counted in word ``CLAMPED_WORD`` (the dispatcher's clamped leg targets; at most one
        per 16 cycles, like ``crc`` events, whose scan slot it shares).
    counter_data : Out(counter_bits)
        That counter, one cycle after ``counter_addr`` (a block RAM read); saturating, zero from
        reset, up to 10 cycles behind its event (18 for ``crc`` and ``clamped``; the uptime,
        ``2 * counter_bits`` bits in two words, saturates as one).

    Latency
    -------
    ``o.valid`` rises :attr:`latency` cycles after the frame's last byte is valid on ``i``.

    Throughput
    ----------
    One byte per cycle while hunting, one per 2 cycles inside a frame (but see ``i``), plus two
    cycles after each frame's last byte.
    """

    #: pulses of ``tick`` that abandon a frame: with one per idle bit time, a pause of at most
    #: RX_TIMEOUT_BYTES byte times never does and one of a byte time more always does
    timeout_ticks = P.BYTE_BITS * P.RX_TIMEOUT_BYTES + P.BYTE_BITS // 2
    #: cycles from the frame's last byte valid on ``i`` to ``o.valid`` (the byte taken in its
    #: second cycle, the CRC checked as it is taken, the offer)
    latency = 3

    def __init__(self, shape: P.Shape, counter_bits: int = P.COUNTER_BITS):
        if not isinstance(shape, P.Shape):
            raise TypeError(f"shape must be an ikseries.hdl.protocol.Shape, not {shape!r}")
        if (not isinstance(counter_bits, int) or isinstance(counter_bits, bool)
                or not 1 <= counter_bits <= P.COUNTER_BITS):
            raise ValueError(f"counter_bits must be an integer in [1, {P.COUNTER_BITS}], not {counter_bits!r}")
        self._shape = shape
        self._counter_bits = counter_bits
        self._lengths = {c.code: sorted(P.request_lengths(c, shape)) for c in P.COMMANDS}
        self._max = P.max_request_payload(shape)
        self._addr_bits = max(1, (self._max - 1).bit_length())
        super().__init__({
            "i": In(stream.Signature(8)), "bit_strobe": In(1), "bit_value": In(1),
            "framing_error": In(1), "overrun": In(1), "tick": In(1),
            "o": Out(stream.Signature(frame_layout(self._max))),
            "rd_addr": In(self._addr_bits), "rd_data": Out(8),
            "counter_addr": In(range(CLAMPED_WORD + 1)), "counter_data": Out(counter_bits), "period": In(1),
            "clamped": In(1),
        })

    @property
    def max_payload(self) -> int:
        return self._max

    @property
    def addr_bits(self) -> int:
        return self._addr_bits

    def _length_check(self, m, code, length):
        """(known, length_ok) of command byte ``code`` with payload length ``length``.

        ``length_ok`` is a bit of a block RAM table addressed by the code's low bits and the
        length (a LUT tree of every command's lengths cost 50 LUTs), valid one cycle after
        ``code`` and ``length`` are; ``known`` is logic (in the table it saved 2 LUTs for a
        second block RAM).
        """
        code_bits = max(self._lengths).bit_length()
        length_bits = self._max.bit_length()
        table = [0] * (1 << (code_bits + length_bits))
        for c, lengths in self._lengths.items():
            for n in lengths:
                table[c << length_bits | n] = 1
        m.submodules.lengths = rom = Memory(shape=1, depth=len(table), init=table, attrs={"ram_style": "block"})
        read = rom.read_port()
        m.d.comb += read.addr.eq(Cat(length, code[:code_bits]))
        return Cat(*(code == c for c in self._lengths)).any(), read.data

    def _timeout(self, m, take):
        """True once ``timeout_ticks`` ticks came without a byte taken.

        The count is a 6-bit XNOR shift register (period 63; zero, its reset value, is a state
        of it): one LUT of feedback instead of a 6-bit adder.
        """
        assert self.timeout_ticks < 63
        state, expired_at = Signal(6), 0
        for _ in range(self.timeout_ticks):
            expired_at = (expired_at << 1 | (1 ^ (expired_at >> 5 & 1) ^ (expired_at >> 4 & 1))) & 0x3F
        expired = state == expired_at
        with m.If(take):
            m.d.sync += state.eq(0)
        with m.Elif(self.tick & ~expired):
            m.d.sync += state.eq(Cat(~(state[5] ^ state[4]), state[:5]))
        return expired

    def elaborate(self, platform):
        m = Module()
        m.submodules.crc = check = SerialCRC()
        write = _write_domain(m)
        bank = 1 << self._addr_bits
        m.submodules.mem = mem = Memory(shape=8, depth=2 * bank, init=[])
        wr, rd = mem.write_port(domain=write), mem.read_port()
        wbank, rbank = Signal(), Signal()
        length = Signal(range(self._max + 1))
        command = Signal(8)
        index = Signal(range(self._max + 1))
        byte = self.i.payload
        take_command = Signal()     # the CMD byte is good: keep it
        known, length_ok = self._length_check(m, byte, length)
        events = {name: Signal(name=f"{name}_event") for name in P.RECEIVER_COUNTERS}
        m.d.comb += [events["framing"].eq(self.framing_error), events["overrun"].eq(self.overrun)]
        counters = _counter_engine(m, [events[name] for name in P.RECEIVER_COUNTERS], self.period,
                                   self.clamped, self._counter_bits, write)
        m.d.comb += [counters.addr.eq(self.counter_addr), self.counter_data.eq(counters.data)]
        m.d.comb += [rd.addr.eq(Cat(self.rd_addr, rbank)), self.rd_data.eq(rd.data),
                     wr.addr.eq(Cat(index[:self._addr_bits], wbank)), wr.data.eq(byte),
                     check.step.eq(self.bit_strobe), check.bit.eq(self.bit_value)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        good = self._frame_fsm(m, check, wr, events, (known, length_ok), length, index, take_command)
        with m.If(good):
            m.d.sync += [self.o.valid.eq(1), self.o.payload.command.eq(command),
                         self.o.payload.length.eq(length), rbank.eq(wbank), wbank.eq(~wbank)]
        with m.If(take_command):
            m.d.sync += command.eq(byte)
        return m

    def _frame_fsm(self, m, check, wr, events, command_check, length, index, take_command):
        """The receiving rules, byte by byte; returns a pulse: a good frame to offer on ``o``."""
        known, length_ok = command_check
        byte, good = self.i.payload, Signal()
        hunting = Signal()
        # inside a frame a byte is taken in its second cycle: the length table's read of it is
        # out then, and the payload write comes from a register (set in the byte's first cycle)
        second = Signal()
        take = self.i.valid & self.i.ready
        m.d.comb += self.i.ready.eq(hunting | second)
        m.d.sync += [second.eq(self.i.valid & ~take), wr.en.eq(0)]
        expired = self._timeout(m, take)

        def refuse(counter):
            m.d.comb += events[counter].eq(1)
            m.next = "hunt"
            with m.If(byte == P.SYNC):      # the refused byte may be the next frame's start
                m.d.comb += check.start.eq(1)
                m.next = "len"

        def frame_state():
            """A state inside a frame: its byte is taken in its second cycle."""
            with m.If(expired):
                m.next = "hunt"
            return m.If(~expired & take)

        # the body state takes the first CRC byte too (index == length); these take the rest,
        # the last checked as it is taken (its bits are in the CRC already)
        crc_states = [f"crc{k}" for k in range(1, P.CRC.width // 8)]
        with m.FSM():
            with m.State("hunt"):
                m.d.comb += hunting.eq(1)
                with m.If(take & (byte == P.SYNC)):
                    m.d.comb += check.start.eq(1)
                    m.next = "len"
            with m.State("len"):
                with frame_state():
                    with m.If(byte > self._max):
                        refuse("bad_length")
                    with m.Else():
                        m.d.sync += length.eq(byte)
                        m.next = "cmd"
            with m.State("cmd"):
                with frame_state():
                    with m.If(~known):
                        refuse("unknown_command")
                    with m.Elif(~length_ok):
                        refuse("bad_length")
                    with m.Else():
                        m.d.comb += take_command.eq(1)
                        m.d.sync += index.eq(0)
                        m.next = "body"
            with m.State("body"):
                # registered in the byte's first cycle: the write (half a cycle after the edge)
                # then comes straight from flip-flops, in the cycle the byte is taken
                with m.If(self.i.valid & ~second & (index != length)):
                    m.d.sync += wr.en.eq(1)
                with frame_state():
                    m.d.sync += index.eq(index + 1)
                    with m.If(index == length):
                        m.next = crc_states[0]
            for name, after in zip(crc_states, crc_states[1:] + ["offer"]):
                with m.State(name):
                    with frame_state():
                        m.next = after
                        if after == "offer":        # the CRC register has taken the last byte
                            with m.If(check.crc != 0):
                                m.d.comb += events["crc"].eq(1)
                                m.next = "hunt"
            # a cycle later, so that whether the previous frame is still offered is a register
            # (o.valid, cleared by a transfer in the check cycle), not the dispatcher's ready
            with m.State("offer"):
                with m.If(self.o.valid):
                    m.d.comb += events["dropped"].eq(1)
                with m.Else():
                    m.d.comb += good.eq(1)
                m.next = "hunt"
        return good


class FrameTransmitter(wiring.Component):
    """Answer frames onto a byte stream: ``SYNC LEN CMD PAYLOAD CRC_LO CRC_HI``.

    An answer is a header on ``i`` (answer code and payload length), then its payload bytes,
    pulled one at a time from a source that counts them (``index``): it keeps the count the
    transmitter would otherwise keep a copy of.

    Parameters
    ----------
    max_payload : int
        Largest answer payload (default: the protocol's largest answer).

    Attributes
    ----------
    i : In(stream.Signature(frame_layout(max_payload)))
        Answer headers; taken when the previous frame's last byte is on ``o``. The length is
        registered as the header is taken; the code is read when CMD is sent: the source holds
        ``i.payload.command`` from the header's transfer until ``done`` (no copy here).
    data : In(stream.Signature(8))
        Payload bytes of the answer being sent, in order.
    index : In(range(max_payload + 1))
        The source's count of payload bytes taken on ``data`` since the header was taken (0
        then, one more the cycle after each transfer): the payload ends when it reaches the
        length.
    done : Out(1)
        High for one cycle as the payload ends (its last byte taken; at once for an empty one):
        a source that stops offering then needs no count of its own.
    o : Out(stream.Signature(8))
        Frame bytes, registered.
    bit_strobe, bit_value : In(1)
        The bits of the bytes on ``o`` as the UART sends them (:class:`~ikseries.hdl.uart.UARTTx`
        ``bit_strobe`` and ``bit_value``), least significant first: the CRC takes every one
        (it restarts with LEN), so a byte's bits must all have come when it is taken, as a
        UART that takes a byte at its stop bit does.

    Latency
    -------
    SYNC is on ``o`` one cycle after the header is taken; every later byte one cycle after the
    previous one is taken, for payload bytes once ``data`` is valid.

    Throughput
    ----------
    A frame of LEN payload bytes takes LEN + 6 cycles from the header taken to CRC_HI taken when
    ``o`` is always ready and ``data`` always valid (a UART byte lasts at least 40); the next
    header is taken in the cycle CRC_HI is taken.
    """

    def __init__(self, max_payload: int | None = None):
        top = max(max(P.answer_lengths(c)) for c in P.COMMANDS) if max_payload is None else max_payload
        if not isinstance(top, int) or isinstance(top, bool) or not 1 <= top <= P.MAX_PAYLOAD:
            raise ValueError(f"max_payload must be an integer in [1, {P.MAX_PAYLOAD}], not {max_payload!r}")
        self._max = top
        super().__init__({
            "i": In(stream.Signature(frame_layout(top))), "data": In(stream.Signature(8)),
            "index": In(range(top + 1)), "done": Out(1), "o": Out(stream.Signature(8)),
            "bit_strobe": In(1), "bit_value": In(1),
        })

    @property
    def max_payload(self) -> int:
        return self._max

    def elaborate(self, platform):
        m = Module()
        m.submodules.crc = gen = SerialCRC()
        length = Signal(range(self._max + 1))
        done = self.index == length
        m.d.comb += [gen.step.eq(self.bit_strobe), gen.bit.eq(self.bit_value)]
        free = ~self.o.valid | self.o.ready     # the output register can take a byte

        def send(value):
            m.d.sync += [self.o.valid.eq(1), self.o.payload.eq(value)]

        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        crc_states = [f"crc{k}" for k in range(P.CRC.width // 8)]
        with m.FSM():
            with m.State("idle"):
                m.d.comb += self.i.ready.eq(free)
                with m.If(self.i.valid & free):
                    send(P.SYNC)
                    m.d.sync += length.eq(self.i.payload.length)
                    m.next = "len"
            with m.State("len"):
                with m.If(free):
                    # SYNC's bits are out (it was taken): the CRC starts with LEN's
                    send(length)
                    m.d.comb += gen.start.eq(1)
                    m.next = "cmd"
            with m.State("cmd"):
                with m.If(free):
                    send(self.i.payload.command)        # held by the source until ``done``
                    m.next = "payload"
            with m.State("payload"):        # until ``index`` reaches the length (at once for an empty payload)
                m.d.comb += self.data.ready.eq(free & ~done)
                with m.If(done):
                    m.d.comb += self.done.eq(1)
                    m.next = crc_states[0]
                with m.Elif(self.data.valid & free):
                    send(self.data.payload)
            # the CRC's low byte first; taking its bits shifts the CRC a byte down (a reflected
            # CRC takes its own low bit with no feedback), so the high byte is then its low byte
            for name, after in zip(crc_states, crc_states[1:] + ["idle"]):
                with m.State(name):
                    with m.If(free):
                        send(gen.crc[:8])
                        m.next = after
        return m


class Link(wiring.Component):
    """The host link on two pins: :class:`~ikseries.hdl.uart.UARTRx` into a
    :class:`FrameReceiver`, a :class:`FrameTransmitter` into a :class:`~ikseries.hdl.uart.UARTTx`.

    Parameters
    ----------
    shape : ikseries.hdl.protocol.Shape
        The robot (request lengths).
    divisor : int
        Clock cycles per bit (:func:`ikseries.hdl.uart.uart_divisor`); at least ``MIN_DIVISOR``, so
        a byte's 10 bit times (40 cycles and more) outlast the receiver's slowest byte (9 cycles).
    counter_bits : int
        The receiver's counter width.

    Attributes
    ----------
    rx : In(1)
        Serial input pin (from the host).
    tx : Out(1)
        Serial output pin (to the host), registered; idle high from reset.
    request, rd_addr, rd_data, counter_addr, counter_data, period, clamped
        The receiver's ``o``, ``rd_addr``, ``rd_data``, ``counter_addr``, ``counter_data``,
        ``period`` and ``clamped``.
    answer, answer_data, answer_index, answer_done
        The transmitter's ``i``, ``data``, ``index`` and ``done``.

    Latency
    -------
    ``request.valid`` rises ``latency`` cycles (the UART receiver's plus the frame receiver's)
    after the start edge of the frame's last byte on ``rx``.

    Throughput
    ----------
    The line rate both ways (one byte per 10 bit times); answers wait while the UART sends.
    """

    def __init__(self, shape: P.Shape, divisor: int, counter_bits: int = P.COUNTER_BITS):
        # the frame receiver takes every byte within 2 cycles, a UART bit is at least 4
        self._rx, self._tx = UARTRx(divisor, buffered=False), UARTTx(divisor)
        self._receiver, self._transmitter = FrameReceiver(shape, counter_bits), FrameTransmitter()
        r, t = self._receiver, self._transmitter
        super().__init__({
            "rx": In(1, init=1), "tx": Out(1, init=1),
            "request": Out(stream.Signature(frame_layout(r.max_payload))), "rd_addr": In(r.addr_bits), "rd_data": Out(8),
            "counter_addr": In(range(CLAMPED_WORD + 1)), "counter_data": Out(counter_bits), "period": In(1),
            "clamped": In(1), "answer": In(stream.Signature(frame_layout(t.max_payload))), "answer_data": In(stream.Signature(8)),
            "answer_index": In(range(t.max_payload + 1)), "answer_done": Out(1),
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
        # the CRCs take the bits as they cross the line
        m.d.comb += [r.bit_strobe.eq(rx.bit_strobe), r.bit_value.eq(rx.bit_value),
                     t.bit_strobe.eq(tx.bit_strobe), t.bit_value.eq(tx.bit_value)]
        wiring.connect(m, r.o, wiring.flipped(self.request))
        wiring.connect(m, wiring.flipped(self.answer), t.i)
        wiring.connect(m, wiring.flipped(self.answer_data), t.data)
        m.d.comb += [rx.rx.eq(self.rx), self.tx.eq(tx.tx), r.framing_error.eq(rx.framing_error),
                     r.overrun.eq(rx.overrun), r.tick.eq(rx.idle_tick), r.rd_addr.eq(self.rd_addr),
                     self.rd_data.eq(r.rd_data), r.counter_addr.eq(self.counter_addr),
                     self.counter_data.eq(r.counter_data), r.period.eq(self.period), r.clamped.eq(self.clamped),
                     t.index.eq(self.answer_index), self.answer_done.eq(t.done)]
        return m
