"""Drive targets through the leg or robot core in the Amaranth simulator."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from amaranth.sim import Simulator

__all__ = ["LegSimResult", "RobotSimResult", "simulate_leg", "simulate_robot"]


@dataclass
class LegSimResult:
    outputs: dict          # servo -> int64 array, in output order
    latencies: np.ndarray  # cycles from each input transfer to its output transfer
    cycles: int
    input_cycles: np.ndarray | None = None   # cycle of each input transfer


def _drive(core, n: int, payload, collect, *, what: str, ready_prob: float, valid_prob: float | None,
           seed: int, vcd: str | None):
    """Offer ``n`` inputs (``payload(k)``) to ``core.i``, take outputs with ``collect(ctx)`` on
    every ``core.o`` transfer; returns (input cycles, output cycles, cycles run).

    ``valid_prob`` None: every input offered as soon as possible; else with that probability
    each cycle. ``ready_prob`` < 1: random backpressure on ``o``.
    """
    rng = np.random.default_rng(seed)
    t_in, t_out = [], []
    state = {"cycles": 0}

    async def bench(ctx):
        cyc, k = 0, 0
        ii = getattr(core, "initiation_interval", 1)   # folded cores take one input per ii cycles
        limit = 50 * (n * ii + core.latency + 10) + 1000
        while len(t_out) < n:
            if cyc > limit:
                raise RuntimeError(f"{what} produced {len(t_out)} of {n} outputs in {cyc} cycles")
            offer = k < n and (valid_prob is None or rng.random() < valid_prob)
            ctx.set(core.i.valid, int(offer))
            if offer:
                ctx.set(core.i.payload, payload(k))
            ctx.set(core.o.ready, int(rng.random() < ready_prob))
            if offer and ctx.get(core.i.ready):
                t_in.append(cyc)
                k += 1
            if ctx.get(core.o.valid) and ctx.get(core.o.ready):
                collect(ctx)
                t_out.append(cyc)
            await ctx.tick()
            cyc += 1
        state["cycles"] = cyc

    sim = Simulator(core)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    if vcd:
        with sim.write_vcd(vcd):
            sim.run()
    else:
        sim.run()
    return np.array(t_in), np.array(t_out), state["cycles"]


def simulate_leg(core, targets: dict, *, ready_prob: float = 1.0, valid_prob: float = 1.0,
                 seed: int = 0, vcd: str | None = None) -> LegSimResult:
    """Stream ``targets`` (port integers) through ``core``; collect outputs and latencies.

    ``core`` is a :class:`LegCore` or a :class:`PlanEvaluator` (anything with ``i``/``o``
    streams and a ``latency``).

    ``ready_prob`` / ``valid_prob`` < 1 apply random backpressure / input gaps.
    """
    names = list(targets)
    servos = [name for name, _ in core.o.payload.shape()]
    got = {s: [] for s in servos}

    def collect(ctx):
        for s in servos:
            got[s].append(ctx.get(core.o.payload[s]))

    t_in, t_out, cycles = _drive(core, len(targets[names[0]]),
                                 lambda k: {f: int(targets[f][k]) for f in names}, collect,
                                 what="leg core", ready_prob=ready_prob, valid_prob=valid_prob,
                                 seed=seed, vcd=vcd)
    return LegSimResult({s: np.array(v, dtype=np.int64) for s, v in got.items()},
                        t_out - t_in, cycles, t_in)


@dataclass
class RobotSimResult:
    legs: np.ndarray       # o.payload.leg of each output transfer, in order
    outputs: dict          # servo -> int64 array, in output order
    latencies: np.ndarray  # cycles from each input transfer to its output transfer
    input_cycles: np.ndarray   # cycle of each input transfer
    cycles: int


def simulate_robot(core, legs, targets: dict, *, ready_prob: float = 1.0, seed: int = 0,
                   vcd: str | None = None) -> RobotSimResult:
    """Stream ``targets`` (port integers) addressed to ``legs`` (one leg index per target)
    through a :class:`RobotCore`; collect each output's leg and widths, and latencies.

    Targets are offered back to back (``i.valid`` always high until all are accepted);
    ``ready_prob`` < 1 applies random backpressure on ``o``.
    """
    names = list(targets)
    legs = np.asarray(legs, dtype=np.int64)
    n = len(legs)
    if any(len(targets[f]) != n for f in names):
        raise ValueError(f"targets must have one value per leg index ({n}), not "
                         f"{[len(targets[f]) for f in names]}")
    servos = core.servos
    got = {s: [] for s in servos}
    got_legs = []

    def collect(ctx):
        got_legs.append(ctx.get(core.o.payload.leg))
        for s in servos:
            got[s].append(ctx.get(core.o.payload.widths[s]))

    t_in, t_out, cycles = _drive(
        core, n, lambda k: {"leg": int(legs[k]), "target": {f: int(targets[f][k]) for f in names}},
        collect, what="robot core", ready_prob=ready_prob, valid_prob=None, seed=seed, vcd=vcd)
    return RobotSimResult(np.array(got_legs, dtype=np.int64),
                          {s: np.array(v, dtype=np.int64) for s, v in got.items()},
                          t_out - t_in, t_in, cycles)
