"""The frame receiver's check, shared by ``tests/test_link.py`` and ``bench/link_fuzz.py``.

Random request traffic (:func:`random_request`, :func:`mixed_stream`), the hardware receiver
simulated on it at the byte-stream level (:func:`simulate_receiver`) and the host parser's
verdict on the same bytes (:func:`model_receiver`), the reference the simulation must equal.
"""
from __future__ import annotations

import random

from amaranth.sim import Simulator

from .hdl import protocol as P
from .hdl.link import FrameReceiver
from .host.protocol import encode, field_bounds, request_parser

__all__ = ["BIT_STEPS", "random_values", "random_request", "corrupt", "mixed_stream", "random_pauses", "model_receiver",
           "simulate_receiver", "frame_gap"]


#: cycles the bench spends on a byte's bits before the byte (one each, as a UART samples them)
BIT_STEPS = 8


def frame_gap(shape: P.Shape) -> int:
    """Cycles between bytes fed to the receiver so that the bench's consumer (reading a payload
    byte a cycle, then taking the frame) is done before the shortest next frame (5 bytes) ends;
    each byte's bits take :data:`BIT_STEPS` cycles before it and the receiver takes each byte
    after SYNC in its second cycle. A UART delivers a byte only every 10 bit times, far slower."""
    held = 5 * BIT_STEPS + 4
    return max(1, -(-(P.max_request_payload(shape) + 4 - held) // 5))


def _value(rng: random.Random, f: P.Field, shape: P.Shape, corner: bool):
    lo, hi, _ = field_bounds(f, shape)
    pick = (lambda: rng.choice((lo, hi))) if corner else (lambda: rng.randint(lo, hi))
    return pick()


def random_values(rng: random.Random, cmd: P.Command, shape: P.Shape, corner: bool = False) -> dict:
    """Random in-range request field values of ``cmd`` (``corner``: each at an end of its range)."""
    values = {}
    for f in cmd.request:
        n = f.elements(shape)
        if f.per is not None:
            k = bin(values[f.per]).count("1")
            values[f.name] = [[_value(rng, f, shape, corner) for _ in range(n)] for _ in range(k)]
        elif f.count == 1:
            values[f.name] = _value(rng, f, shape, corner)
        else:
            values[f.name] = [_value(rng, f, shape, corner) for _ in range(n)]
    return values


def random_request(rng: random.Random, shape: P.Shape) -> bytes:
    cmd = rng.choice(P.COMMANDS)
    return encode(cmd.name, shape, **random_values(rng, cmd, shape, corner=rng.random() < 0.2))


def corrupt(rng: random.Random, frame: bytes, shape: P.Shape) -> bytes:
    """``frame`` with a flipped bit, truncated, with another LEN or with a CMD that is no request code."""
    kind = rng.randrange(4)
    if kind == 0:       # a flipped bit anywhere after SYNC
        i = rng.randrange(1, len(frame))
        return frame[:i] + bytes((frame[i] ^ (1 << rng.randrange(8)),)) + frame[i + 1:]
    if kind == 1:       # truncated
        return frame[:rng.randrange(1, len(frame))]
    if kind == 2:       # another length
        return frame[:1] + bytes((rng.randrange(P.max_request_payload(shape) + 2),)) + frame[2:]
    codes = {c.code for c in P.COMMANDS}
    return frame[:2] + bytes((rng.choice([b for b in range(256) if b not in codes]),)) + frame[3:]


def mixed_stream(rng: random.Random, shape: P.Shape, nbytes: int) -> bytes:
    """About ``nbytes`` of valid requests (half the frames), corrupted ones (flipped bit,
    truncated, other length, unknown command) and random garbage (SYNC bytes included)."""
    out = bytearray()
    while len(out) < nbytes:
        r = rng.random()
        if r < 0.5:
            out += random_request(rng, shape)
        elif r < 0.85:
            out += corrupt(rng, random_request(rng, shape), shape)
        else:
            out += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 12)))
    return bytes(out)


