"""The output buffer of a pipeline that never stalls, against a model of its counts."""
import numpy as np
import pytest
from amaranth.sim import Simulator

from ikseries.hdl.outbuffer import OutputBuffer


def _run(depth: int, delay: int, cycles: int, seed: int, ready_prob: float, offer_prob: float = 0.8):
    """A model pipeline of ``delay`` cycles (inputs offered at random, taken on ``room``)
    in front of the buffer, ``o.ready`` random: returns the words read and the problems seen."""
    rng = np.random.default_rng(seed)
    dut = OutputBuffer(16, depth)
    got, bad = [], []

    async def bench(ctx):
        line = [None] * delay       # words in the model pipeline, oldest last
        sent, promised = 0, 0
        for cycle in range(cycles):
            offer = rng.random() < offer_prob
            room = ctx.get(dut.room)
            if room != (promised < depth):
                bad.append(f"cycle {cycle}: room {room} with {promised} of {depth} words promised")
            ctx.set(dut.promise, offer and room)
            take = offer and room
            line.insert(0, sent if take else None)
            word = line.pop()
            ctx.set(dut.w.valid, word is not None)
            ctx.set(dut.w.payload, word or 0)
            sent += take
            promised += take
            ctx.set(dut.o.ready, rng.random() < ready_prob)
            if ctx.get(dut.o.valid) and ctx.get(dut.o.ready):
                got.append(ctx.get(dut.o.payload))
                promised -= 1
            await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return got, bad


@pytest.mark.parametrize("depth, delay", [(1, 0), (2, 0), (3, 1), (5, 3), (12, 10), (21, 19)])
def test_every_word_out_in_order_and_room_counts_the_promises(depth, delay):
    """Whatever the backpressure, every word comes out once, in order, and ``room`` is high
    exactly while fewer than ``depth`` words are promised (taken and not yet read)."""
    for seed, ready_prob in ((1, 0.3), (2, 0.9)):
        got, bad = _run(depth, delay, 400, seed, ready_prob)
        assert not bad, bad[:3]
        assert got == list(range(len(got))) and len(got) > 20


def test_delay_plus_two_words_keep_one_word_a_cycle_flowing():
    """Offered an input every cycle with ``o.ready`` always high, a buffer of the pipeline's
    delay + 2 words takes one every cycle (a word is promised for the delay, the buffer's
    cycle and the credit's return); one word fewer, and it cannot."""
    got, bad = _run(21, 19, 300, 3, 1.0, offer_prob=1.0)
    assert not bad and len(got) == 300 - 19 - 1
    got_short, bad = _run(20, 19, 300, 3, 1.0, offer_prob=1.0)
    assert not bad and len(got_short) < len(got)


def test_bad_depth():
    with pytest.raises(ValueError, match=r"^depth must be an integer >= 1, not 0$"):
        OutputBuffer(8, 0)
