"""Drives targets into the design: the input fields, i_valid with a valid/gap pattern, o_ready."""
from __future__ import annotations

import numpy as np

from .ports import Ports

__all__ = ["Pattern", "Driver"]


class Pattern:
    """A random valid/gap and ready pattern.

    Every ``regime_len`` cycles one of ``regimes`` ((p_valid, p_ready) pairs) is chosen at
    random; i_valid is then offered with probability p_valid (while targets remain), o_ready
    raised with probability p_ready (1.0 = always).

    Parameters
    ----------
    rng : numpy Generator
        Random source (shared with the driver's junk values: one stream per test).
    regimes : list of (float, float)
        (p_valid, p_ready) choices.
    regime_len : int
        Cycles per regime.
    """

    def __init__(self, rng, regimes, regime_len: int = 64):
        self.rng, self.regimes, self.regime_len = rng, list(regimes), regime_len
        self.cycle = 0
        self.p_valid, self.p_ready = self.regimes[0]

    def next(self, pending: bool) -> tuple[bool, bool]:
        """(offer a target, o_ready) for the next cycle; ``pending``: targets remain."""
        if self.cycle % self.regime_len == 0:
            self.p_valid, self.p_ready = self.regimes[self.rng.integers(len(self.regimes))]
        self.cycle += 1
        offer = pending and (self.p_valid >= 1 or self.rng.random() < self.p_valid)
        ready = self.p_ready >= 1 or self.rng.random() < self.p_ready
        return bool(offer), bool(ready)


class Driver:
    """Writes the design's inputs (call at a falling edge: the next rising edge sees them).

    Parameters
    ----------
    ports : Ports
        The design's signals.
    inputs : sequence of plan inputs
        The plan's input fields (their port ranges bound the junk driven while i_valid is low).
    legs : int
        Legs of the core (the junk leg is drawn from them).
    rng : numpy Generator
        Random source of the junk values.
    """

    def __init__(self, ports: Ports, inputs, legs: int, rng):
        self.ports, self.inputs, self.legs, self.rng = ports, list(inputs), legs, rng

    def inputs_only(self, values: dict | None, leg: int | None = None) -> None:
        """Drive target ``values`` ({input: int}) for ``leg`` on the input fields; None: random
        port junk (for cycles with i_valid low)."""
        for i in self.inputs:
            if values is None:
                lo, hi = i.port_range
                v = int(self.rng.integers(lo, hi + 1))
            else:
                v = int(values[i.name])
            self.ports.inputs[i.name].value = v
        if self.ports.i_leg is not None:
            self.ports.i_leg.value = int(self.rng.integers(self.legs)) if values is None or leg is None else int(leg)

    def offer(self, values: dict | None, leg: int | None = None) -> None:
        """i_valid high with target ``values`` for ``leg``; None: i_valid low, junk on the fields."""
        self.ports.i_valid.value = int(values is not None)
        self.inputs_only(values, leg)

    def ready(self, ready: bool) -> None:
        self.ports.o_ready.value = int(ready)

    def reset_state(self) -> None:
        """rst high, i_valid and o_ready low, junk on the input fields."""
        self.ports.rst.value = 1
        self.ports.i_valid.value = 0
        self.ports.o_ready.value = 0
        self.inputs_only(None)

    def random_legs(self, n: int) -> np.ndarray:
        """A random leg per target (all 0 for a one-leg core)."""
        return self.rng.integers(0, self.legs, n) if self.legs > 1 else np.zeros(n, dtype=np.int64)
