"""A host on the pins of a simulated RobotController: bit-timed bytes into ``rx``, answers
decoded off ``tx`` with the host Decoder, pulses measured on ``pwm``."""
from __future__ import annotations

import numpy as np
from amaranth.sim import Simulator

from ikseries.host.protocol import Decoder
from ikseries.sim import golden


def golden_widths(plan, target) -> list[int]:
    """The golden model's pulse per servo (plan output order) for a target of port integers,
    saturated to the input ranges as the controller does."""
    ints = {i.name: np.array([min(max(v, i.lo), i.hi)]) for i, v in zip(plan.inputs, target)}
    out = golden.outputs(plan, ints)
    return [int(out[o.name][0]) for o in plan.outputs]


class PinHost:
    """Records every answer (cycle, Message) and every pulse (rise cycle, width) per channel."""

    def __init__(self, dut):
        self.dut, self.div = dut, dut.divisor
        self.answers, self.pulses = [], [[] for _ in range(len(dut.pwm))]
        self.cycle = 0
        self.requests = 0       # frames sent through request(), each expecting an answer
        self.period_starts = []
        self._decoder = Decoder()

    async def monitor(self, ctx):
        """Every cycle: decode tx, measure pulses, note period starts."""
        div, n = self.div, len(self.dut.pwm)
        rise = [None] * n
        prev = 0
        rx_at, bits = None, []
        while True:
            tx, pwm = ctx.get(self.dut.tx), ctx.get(self.dut.pwm)
            if ctx.get(self.dut.servo.period_start):
                self.period_starts.append(self.cycle)
            if rx_at is None:
                if tx == 0:
                    rx_at, bits = self.cycle, []
            elif self.cycle == rx_at + div // 2 + div * (len(bits) + 1):
                bits.append(tx)
                if len(bits) == 9:
                    byte = sum(b << k for k, b in enumerate(bits[:8]))
                    for msg in self._decoder.feed([byte]):
                        self.answers.append((self.cycle, msg))
                    rx_at = None
            changed = pwm ^ prev
            for ch in range(n):
                if changed >> ch & 1:
                    if pwm >> ch & 1:
                        rise[ch] = self.cycle
                    elif rise[ch] is not None:
                        self.pulses[ch].append((rise[ch], self.cycle - rise[ch]))
            prev = pwm
            self.cycle += 1
            await ctx.tick()

    async def send(self, ctx, data: bytes):
        for byte in data:
            for bit in [0] + [byte >> k & 1 for k in range(8)] + [1]:
                ctx.set(self.dut.rx, bit)
                await ctx.tick().repeat(self.div)

    async def request(self, ctx, data: bytes, timeout: int = 20000):
        """Send a frame and wait for one answer; returns (answer, cycle the frame ended)."""
        before = len(self.answers)
        self.requests += 1
        await self.send(ctx, data)
        sent = self.cycle
        for _ in range(timeout):
            if len(self.answers) > before:
                return self.answers[before][1], sent
            await ctx.tick()
        raise AssertionError(f"no answer to {data.hex()} within {timeout} cycles")

    async def periods(self, ctx, n: int):
        await ctx.tick().repeat(n * self.dut.servo.period)

    def widths_after(self, ch: int, cycle: int) -> list[int]:
        return [w for t, w in self.pulses[ch] if t >= cycle]

    def first_pulse(self, ch: int, cycle: int, width: int):
        """Rise cycle of the first pulse of ``width`` on ``ch`` rising at or after ``cycle``."""
        return next((t for t, w in self.pulses[ch] if t >= cycle and w == width), None)


def run(dut, script, probes=()):
    """Run ``script(ctx, host)`` against ``dut`` with a PinHost and ``probes`` (background
    testbenches) watching; returns the host."""
    host = PinHost(dut)

    async def bench(ctx):
        await script(ctx, host)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(host.monitor, background=True)
    for probe in probes:
        sim.add_testbench(probe, background=True)
    sim.add_testbench(bench)
    sim.run()
    return host


class SimulatedPort:
    """A serial port whose other end is a simulated RobotController: ``write`` queues bytes for
    ``rx``, ``read`` runs the simulation until ``tx`` has given bytes (or ``cycles`` pass)."""

    def __init__(self, dut, cycles: int = 50000):
        self.dut, self.div, self.cycles = dut, dut.divisor, cycles
        self._out, self._in = bytearray(), bytearray()
        self._sim = Simulator(dut)
        self._sim.add_clock(1e-6)
        self._sim.add_testbench(self._drive, background=True)
        self._sim.add_testbench(self._listen, background=True)
        self._now = 0.0

    async def _drive(self, ctx):
        while True:
            if not self._out:
                await ctx.tick()
                continue
            byte = self._out.pop(0)
            for bit in [0] + [byte >> k & 1 for k in range(8)] + [1]:
                ctx.set(self.dut.rx, bit)
                await ctx.tick().repeat(self.div)

    async def _listen(self, ctx):
        div = self.div
        while True:
            while ctx.get(self.dut.tx):
                await ctx.tick()
            await ctx.tick().repeat(div // 2 + div)
            byte = 0
            for k in range(8):
                byte |= ctx.get(self.dut.tx) << k
                await ctx.tick().repeat(div)
            self._in.append(byte)

    def write(self, data: bytes) -> int:
        self._out += data
        return len(data)

    def read(self, n: int) -> bytes:
        step = 200
        for _ in range(0, self.cycles, step):
            if self._in:
                break
            self._now += step * 1e-6
            self._sim.run_until(self._now)
        out, self._in = bytes(self._in[:n]), self._in[n:]
        return out
