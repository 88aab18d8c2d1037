"""The output buffer of a pipeline that never stalls, with the credits that keep it from
overflowing."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Shape, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

__all__ = ["OutputBuffer"]


def _thermometer(m, name: str, n: int, up, down, full: bool) -> Signal:
    """A count 0..n as ``n`` flip-flops, bit k high while the count exceeds k, so "more than
    zero" is bit 0 straight from its flip-flop; ``up`` / ``down`` (never both) step it by one.
    ``full``: n after reset, else 0."""
    t = Signal(n, name=name, init=(1 << n) - 1 if full else 0)
    with m.If(up):
        m.d.sync += t.eq(Cat(Const(1, 1), t[:-1]))
    with m.Elif(down):
        m.d.sync += t.eq(Cat(t[1:], Const(0, 1)))
    return t


class OutputBuffer(wiring.Component):
    """A FIFO for a pipeline that cannot be stopped, and the credit count that decides when it
    may take another input.

    Every input the pipeline accepts (``promise``) is promised a word, and ``room`` is high
    while an unpromised word is left, so a word written on ``w`` always finds a place: there is
    no full flag and ``w`` has no ``ready``. Both counts (words promised and not yet read,
    words held) are thermometer codes, so ``room`` and ``o.valid`` come straight from a
    flip-flop and neither the pipeline's inputs nor its outputs see a comparison or an adder.
    The words are in a memory with an asynchronous read (LUT RAM on the ECP5), its depth
    ``depth`` rounded up to a power of two so the pointers wrap without a comparison.

    Parameters
    ----------
    layout : data layout
        The payload.
    depth : int
        Words (>= 1): the targets that may be in flight, pipeline and buffer together.

    Attributes
    ----------
    w : In(stream.Signature(layout, always_ready=True))
        A word from the pipeline, written when ``w.valid``.
    o : Out(stream.Signature(layout))
        The oldest word, first word fall through.
    promise : In(1)
        An input enters the pipeline this cycle; its word is taken from ``room``.
    room : Out(1)
        A word is neither held nor promised: the pipeline may take an input.

    Latency
    -------
    One cycle from a write on ``w`` to the word on ``o`` (when it is the oldest); one cycle
    from a read on ``o`` to its credit on ``room``.

    Throughput
    ----------
    One word a cycle in and out.
    """

    def __init__(self, layout, depth: int):
        if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
            raise ValueError(f"depth must be an integer >= 1, not {depth!r}")
        self._depth = depth
        super().__init__({
            "w": In(stream.Signature(layout, always_ready=True)),
            "o": Out(stream.Signature(layout)),
            "promise": In(1),
            "room": Out(1),
        })

    @property
    def depth(self) -> int:
        return self._depth

    def elaborate(self, platform):
        m = Module()
        words = 1 << max(0, (self._depth - 1).bit_length())
        width = Shape.cast(self.w.payload.shape()).width
        m.submodules.storage = mem = Memory(shape=width, depth=words, init=[])
        wp, rp = mem.write_port(), mem.read_port(domain="comb")
        pop = Signal()
        m.d.comb += pop.eq(self.o.valid & self.o.ready)
        credits = _thermometer(m, "credits", self._depth, pop & ~self.promise, self.promise & ~pop, True)
        held = _thermometer(m, "held", self._depth, self.w.valid & ~pop, pop & ~self.w.valid, False)
        write, read = Signal(range(words), name="write"), Signal(range(words), name="read")
        with m.If(self.w.valid):
            m.d.sync += write.eq(write + 1)
        with m.If(pop):
            m.d.sync += read.eq(read + 1)
        m.d.comb += [
            wp.addr.eq(write), wp.data.eq(self.w.payload), wp.en.eq(self.w.valid),
            rp.addr.eq(read), self.o.payload.eq(rp.data), self.o.valid.eq(held[0]),
            self.room.eq(credits[0]),
        ]
        return m
