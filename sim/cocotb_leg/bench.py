"""One test's bench: the pieces (driver, monitor, model, scoreboard, timing rule) set up from the
run configuration and the design's manifest, the reset sequence and the streaming loop."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from cocotb.triggers import FallingEdge, ReadOnly

from ikseries.fit.channels import ChannelTable
from ikseries.fit.plan import Plan

from .config import TESTS, Design, RunConfig
from .driver import Driver, Pattern
from .model import Model
from .monitor import Monitor
from .ports import Ports
from .rules import timing_rule
from .scoreboard import Checker, Scoreboard
from .timebase import Timebase

__all__ = ["Bench", "concat"]


def concat(*targets) -> dict:
    """Targets ({input: array}) one after the other."""
    return {n: np.concatenate([t[n] for t in targets]) for n in targets[0]}


class Bench:
    """Everything one cocotb test needs, read from the run configuration (:class:`RunConfig`)
    and the manifest it names.

    Parameters
    ----------
    dut : cocotb handle
        The simulated top-level module.
    test : str
        The running test, one of :data:`~.config.TESTS` (its position there, from 1, seeds its
        random stream with the run's seed).
    """

    def __init__(self, dut, test: str):
        self.dut, self.log = dut, dut._log
        self.config = RunConfig.from_environment()
        assert self.config.tests is None or test in self.config.tests, \
            f"{test} runs, but the run configuration selects only {', '.join(self.config.tests)}"
        self.design = Design.read(self.config.manifest)
        self.plan = Plan.from_json(json.loads(Path(self.config.plan).read_text()))
        self.design.check_plan(self.plan)
        d = self.design
        self.rng = np.random.default_rng([self.config.seed, TESTS.index(test) + 1])
        self.ports = Ports(dut, d)
        self.time = Timebase(self.ports.clk)
        self.driver = Driver(self.ports, self.plan.inputs, d.legs, self.rng)
        self.model = Model(self.plan, None if d.channel_table is None else ChannelTable.from_record(d.channel_table))
        self.rule = timing_rule(d.stream_rule, d.latency, d.initiation_interval)
        self.e1: int | None = None          # first rising edge with rst low (relative edge 1)

    @property
    def servos(self) -> list[str]:
        return self.design.servos

    async def start(self, reset_cycles: int = 3) -> None:
        """Clock on, ``reset_cycles`` reset edges (checking the reset state), rst low for edge 1."""
        self.driver.reset_state()
        self.time.start()
        chk = Checker("reset state")
        for c in range(reset_cycles):
            await FallingEdge(self.ports.clk)
            await ReadOnly()
            # after a reset edge: pipeline empty, PWM outputs low
            chk(int(self.ports.o_valid.value) == 0, f"o_valid high after {c + 1} reset edge(s)")
            for s, sig in self.ports.pwm.items():
                chk(int(sig.value) == 0, f"pwm_{s} high after {c + 1} reset edge(s)")
        chk.done()
        await FallingEdge(self.ports.clk)
        self.ports.rst.value = 0
        self.e1 = self.time.upcoming()
        self.rule.start(self.e1)

    def stop(self) -> None:
        self.time.stop()

    async def stream(self, targets: dict, pattern: Pattern, legs=None) -> tuple[Monitor, Scoreboard]:
        """Offer ``targets`` in order with ``pattern`` and collect the outputs.

        Checks the timing rule and the hold rule in every cycle on the way (in the scoreboard's
        handshake checker, reported by :meth:`Scoreboard.check`); ``legs``: leg of each target
        (robot top). Returns the monitor (transfers, stalls, outputs) and the scoreboard.
        """
        d = self.design
        n = len(next(iter(targets.values())))
        legs = np.zeros(n, dtype=np.int64) if legs is None else legs
        mon = Monitor(self.ports, self.servos)
        sb = Scoreboard(self.servos, d.latency, d.initiation_interval, d.stream_rule == "buffered")
        k, drain, cycle = 0, 0, 0
        limit = 50 * n * d.initiation_interval + 10 * d.latency + 1000
        while drain <= d.latency + 4:
            e = await self.time.falling()
            offer, ready = pattern.next(k < n)
            self.driver.offer({nm: targets[nm][k] for nm in targets} if offer else None, legs[k] if offer else None)
            self.driver.ready(ready)
            await ReadOnly()
            s = mon.sample(e, offer, ready)
            for msg in self.rule.check(s, mon.in_flight):
                sb.handshake(False, msg)
            sb.hold(s)
            mon.record(s, output=not s.output_transfer or sb.output_expected(s, n, len(mon.out_edges)))
            k += s.input_transfer
            if len(mon.out_edges) == n:
                drain += 1
            cycle += 1
            if not sb.handshake(cycle < limit, f"no progress: {len(mon.in_edges)} inputs and "
                                               f"{len(mon.out_edges)} outputs of {n} after {cycle} cycles"):
                break
        await FallingEdge(self.ports.clk)
        self.ports.i_valid.value = 0
        self.ports.o_ready.value = 1
        return mon, sb

    def check_stream(self, targets: dict, mon: Monitor, sb: Scoreboard, exact_latency: bool, legs=None) -> dict:
        """The scoreboard's checks of a streamed sequence against the model; returns the
        expected outputs. o_leg is compared where the core has one."""
        exp = self.model.outputs(targets, legs)
        sb.check(targets, exp, mon, exact_latency, legs if self.ports.o_leg is not None else None)
        return exp
