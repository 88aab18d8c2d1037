"""The host's two wires: a UART driver on ``rx`` and a UART monitor on ``tx`` (8N1, bit-timed
from the design's divisor, in clock cycles of the bench's :class:`~ikseries.sim.cocotb_leg.timebase.Timebase`)."""
from __future__ import annotations

from dataclasses import dataclass

from cocotb.simtime import get_sim_time
from cocotb.triggers import FallingEdge, Timer

from ikseries.host.protocol import Decoder, Message

__all__ = ["Answer", "UartDriver", "UartMonitor", "cycle_now"]


def cycle_now(tb) -> int:
    """Clock cycles since the bench clock started (rising edge index of the current time)."""
    return (get_sim_time("step") - tb.t0) // tb.T


def byte_bits(byte: int) -> list[int]:
    return [0] + [byte >> k & 1 for k in range(8)] + [1]


class UartDriver:
    """Shifts bytes into ``rx``, each bit exactly ``divisor`` cycles, bytes back to back."""

    def __init__(self, rx, tb, divisor: int):
        self.rx, self.tb, self.div = rx, tb, divisor
        self.sent = 0

    def byte_cycles(self, n: int = 1) -> int:
        return 10 * self.div * n

    async def send(self, data: bytes) -> None:
        # bits change at falling edges, half a cycle away from the receiver's sampling edge
        if (get_sim_time("step") - self.tb.t0) % self.tb.T:
            await FallingEdge(self.tb.clk)
        bit = self.div * self.tb.T
        for byte in data:
            for b in byte_bits(byte):
                self.rx.value = b
                await Timer(bit, unit="step")
        self.sent += len(data)


@dataclass(frozen=True)
class Answer:
    """One decoded answer frame: the cycles of its first start bit and of its last stop bit."""
    start: int
    end: int
    message: Message


class UartMonitor:
    """Samples ``tx`` in the middle of every bit and decodes the bytes into answers with the
    host's :class:`~ikseries.host.protocol.Decoder`; a byte whose stop bit is low is counted in
    ``framing`` and not decoded."""

    def __init__(self, tx, tb, divisor: int):
        self.tx, self.tb, self.div = tx, tb, divisor
        self.answers: list[Answer] = []
        self.bytes = 0
        self.framing = 0
        self.decoder = Decoder()
        self._frame_start = None

    async def run(self) -> None:
        div, T = self.div, self.tb.T
        while True:
            await FallingEdge(self.tx)
            start = cycle_now(self.tb)
            # tx changes just after a rising edge; sample half a cycle later, mid-bit
            await Timer((div + div // 2) * T + T // 2, unit="step")
            byte = 0
            for k in range(8):
                byte |= int(self.tx.value) << k
                await Timer(div * T, unit="step")
            if not int(self.tx.value):
                self.framing += 1
                continue
            self._take(byte, start)

    def _take(self, byte: int, start: int) -> None:
        self.bytes += 1
        if self._frame_start is None:
            self._frame_start = start
        for msg in self.decoder.feed([byte]):
            self.answers.append(Answer(self._frame_start, start + 10 * self.div, msg))
            self._frame_start = None

    async def wait_answers(self, n: int, timeout: int) -> None:
        """Wait until ``n`` answers have arrived; fail after ``timeout`` cycles."""
        step = 10 * self.div
        for _ in range(0, timeout, step):
            if len(self.answers) >= n:
                return
            await Timer(step * self.tb.T, unit="step")
        raise AssertionError(f"{len(self.answers)} answers after {timeout} cycles, expected {n}")
