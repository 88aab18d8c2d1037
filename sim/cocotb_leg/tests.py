"""The cocotb tests of the exported leg core (:func:`ikseries.hdl.export.leg_verilog`) and robot
core (:func:`ikseries.hdl.export.robot_verilog`), composed from the bench's pieces.

Runs inside the simulator (Icarus or Verilator); start it with :func:`ikseries.sim.runner.run`.
Every test reads the run configuration and the design's manifest (:class:`~.bench.Bench`); the
core's stream rule picks its timing rule (:mod:`ikseries.sim.cocotb_leg.rules`, which says how to
add one for a new architecture). Expected pulse widths come from the golden integer model
(:mod:`ikseries.sim.golden`), never from the bench. The robot top gets every target with a
random leg and must return it on o_leg.
"""
from __future__ import annotations

import numpy as np

import cocotb
from cocotb.triggers import FallingEdge, ReadOnly

from ikseries.sim.targets import corner_targets, random_targets

from . import pwm
from .bench import Bench, concat
from .driver import Pattern
from .model import transitions
from .monitor import watch
from .scoreboard import Checker

#: the backpressure test's (p_valid, p_ready) regimes
BACKPRESSURE_REGIMES = [(0.5, 0.5), (0.9, 0.3), (0.3, 0.9), (1.0, 0.7), (0.8, 1.0), (0.1, 0.1), (1.0, 0.0)]


@cocotb.test()
async def test_back_to_back(dut):
    """Corner + random targets offered every cycle, o_ready always high: bit-exact outputs in
    order (robot top: each to a random leg, returned on o_leg), one input and one output transfer
    every II cycles exactly (II = 1: i_ready never low, one output per cycle), latency == the
    manifest's for every target."""
    b = Bench(dut, "test_back_to_back")
    try:
        await b.start()
        targets = concat(corner_targets(b.plan, port_extremes=True),
                         random_targets(b.plan, b.config.n_random, b.rng))
        n = len(next(iter(targets.values())))
        legs = b.driver.random_legs(n)
        mon, sb = await b.stream(targets, Pattern(b.rng, [(1.0, 1.0)]), legs=legs)
        b.check_stream(targets, mon, sb, exact_latency=True, legs=legs)
        sb.throughput(mon)
        d = b.design
        b.log.info("%d targets (%d corner) back to back, one every %d cycle(s)%s: bit-exact, latency %d "
                   "cycles each, edges %d..%d", n, n - b.config.n_random, d.initiation_interval,
                   f", legs {sorted(set(legs.tolist()))}" if d.robot else "", d.latency,
                   mon.in_edges[0], mon.out_edges[-1])
    finally:
        b.stop()


