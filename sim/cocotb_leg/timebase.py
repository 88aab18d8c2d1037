"""Clock and edge arithmetic of the bench.

The clock starts low at ``t0`` and rises at ``t0 + T/2 + e*T`` (rising edge ``e``); the falling
edge at ``t0 + e*T`` precedes rising edge ``e``. The bench writes inputs at falling edges and
samples after ``ReadOnly()`` at falling edges, so what it samples is what the next rising edge
sees; a transfer "at edge e" means valid & ready were sampled high by rising edge ``e``.
"""
from __future__ import annotations

from cocotb.clock import Clock
from cocotb.simtime import convert, get_sim_time
from cocotb.triggers import FallingEdge, Timer

from .config import CLOCK_NS

__all__ = ["Timebase"]


class Timebase:
    """The bench clock on ``clk`` and the mapping between simulation time and rising edges.

    Parameters
    ----------
    clk : cocotb handle
        The design's clock input.
    """

    def __init__(self, clk):
        self.clk = clk
        self.T = int(convert(CLOCK_NS, "ns", to="step"))
        assert self.T % 2 == 0, f"clock period of {self.T} simulator steps is not even"
        self.t0: int | None = None
        self._clock = None

    def start(self) -> None:
        """Start the clock (low now, first rising edge half a period later)."""
        self.t0 = get_sim_time("step")
        # C clock (GPI): about 1.5x faster than the Python one on Icarus
        self._clock = Clock(self.clk, CLOCK_NS, unit="ns", impl="gpi")
        self._clock.start(start_high=False)

    def stop(self) -> None:
        if self._clock is not None:
            self._clock.stop()
            self._clock = None

    def upcoming(self) -> int:
        """Index of the next rising edge; only valid at a falling-edge time."""
        q, r = divmod(get_sim_time("step") - self.t0, self.T)
        assert r == 0, f"bench not at a falling edge (t={get_sim_time('step')}, t0={self.t0})"
        return q

    def edge_at(self, t: int) -> int:
        """Rising-edge index of time ``t`` (must be a rising-edge time)."""
        q, r = divmod(t - self.t0 - self.T // 2, self.T)
        assert r == 0, f"signal changed at t={t} steps, not at a rising clock edge"
        return q

    def seen_by_edges(self, log: list) -> list:
        """A value-change ``log`` [(time, value)] of a signal that may also change between
        rising edges (combinationally from an input the bench drives at falling edges) as
        [(edge n, value edge n + 1 sees)]: changes within one cycle merged, the last kept."""
        out: list = []
        for t, v in log:
            n = (t - self.t0 - self.T // 2) // self.T      # last rising edge at or before t
            if out and out[-1][0] == n:
                out.pop()
            if not out or out[-1][1] != v:
                out.append((n, v))
        return out

    async def falling(self) -> int:
        """Wait for the next falling edge; returns the index of the rising edge after it."""
        await FallingEdge(self.clk)
        return self.upcoming()

    async def goto(self, e: int) -> None:
        """Move to the falling edge right before rising edge ``e`` (strictly in the future)."""
        now = get_sim_time("step")
        target = self.t0 + e * self.T
        assert target > now, f"goto({e}) is not in the future"
        await Timer(target - now - self.T // 2, "step")   # lands on rising edge e-1
        await FallingEdge(self.clk)
        assert get_sim_time("step") == target
