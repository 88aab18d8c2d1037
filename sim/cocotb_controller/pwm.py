"""The ``pwm`` pins: every value change recorded, then each channel's high time in every PWM
period of the grid its pulses start on."""
from __future__ import annotations

from cocotb.triggers import ValueChange

from .uart import cycle_now

__all__ = ["PwmMonitor"]


class PwmMonitor:
    """Records (cycle, pwm word) at every change of ``pwm``; the period starts are the grid
    ``phase + k * period``, ``lead`` cycles before the first rising edge seen (the pulses of
    a period rise ``lead`` cycles after its start, the servo controller's pass)."""

    def __init__(self, pwm, tb, channels: int, period: int, lead: int):
        self.pwm, self.tb, self.channels, self.period, self.lead = pwm, tb, channels, period, lead
        self.changes: list[tuple[int, int]] = []

    async def run(self) -> None:
        while True:
            await ValueChange(self.pwm)
            self.changes.append((cycle_now(self.tb), int(self.pwm.value)))

    @property
    def phase(self) -> int | None:
        """Cycle of the period start before the first rising edge, modulo the period (None
        before any pulse)."""
        prev = 0
        for cyc, v in self.changes:
            if v & ~prev:
                return (cyc - self.lead) % self.period
            prev = v
        return None

    def start(self, k: int) -> int:
        """Cycle of period start ``k`` (period 0 starts before the period ``phase``)."""
        return self.phase + k * self.period

    def index(self, cycle: int) -> int:
        """The period containing ``cycle``."""
        return (cycle - self.phase) // self.period

    def off_grid_rises(self) -> list[tuple[int, int]]:
        """(cycle, channel) of every rising edge not ``lead`` cycles after a period start."""
        bad, prev = [], 0
        for cyc, v in self.changes:
            rose = v & ~prev
            if rose and (cyc - self.lead - self.phase) % self.period:
                bad += [(cyc, c) for c in range(self.channels) if rose >> c & 1]
            prev = v
        return bad

    def high_times(self, first: int, last: int) -> dict[int, list[int]]:
        """{period k: [high cycles of each channel]} for periods ``first .. last - 1``."""
        out = {k: [0] * self.channels for k in range(first, last)}
        lo, hi = self.start(first), self.start(last)
        for (cyc, v), nxt in zip(self.changes, self.changes[1:] + [(hi, 0)]):
            a, b = max(cyc, lo), min(nxt[0], hi)
            if a >= b or not v:
                continue
            for c in range(self.channels):
                if v >> c & 1:
                    self._add(out, c, a, b)
        return out

    def _add(self, out, c: int, a: int, b: int) -> None:
        while a < b:
            k = self.index(a)
            end = min(b, self.start(k + 1))
            out[k][c] += end - a
            a = end
