"""ServoPWMCounters (hdl/pwmcounters.py): pulses measured on the pins against the widths sent."""
from __future__ import annotations

import random

import pytest
from amaranth.sim import Simulator

from ikseries.hdl.pwmcounters import ServoPWMCounters


def measure(dut, windows, load_at, periods, extra=0):
    """Send ``windows[k]`` (one width per channel, plus ``extra`` more) in period k's window,
    the j-th width at phase ``load_at(k, j)``; return per period (from a ``period_start`` to the
    next) each channel's (rise offset from the period start, high cycles), the cycles
    ``i.ready`` or a pin was high in the quiet period after reset, and the phases any pin was
    high in."""
    out = {"pulses": [], "ready_early": 0, "pins_early": 0, "high_phases": set()}

    async def bench(ctx):
        n, started, k, sent = dut.channels, False, -1, 0
        rise, high = [None] * n, [0] * n
        offset = 0
        for cycle in range((periods + 2) * dut.period + 2):
            if ctx.get(dut.period_start):
                if started:
                    out["pulses"].append(list(zip(rise, high)))
                started, k, sent, offset = True, k + 1, 0, 0
                rise, high = [None] * n, [0] * n
            phase = ctx.get(dut.phase)
            if cycle < dut.period:
                out["ready_early"] += ctx.get(dut.i.ready)
                out["pins_early"] += ctx.get(dut.pwm) != 0
                assert not ctx.get(dut.period_start), f"period start at cycle {cycle}"
            queue = windows[k] + [0] * extra if 0 <= k < len(windows) else []
            valid = started and sent < len(queue) and load_at(k, sent) <= phase < dut.lead
            ctx.set(dut.i.valid, valid)
            ctx.set(dut.i.payload.width, queue[sent] if valid else 0)
            pins = ctx.get(dut.pwm)
            if pins:
                out["high_phases"].add(phase)
            for c in range(n):
                if pins >> c & 1:
                    high[c] += 1
                    rise[c] = offset if rise[c] is None else rise[c]
            if valid and ctx.get(dut.i.ready):
                sent += 1
            offset += 1
            await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return out


def expected(dut, widths):
    return [(dut.lead, min(w, dut.max_width)) if min(w, dut.max_width) else (None, 0) for w in widths]


@pytest.mark.parametrize("seed", [1, 2])
def test_random_widths_show_in_their_period_from_one_edge(seed):
    rng = random.Random(seed)
    dut = ServoPWMCounters(period=60, width_bits=6, channels=4, lead=9)
    windows = [[rng.choice([0, 1, 2, dut.max_width, dut.max_width + 1, 63, rng.randrange(64)])
                for _ in range(4)] for _ in range(12)]
    gaps = {(k, j): rng.randrange(3) for k in range(12) for j in range(5)}
    # loads at phase 0, back to back, or spread up to the window's last phase
    got = measure(dut, windows, lambda k, j: min(j * gaps[k, j], dut.lead - 5 + j), 12)
    assert got["pulses"][:11] == [expected(dut, w) for w in windows[:11]]
    # the window is quiet: the counters rest there
    assert not got["high_phases"] & set(range(1, dut.lead + 1))


def test_every_width_at_four_bits_and_the_cap():
    dut = ServoPWMCounters(period=20, width_bits=4, channels=2, lead=7)
    assert dut.max_width == 13
    windows = [[w, 15 - w] for w in range(16)]
    got = measure(dut, windows, lambda k, j: 2 * j, 16)
    assert got["pulses"][:15] == [expected(dut, w) for w in windows[:15]]
    assert {p[1] for per in got["pulses"] for p in per} >= {0, 1, 12, 13}


def test_transfers_beyond_the_channels_are_ignored():
    dut = ServoPWMCounters(period=40, width_bits=5, channels=2, lead=8)
    windows = [[3, 5], [7, 1], [0, 9]]
    got = measure(dut, windows, lambda k, j: j, 3, extra=2)
    assert got["pulses"][:2] == [expected(dut, w) for w in windows[:2]]


def test_the_first_period_after_reset_is_quiet():
    dut = ServoPWMCounters(period=50, width_bits=5, channels=3, lead=6)
    got = measure(dut, [[4, 0, 31], [1, 2, 3]], lambda k, j: j + 1, 2)
    assert got["ready_early"] == 0 and got["pins_early"] == 0
    assert got["pulses"][:2] == [expected(dut, [4, 0, 31]), expected(dut, [1, 2, 3])]

    async def first_start(ctx):
        for cycle in range(120):
            if ctx.get(dut.period_start):
                assert cycle == dut.period + 1
                return
            await ctx.tick()
        raise AssertionError("no period start")

    dut = ServoPWMCounters(period=50, width_bits=5, channels=3, lead=6)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(first_start)
    sim.run()


@pytest.mark.parametrize("args, msg", [
    ((1, 8, 2, 1), "period must be an integer >= 2, not 1"),
    ((10, 0, 2, 1), "width_bits must be an integer >= 1, not 0"),
    ((10, 8, 0, 1), "channels must be an integer >= 1, not 0"),
    ((10, 8, 2, 0), "lead must be an integer >= 1, not 0"),
    ((10, 8, 2, 10), "lead must be < period=10, not 10"),
    ((10, 8, 2, True), "lead must be an integer >= 1, not True"),
])
def test_parameter_errors(args, msg):
    with pytest.raises(ValueError, match=msg):
        ServoPWMCounters(*args)