@cocotb.test()
async def test_backpressure(dut):
    """Random i_valid gaps and random o_ready backpressure: outputs bit-exact, in order, none
    dropped or duplicated; o_valid and payload hold while stalled; i_ready follows the core's
    timing rule in every cycle (pipelined: high whenever o_ready is high and low while o_valid &
    !o_ready; folded: high exactly when nothing is in flight or the output transfers; modulo:
    high exactly when en and the phase is 0); inputs >= II cycles apart; robot top: o_leg == the
    target's random leg; latency == expected + stall cycles in between."""
    b = Bench(dut, "test_backpressure")
    try:
        await b.start()
        targets = concat(corner_targets(b.plan, port_extremes=True),
                         random_targets(b.plan, max(b.config.n_random // 2, 1), b.rng))
        n = len(next(iter(targets.values())))
        legs = b.driver.random_legs(n)
        # regimes last ~48 cycles, or ~2 evaluations of a core with II > 1
        pattern = Pattern(b.rng, BACKPRESSURE_REGIMES, regime_len=max(48, 2 * b.design.initiation_interval))
        mon, sb = await b.stream(targets, pattern, legs=legs)
        b.check_stream(targets, mon, sb, exact_latency=False, legs=legs)
        cycles = mon.out_edges[-1] - mon.in_edges[0] + 1
        b.log.info("%d targets over %d cycles with %d stall cycles: bit-exact, in order, "
                   "latency %d + stalls", n, cycles, len(mon.stall_edges), b.design.latency)
    finally:
        b.stop()


@cocotb.test()
async def test_pwm(dut):
    """PWM waveforms against the widths transferred on o (:mod:`ikseries.sim.cocotb_leg.pwm`
    has the schedule). F has a width >= P on some servo if such a target exists (constant high
    across the period boundary). Checks: low after reset and through period 0 although A, B, C
    arrive in it; every rising edge at a period start, one period apart; high time == the width
    last transferred up to that period start; the exact list of pwm (and o_valid, i_ready)
    transitions equals the model's (the timing rule's waveforms); reset at the end forces every
    output low.

    The robot top gets every target for its last leg: that leg's pwm outputs are checked as
    above, o_leg must name it, every other leg's pwm outputs must stay low, and period_start
    must be high exactly after relative edges k*P + 1.
    """
    b = Bench(dut, "test_pwm")
    d = b.design
    try:
        problem = b.rule.pwm_period_problem(d.period)
        assert problem is None, problem
        tgt, wid, has_long = pwm.pick_targets(b.model, b.servos, d.period, b.rng, b.log, _selected(b))
        sched = pwm.output_schedule(d.period, d.initiation_interval)
        n_end = pwm.window_end(wid, b.servos, d.period)
        timing = b.rule.pwm_timing(sched, n_end)
        tgt["G"] = tgt["F"]
        for nm in pwm.NAMES:
            b.log.info("target %s %s at relative output edge %d: widths %s", nm, tgt[nm], sched[nm], wid[nm])
        await b.start()
        b.driver.ready(not timing.ready_pulses)
        rel0 = b.e1 - 1                         # absolute edge = rel0 + relative edge
        logs = await _pwm_watch(b)
        await _pwm_drive(b, tgt, wid, pwm.actions(sched, timing, rel0))
        high_at_reset, reset_check = await _pwm_reset(b, logs, rel0, n_end, has_long, wid)
        _pwm_compare(b, logs, sched, wid, timing, rel0, n_end)
        reset_check.done()
        b.log.info("PWM: %d relative edges observed, waveforms match; reset with %s high "
                   "drove every output low", n_end, high_at_reset or "no output")
    finally:
        b.stop()


def _selected(b: Bench) -> int:
    """The robot top's leg under test (its last); 0 on a leg top."""
    return b.design.legs - 1


async def _pwm_watch(b: Bench) -> dict:
    """Check every pwm output low at reset release; start recording the waveforms.

    Returns {"pwm": {servo: log} of the servos under test (robot top: the selected leg's),
    "others": {(leg, servo): log}, "o_valid", "i_ready", "period_start": log}."""
    await ReadOnly()
    chk = Checker("PWM at reset release")
    for s, sig in b.ports.pwm.items():
        chk(int(sig.value) == 0, f"{sig._name} high at reset release")
    chk.done()
    sel = _selected(b)
    logs: dict = {"pwm": {s: [] for s in b.servos}, "others": {}, "o_valid": [], "i_ready": [], "period_start": []}
    for s in b.servos:
        cocotb.start_soon(watch(b.ports.pwm[(sel, s) if b.design.robot else s], logs["pwm"][s]))
    for k, sig in b.ports.pwm.items():
        if b.design.robot and k[0] != sel:
            logs["others"][k] = []
            cocotb.start_soon(watch(sig, logs["others"][k]))
    cocotb.start_soon(watch(b.ports.o_valid, logs["o_valid"]))
    cocotb.start_soon(watch(b.ports.i_ready, logs["i_ready"]))
    if b.ports.period_start is not None:
        cocotb.start_soon(watch(b.ports.period_start, logs["period_start"]))
    return logs


async def _pwm_drive(b: Bench, tgt: dict, wid: dict, act: dict) -> None:
    """Carry out the drive actions; check i_ready at every input and each output payload (and
    o_leg) before its transfer edge."""
    io = Checker("o transfers in the PWM test")
    sel = _selected(b)
    p = b.ports
    for e in sorted(act):
        a = act[e]
        await b.time.goto(e)
        if "drive" in a:
            b.driver.offer(tgt[a["drive"]] if a["drive"] else None, sel)
        if "ready" in a:
            b.driver.ready(a["ready"])
        await ReadOnly()
        if a.get("drive"):
            io(int(p.i_ready.value) == 1, f"i_ready low at the input edge of {a['drive']}")
        for nm in a.get("sample", []):
            got = {s: int(p.outputs[s].value) for s in b.servos}
            io(int(p.o_valid.value) == 1 and got == wid[nm],
               f"{nm}: o_valid={p.o_valid.value} o={got} before edge {e}, expected {wid[nm]}")
            if p.o_leg is not None:
                io(int(p.o_leg.value) == sel, f"{nm}: o_leg={int(p.o_leg.value)}, expected {sel}")
    io.done()


async def _pwm_reset(b: Bench, logs: dict, rel0: int, n_end: int, has_long: bool, wid: dict):
    """Run freely to the end of the observation window, then reset while F is still active:
    every output low one edge after rst, some output high when rst rose if F has a width >= P.
    Returns (the servos high when rst rose, the checker, reported after the waveforms)."""
    await b.time.goto(rel0 + n_end + 1)
    b.ports.rst.value = 1
    await FallingEdge(b.ports.clk)
    await ReadOnly()
    chk = Checker("reset while pulsing")
    before = {s: [v for t, v in lg if b.time.edge_at(t) - rel0 <= n_end] for s, lg in logs["pwm"].items()}
    for s, sig in b.ports.pwm.items():
        chk(int(sig.value) == 0, f"{sig._name} still high one edge after rst")
    chk(int(b.ports.o_valid.value) == 0, "o_valid high after rst")
    high = [s for s in b.servos if before[s] and before[s][-1] == 1]
    chk(bool(high) or not has_long, f"no output high when rst was raised, though F has a width >= "
                                    f"{b.design.period}: {wid['F']}")
    return high, chk


def _pwm_compare(b: Bench, logs: dict, sched: dict, wid: dict, timing, rel0: int, n_end: int) -> None:
    """The recorded waveforms against the model: pwm pulses, o_valid and i_ready (the timing
    rule's), other legs' pwm outputs low, period_start."""
    P = b.design.period

    def rel(log):       # (relative edge, value) of a value-change log, up to the window's end
        return [(n, v) for n, v in ((b.time.edge_at(t) - rel0, v) for t, v in log) if n <= n_end]
    pulse, wave = Checker(f"PWM pulses (period {P})"), Checker("PWM transitions vs model")
    first_start = (sched["A"] // P + 1) * P + 1
    for s in b.servos:
        transfers = [(sched[nm], wid[nm][s]) for nm in pwm.NAMES]
        rises, falls = pwm.check_pulses(pulse, wave, f"pwm_{s}", rel(logs["pwm"][s]), transfers, P, n_end,
                                        first_start)
        b.log.info("pwm_%s: rising edges (relative) %s, falling %s; expected widths per period %s", s, rises, falls,
                   [([wv for t, wv in transfers if t <= k * P] or [0])[-1] for k in range((n_end - 1) // P + 1)])
    ov_rec, ov_exp = rel(logs["o_valid"]), transitions(timing.o_valid)
    wave(ov_rec == ov_exp, lambda: f"o_valid: recorded {ov_rec[:12]} expected {ov_exp}")
    # a combinational i_ready: what counts is the value each rising edge sees
    ir_rec = ([(n - rel0, v) for n, v in b.time.seen_by_edges(logs["i_ready"]) if n - rel0 <= n_end]
              if timing.i_ready_combinational else rel(logs["i_ready"]))
    ir_exp = transitions(timing.i_ready, initial=1)
    wave(ir_rec == ir_exp, lambda: f"i_ready: recorded {ir_rec[:12]} expected {ir_exp[:12]}")
    for (g, s), lg in logs["others"].items():
        wave(not rel(lg), lambda: f"pwm_l{g}_{s} (no target sent to leg {g}) changed: {lg[:6]}")
    if b.design.robot:
        ps_rec = rel(logs["period_start"])
        ps_exp = transitions((np.arange(n_end) % P == 0).astype(np.int64))
        wave(ps_rec == ps_exp, lambda: f"period_start: recorded {ps_rec[:12]} expected {ps_exp[:12]}")
    wave.done()
    pulse.done()
