"""The XNOR shift-register countdown (hdl/lfsr.py) against a plain counter."""
import random

import pytest
from amaranth.hdl import Module, Signal
from amaranth.sim import Simulator

from ikseries.hdl.lfsr import XNOR_TAPS, countdown, lfsr_after, lfsr_bits, lfsr_step


@pytest.mark.parametrize("n", [n for n in sorted(XNOR_TAPS) if n <= 18])
def test_taps_are_maximal_length(n):
    state, seen = 0, set()
    while state not in seen:
        seen.add(state)
        state = lfsr_step(n, state)
    assert state == 0 and len(seen) == (1 << n) - 1 and (1 << n) - 1 not in seen


@pytest.mark.parametrize("n", sorted(XNOR_TAPS))
def test_after_is_the_iterated_step(n):
    rng = random.Random(n)
    for steps in [0, 1, 2, 3, 1000] + [rng.randrange(5000) for _ in range(3)]:
        state = rng.randrange((1 << n) - 1)
        want = state
        for _ in range(steps):
            want = lfsr_step(n, want)
        assert lfsr_after(n, steps, state) == want


def test_bits_are_the_shortest_register_that_does_not_repeat():
    assert lfsr_bits(0) == 3 and lfsr_bits(6) == 3 and lfsr_bits(7) == 4 and lfsr_bits(239_935) == 18
    with pytest.raises(ValueError, match=r"^steps must be below 16777215, not 16777215$"):
        lfsr_bits((1 << 24) - 1)


@pytest.mark.parametrize("cycles", [-3, 0, 1, 2, 7, 8, 40])
def test_countdown_is_since_below_cycles(cycles):
    m = Module()
    restart = Signal()
    out = Signal()
    m.d.comb += out.eq(countdown(m, restart, cycles))
    sim = Simulator(m)
    sim.add_clock(1e-6)
    rng = random.Random(cycles)

    async def bench(ctx):
        since = 0
        for _ in range(400):
            r = rng.random() < 0.03
            ctx.set(restart, r)
            assert ctx.get(out) == (since < cycles), since
            await ctx.tick()
            since = 0 if r else since + 1
    sim.add_testbench(bench)
    sim.run()
