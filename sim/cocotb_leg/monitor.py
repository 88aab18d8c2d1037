"""Watches the design: samples each cycle's handshake and payload, records the transfers."""
from __future__ import annotations

import dataclasses

from cocotb.simtime import get_sim_time
from cocotb.triggers import ValueChange

from .ports import Ports

__all__ = ["Sample", "Monitor", "watch"]


@dataclasses.dataclass(frozen=True)
class Sample:
    """What rising edge ``edge`` sees (sampled after ``ReadOnly()`` at the falling edge before it).

    ``payload``: the output fields in servo order plus o_leg (0 without one) when o_valid is
    high, else None.
    """
    edge: int
    offered: bool
    o_ready: bool
    o_valid: bool
    i_ready: bool
    payload: tuple | None

    @property
    def input_transfer(self) -> bool:
        return self.offered and self.i_ready

    @property
    def output_transfer(self) -> bool:
        return self.o_valid and self.o_ready

    @property
    def stall(self) -> bool:
        """o_valid high and o_ready low: the output waits."""
        return self.o_valid and not self.o_ready


class Monitor:
    """Samples the stream ports and records input transfers, output transfers and stalls.

    Parameters
    ----------
    ports : Ports
        The design's signals.
    servos : list of str
        Output fields, in payload order.
    """

    def __init__(self, ports: Ports, servos):
        self.ports, self.servos = ports, list(servos)
        self.in_edges: list[int] = []
        self.out_edges: list[int] = []
        self.stall_edges: list[int] = []
        self.outputs: list[tuple] = []

    def sample(self, edge: int, offered: bool, o_ready: bool) -> Sample:
        """The stream ports now (after ``ReadOnly()``), for rising edge ``edge``."""
        p = self.ports
        ov, ir = bool(int(p.o_valid.value)), bool(int(p.i_ready.value))
        pay = None
        if ov:
            pay = tuple(int(p.outputs[s].value) for s in self.servos) + (
                (int(p.o_leg.value),) if p.o_leg is not None else (0,))
        return Sample(edge, offered, o_ready, ov, ir, pay)

    @property
    def in_flight(self) -> int:
        """Targets whose input transferred and whose output has not."""
        return len(self.in_edges) - len(self.out_edges)

    def record(self, s: Sample, output: bool = True) -> None:
        """Record the transfers and stall of ``s``; ``output=False`` leaves out its output
        transfer (one the scoreboard refused: beyond the targets sent)."""
        if s.input_transfer:
            self.in_edges.append(s.edge)
        if s.output_transfer and output:
            self.out_edges.append(s.edge)
            self.outputs.append(s.payload)
        if s.stall:
            self.stall_edges.append(s.edge)


async def watch(sig, log: list) -> None:
    """Append (simulation time in steps, value) to ``log`` at every change of ``sig``."""
    while True:
        await ValueChange(sig)
        log.append((get_sim_time("step"), int(sig.value)))
