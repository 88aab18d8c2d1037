"""The host of one test: reset, the UART and PWM pieces started, requests sent at a chosen
phase of the PWM period and their answers awaited, every answered request recorded."""
from __future__ import annotations

import json
from pathlib import Path

import cocotb
from cocotb.triggers import FallingEdge, Timer

from ikseries.fit.plan import Plan
from ikseries.hdl import protocol as P
from ikseries.host.protocol import decode_request, encode, request_parser

from ..cocotb_leg.timebase import Timebase
from .config import ControllerConfig
from .pwm import PwmMonitor
from .uart import UartDriver, UartMonitor, cycle_now

__all__ = ["Host", "parse_requests"]

#: a request's last stop bit ends this many cycles after a period start: the dispatcher then
#: works (and answers) well inside the period, never at its edge (see checker.SLACK)
ALIGN_DIVIDER = 8


def parse_requests(shape: P.Shape, data: bytes) -> list:
    """The request Messages the protocol's receiver finds in ``data`` (the host parser's rules)."""
    return [decode_request(code, payload, shape) for code, payload in request_parser(shape).feed(data)]


class Host:
    """Everything a test drives and watches, from the run configuration."""

    def __init__(self, dut, test: str):
        self.dut = dut
        self.config = cfg = ControllerConfig.from_environment()
        assert cfg.tests is None or test in cfg.tests, f"{test} is not selected ({cfg.tests})"
        self.plan = Plan.from_json(json.loads(Path(cfg.plan).read_text()))
        self.shape = P.Shape(cfg.legs, len(self.plan.inputs), cfg.legs * len(self.plan.outputs))
        self.period = cfg.period
        self.tb = Timebase(dut.clk)
        self.tx = UartDriver(dut.rx, self.tb, cfg.divisor)
        self.rx = UartMonitor(dut.tx, self.tb, cfg.divisor)
        self.pwm = PwmMonitor(dut.pwm, self.tb, self.shape.channels, cfg.period, cfg.lead)
        self.acked: list = []          # [(answer start cycle, request Message)]
        self.requests: list = []       # every request the receiver should find, in order
        self.reset_at = 0

    async def start(self) -> None:
        """Clock, reset (10 cycles), monitors."""
        self.dut.rx.value, self.dut.rst.value = 1, 1
        self.tb.start()
        await Timer(10 * self.tb.T, unit="step")
        await FallingEdge(self.dut.clk)
        self.dut.rst.value = 0
        self.reset_at = cycle_now(self.tb)
        cocotb.start_soon(self.rx.run())
        cocotb.start_soon(self.pwm.run())
        await Timer(20 * self.tb.T, unit="step")

    def cycle(self) -> int:
        return cycle_now(self.tb)

    def cycles(self, n: int):
        return Timer(n * self.tb.T, unit="step")

    async def send(self, data: bytes, aligned: bool = True) -> list:
        """Send ``data`` (ending ``period / ALIGN_DIVIDER`` cycles after a period start when
        ``aligned``), wait for an answer to each request in it; returns those answers."""
        reqs = parse_requests(self.shape, data)
        if aligned:
            await self._align(self.tx.byte_cycles(len(data)))
        n = len(self.rx.answers)
        await self.tx.send(data)
        await self.rx.wait_answers(n + len(reqs), 40 * self.period)
        got = self.rx.answers[n:]
        self.requests += reqs
        self.acked += [(a.start, r) for a, r in zip(got, reqs)]
        return got

    async def request(self, command: str, aligned: bool = True, **fields):
        """One request; its answer's Message."""
        (ans,) = await self.send(encode(command, self.shape, **fields), aligned)
        return ans.message

    async def _align(self, duration: int) -> None:
        assert self.pwm.phase is not None, "the PWM phase is unknown: no pulse seen yet"
        now = cycle_now(self.tb) + 1
        k = self.pwm.index(now + duration) + 1
        start = self.pwm.start(k) + self.period // ALIGN_DIVIDER - duration
        if start - now > self.period:
            start -= self.period
        await self.cycles(start - now)

    async def periods(self, n: int) -> None:
        await self.cycles(n * self.period)

    async def find_phase(self, channel: int, pulse: int) -> None:
        """Enable every channel and give ``channel`` a pulse (unaligned: the phase is not known
        yet); wait for the pulse."""
        await self.request("enable", aligned=False, channels=(1 << self.shape.channels) - 1)
        await self.request("set_pulse", aligned=False, channel=channel, pulse=pulse)
        for _ in range(4):
            if self.pwm.phase is not None:
                return
            await self.periods(1)
        raise AssertionError(f"no pulse on channel {channel} within 4 periods of set_pulse")