def random_pauses(rng: random.Random, nbytes: int, every: int) -> list[int]:
    """Sorted distinct byte positions of ``nbytes``, about one per ``every``: a pause longer than
    the receive timeout comes before each."""
    return sorted(rng.sample(range(nbytes), nbytes // every))


def model_receiver(shape: P.Shape, data: bytes, pauses=()) -> tuple[list[tuple[int, bytes]], dict]:
    """The frames and counters the protocol's rules give for ``data`` with a timeout pause before
    each byte position in ``pauses`` (the host parser)."""
    parser = request_parser(shape)
    frames, last = [], 0
    for k in [*pauses, len(data)]:
        frames += parser.feed(data[last:k])
        if k < len(data):
            parser.pause()
        last = k
    return frames, {k: v for k, v in parser.counters.items() if k != "garbage"}


def simulate_receiver(shape: P.Shape, data: bytes, gap: int | None = None, framing_pulses: int = 0,
                      overrun_pulses: int = 0, hold: bool = False, counter_bits: int = P.COUNTER_BITS,
                      pauses=()) -> dict:
    """Feed ``data`` to a :class:`~ikseries.hdl.link.FrameReceiver`, each byte's bits on its
    ``bit_strobe``/``bit_value`` (a cycle each, least significant first) then the byte, the
    next ``gap`` cycles after it is taken (default :func:`frame_gap`), while a consumer reads
    each frame's payload through ``rd_addr``/``rd_data`` and takes it (``hold``: never takes one). Before each byte position
    in ``pauses`` the receiver's ``tick`` is held high for its ``timeout_ticks`` cycles (a pause
    that ends a frame); it is low otherwise. Then pulses the UART error inputs as asked, 8
    cycles apart. ``counter_bits``: the receiver's counter width.

    Returns ``frames`` ([(command, payload)], in order), ``counters`` (name -> value, read
    through ``counter_addr``/``counter_data``) and ``cycles``.
    """
    dut = FrameReceiver(shape, counter_bits)
    gap = frame_gap(shape) if gap is None else gap
    pauses = set(pauses)
    frames, result = [], {}
    sim = Simulator(dut)
    sim.add_clock(1e-6)

    async def producer(ctx):
        cycles = 0
        for k, b in enumerate(data):
            if k in pauses:
                ctx.set(dut.tick, 1)
                await ctx.tick().repeat(dut.timeout_ticks)
                ctx.set(dut.tick, 0)
                cycles += dut.timeout_ticks
            ctx.set(dut.bit_strobe, 1)
            for j in range(BIT_STEPS):      # the CRC takes the bits as a UART samples them
                ctx.set(dut.bit_value, b >> j & 1)
                await ctx.tick()
            ctx.set(dut.bit_strobe, 0)
            cycles += BIT_STEPS
            ctx.set(dut.i.payload, b)
            ctx.set(dut.i.valid, 1)
            while True:
                *_, ready = await ctx.tick().sample(dut.i.ready)
                cycles += 1
                if ready:
                    break
            ctx.set(dut.i.valid, 0)
            if gap > 1:
                await ctx.tick().repeat(gap - 1)
                cycles += gap - 1
        for k in range(max(framing_pulses, overrun_pulses)):
            ctx.set(dut.framing_error, k < framing_pulses)
            ctx.set(dut.overrun, k < overrun_pulses)
            await ctx.tick()
            ctx.set(dut.framing_error, 0)
            ctx.set(dut.overrun, 0)
            await ctx.tick().repeat(7)
            cycles += 8
        await ctx.tick().repeat(4 * gap + 16)      # the counters: at most 10 cycles behind
        counters = {}
        for k, name in enumerate(P.RECEIVER_COUNTERS):
            ctx.set(dut.counter_addr, k)
            await ctx.tick()
            counters[name] = ctx.get(dut.counter_data)
        result["counters"] = counters
        result["cycles"] = cycles + 4 * gap + 16 + len(P.RECEIVER_COUNTERS)

    async def consumer(ctx):
        while not hold and "counters" not in result:
            await ctx.tick()
            if not ctx.get(dut.o.valid):
                continue
            command, length = ctx.get(dut.o.payload.command), ctx.get(dut.o.payload.length)
            payload = bytearray()
            for a in range(length):
                ctx.set(dut.rd_addr, a)
                await ctx.tick()
                payload.append(ctx.get(dut.rd_data))
            frames.append((command, bytes(payload)))
            ctx.set(dut.o.ready, 1)
            await ctx.tick()
            ctx.set(dut.o.ready, 0)

    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    sim.run()
    return {"frames": frames, **result}
