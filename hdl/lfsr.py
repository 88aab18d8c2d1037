"""Counting with a linear feedback shift register: a wait of a fixed number of cycles in
a few LUTs instead of a counter's adder and comparator."""
from __future__ import annotations

from amaranth.hdl import Cat, Signal

__all__ = ["XNOR_TAPS", "lfsr_bits", "lfsr_step", "lfsr_after", "countdown"]

#: maximal-length XNOR feedback taps (1-based bit numbers, Xilinx XAPP052) per register
#: length: from any state but all ones the register runs through all other 2 ** n - 1 states
XNOR_TAPS = {3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5),
             10: (10, 7), 11: (11, 9), 12: (12, 6, 4, 1), 13: (13, 4, 3, 1), 14: (14, 5, 3, 1),
             15: (15, 14), 16: (16, 15, 13, 4), 17: (17, 14), 18: (18, 11), 19: (19, 6, 2, 1),
             20: (20, 17), 21: (21, 19), 22: (22, 21), 23: (23, 18), 24: (24, 23, 22, 17)}


def lfsr_bits(steps: int) -> int:
    """The shortest register of :data:`XNOR_TAPS` whose sequence from 0 does not repeat within
    ``steps`` steps (``steps + 1`` distinct states)."""
    for n in sorted(XNOR_TAPS):
        if steps < (1 << n) - 1:
            return n
    raise ValueError(f"steps must be below {(1 << max(XNOR_TAPS)) - 1}, not {steps!r}")


def lfsr_step(n: int, state: int) -> int:
    """The state after ``state`` (an int of ``n`` bits): shifted up a bit, the XNOR of the taps in."""
    fb = 1
    for t in XNOR_TAPS[n]:
        fb ^= state >> (t - 1) & 1
    return (state << 1 | fb) & ((1 << n) - 1)


def lfsr_after(n: int, steps: int, state: int = 0) -> int:
    """``lfsr_step`` applied ``steps`` times, by squaring the affine step map (``steps`` may be
    millions: a PWM period in cycles)."""
    # an affine map of GF(2) ** n: the images of the unit vectors under its linear part, its constant
    def apply(f, s):
        cols, const = f
        for i in range(n):
            if s >> i & 1:
                const ^= cols[i]
        return const

    def compose(g, f):          # g after f
        base = apply(g, 0)
        return [apply(g, c) ^ base for c in f[0]], apply(g, f[1])

    base = lfsr_step(n, 0)
    power = ([lfsr_step(n, 1 << i) ^ base for i in range(n)], base)
    acc = ([1 << i for i in range(n)], 0)       # the identity
    while steps:
        if steps & 1:
            acc = compose(power, acc)
        power, steps = compose(power, power), steps >> 1
    return apply(acc, state)


def countdown(m, restart, cycles: int, name: str = "countdown"):
    """A signal that is high while fewer than ``cycles`` cycles have passed since ``restart`` was
    last high (and since reset): ``since < cycles`` of a counter ``since`` cleared by
    ``restart`` and counting up each other cycle, without its adder or comparator.

    The state is an XNOR shift register cleared by ``restart`` (a synchronous reset, no LUT per
    bit) and stepped until it reaches its state ``cycles`` steps after 0, where it stays; the
    result is that state's comparison (combinational from the register).
    """
    cycles = max(cycles, 0)
    n = lfsr_bits(cycles)
    state = Signal(n, name=name)
    end = lfsr_after(n, cycles)
    fb = ~Cat(*(state[t - 1] for t in XNOR_TAPS[n])).xor()
    running = state != end
    with m.If(restart):
        m.d.sync += state.eq(0)
    with m.Elif(running):
        m.d.sync += state.eq(Cat(fb, state[:-1]))
    return running
