"""A block RAM write port that costs no read-port bypass logic in Yosys."""
from __future__ import annotations

from amaranth.hdl import ClockDomain, ClockSignal, Signal

__all__ = ["FallingEdgeWrite", "falling_edge_write_port"]


class FallingEdgeWrite:
    """A write port's ``en``, ``addr`` and ``data`` as plain signals, to drive like the port's."""

    def __init__(self, port):
        self.en, self.addr, self.data = Signal(), Signal.like(port.addr), Signal.like(port.data)


def falling_edge_write_port(m, mem, name: str = "write") -> FallingEdgeWrite:
    """A write port of ``mem`` whose requests are registered, then written on the falling edge.

    A write port and a synchronous read port on the same edge make Yosys emulate Amaranth's
    read-old-data collision with a bypass register, comparator and multiplexer per read port
    (43 FF and 25 LUT for 18 words of 18 bits on iCE40); on the other edge there is nothing to
    emulate. The behaviour is unchanged: a request of cycle ``t`` lands half a cycle after edge
    ``t + 1``, after the read sampled at that edge (which saw the old word, as before) and before
    the one at ``t + 2`` (which sees the new one, as before). The register keeps the half cycle
    free of logic. ``name`` is the local clock domain added to ``m``.
    """
    m.domains += ClockDomain(name, clk_edge="neg", local=True, reset_less=True)
    m.d.comb += ClockSignal(name).eq(ClockSignal("sync"))
    port = mem.write_port(domain=name)
    ask = FallingEdgeWrite(port)
    m.d.sync += [port.en.eq(ask.en), port.addr.eq(ask.addr), port.data.eq(ask.data)]
    return ask
