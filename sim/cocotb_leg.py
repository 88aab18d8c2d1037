"""cocotb testbench of the exported leg core (``ikseries.hdl.export.leg_verilog``) and robot core
(``ikseries.hdl.export.robot_verilog``).

Runs inside the simulator (Icarus or Verilator); start it with :func:`ikseries.sim.runner.run`.
Configuration comes from environment variables set by the runner:

``IKSERIES_PLAN``      plan JSON the Verilog was generated from
``IKSERIES_PERIOD``    PWM period (clock cycles) the Verilog was generated with
``IKSERIES_LATENCY``   expected latency, input transfer edge -> output transfer edge
``IKSERIES_SEED``      seed of the random targets and handshakes (default 1)
``IKSERIES_N_RANDOM``  number of random back-to-back targets (default 3000)
``IKSERIES_II``        initiation interval: cycles between input transfers (default 1, pipelined)
``IKSERIES_ARCH``      stream timing of the core: ``pipelined``, ``folded`` or ``modulo`` (default:
                       ``pipelined`` for II = 1, else ``folded``)
``IKSERIES_TOP``       ``leg`` (default) or ``robot``
``IKSERIES_LEGS``      legs of the robot top (default 1)

Expected pulse widths come from the golden integer model (:mod:`ikseries.sim.golden`),
never from the bench. Ports: clk, rst (active-high, synchronous), i_valid/i_ready/i_<input>,
o_valid/o_ready/o_<servo>, pwm_<servo>; the robot top adds i_leg/o_leg and has
pwm_l<leg>_<servo> and period_start instead of pwm_<servo>.

With an initiation interval II > 1 (a folded evaluator: one evaluation at a time) i_ready is
high exactly when no evaluation is in flight or its output transfers in that cycle, so input
transfers are at least II cycles apart; the streaming tests check that rule in every cycle
instead of the pipelined "i_ready high whenever o_ready is high". The robot top gets every
target with a random leg and must return it on o_leg.

A modulo-scheduled core (``IKSERIES_ARCH=modulo``: several targets in flight, one entering every
II cycles) has a free-running phase counter (0..II-1, 0 after reset) that advances in every
cycle with en = !o_valid | o_ready and freezes with the whole pipeline in a stall; i_ready is
en & (phase == 0), whether i_valid is high or not (an un-offered slot is a bubble). The bench
keeps its own copy of the phase (0 in the cycle before relative edge 1, advanced after every
cycle in which it sampled en high) and the streaming tests check i_ready against it in every
cycle; latency is then exact plus the stall cycles in between, as for the other cores.

The PWM test keeps its output schedule on a modulo core, but not its input schedule (input edges
depend on the phase): each pair of targets (A B, C D, then F) enters at the first phase-0 edge after
the previous pair has transferred (the second II edges later) and waits at the output, o_valid high
and o_ready low, until its scheduled transfer edge, where o_ready is raised for one cycle; a last
target G (F again) arrives after F and is never accepted. So the scheduled edges are met for any
period the test accepts, the pipeline is frozen (en low) nearly all the time, which is what makes
the ~5 simulated periods affordable on Icarus (the running modulo pipeline simulates at a few
thousand cycles per second there), and o_valid held with o_ready low must not load the PWM
generators. The bench models the phase through these stalls (:func:`_modulo_timing`) and checks the
whole o_valid and i_ready waveforms against it.

Timing conventions: the clock starts low at ``t0`` and rises at ``t0 + T/2 + e*T``
(rising edge ``e``); the falling edge at ``t0 + e*T`` precedes rising edge ``e``. The bench
writes inputs at falling edges and samples after ``ReadOnly()`` at falling edges, so what it
samples is what the next rising edge sees; a transfer "at edge e" means valid & ready were
sampled high by rising edge ``e``.
"""
from __future__ import annotations

import bisect
import json
import os

import numpy as np

import cocotb
from cocotb.clock import Clock
from cocotb.simtime import convert, get_sim_time
from cocotb.triggers import FallingEdge, ReadOnly, Timer, ValueChange

from ikseries.fit.plan import Plan
from ikseries.sim import golden
from ikseries.sim.targets import corner_targets, random_targets
from ikseries.sim.runner import (ENV_ARCH, ENV_II, ENV_LATENCY, ENV_LEGS, ENV_N_RANDOM, ENV_PERIOD, ENV_PLAN, ENV_SEED,
                                 ENV_TOP)

CLK_NS = 10
MAX_ERRORS = 12     # messages kept per check


def concat(*targets) -> dict:
    return {n: np.concatenate([t[n] for t in targets]) for n in targets[0]}


class Checker:
    """Collects failures of one check; ``done()`` fails the test listing the first ones."""

    def __init__(self, what: str):
        self.what, self.count, self.msgs = what, 0, []

    def __call__(self, cond, msg) -> bool:
        if not cond:
            self.count += 1
            if len(self.msgs) < MAX_ERRORS:
                self.msgs.append(msg() if callable(msg) else msg)
        return bool(cond)

    def done(self):
        assert self.count == 0, (f"{self.what}: {self.count} failure(s); first ones:\n  "
                                 + "\n  ".join(self.msgs))


class Leg:
    """Driver, monitor and timing bookkeeping for one cocotb test."""

    def __init__(self, dut, test_id: int):
        self.dut = dut
        self.log = dut._log
        with open(os.environ[ENV_PLAN]) as f:
            self.plan = Plan.from_json(json.load(f))
        self.period = int(os.environ[ENV_PERIOD])
        self.latency = int(os.environ[ENV_LATENCY])
        self.seed = int(os.environ.get(ENV_SEED, "1"))
        self.n_random = int(os.environ.get(ENV_N_RANDOM, "3000"))
        self.ii = int(os.environ.get(ENV_II, "1"))
        self.arch = os.environ.get(ENV_ARCH) or ("pipelined" if self.ii == 1 else "folded")
        self.robot = os.environ.get(ENV_TOP, "leg") == "robot"
        self.legs = int(os.environ.get(ENV_LEGS, "1"))
        assert self.ii >= 1 and self.legs >= 1 and (self.robot or self.legs == 1) \
            and self.arch in ("pipelined", "folded", "modulo"), \
            (f"bad bench configuration: II {self.ii}, architecture {self.arch}, "
             f"top {os.environ.get(ENV_TOP)}, legs {self.legs}")
        self.rng = np.random.default_rng([self.seed, test_id])
        self.inputs = list(self.plan.inputs)
        self.servos = [o.name for o in self.plan.outputs]
        self.i_sig = {i.name: getattr(dut, f"i_{i.name}") for i in self.inputs}
        self.o_sig = {s: getattr(dut, f"o_{s}") for s in self.servos}
        # leg top: {servo: pwm_<servo>}; robot top: {(leg, servo): pwm_l<leg>_<servo>}
        if self.robot:
            self.pwm_sig = {(g, s): getattr(dut, f"pwm_l{g}_{s}") for g in range(self.legs)
                            for s in self.servos}
        else:
            self.pwm_sig = {s: getattr(dut, f"pwm_{s}") for s in self.servos}
        # a one-leg robot core has zero-width leg ports (not exported)
        self.i_leg = getattr(dut, "i_leg", None) if self.robot and self.legs > 1 else None
        self.o_leg = getattr(dut, "o_leg", None) if self.robot and self.legs > 1 else None
        self.T = int(convert(CLK_NS, "ns", to="step"))
        assert self.T % 2 == 0
        self.clock = None
        self.t0 = None
        self.e1 = None          # first rising edge with rst low (relative edge 1)

    # ---- time ---------------------------------------------------------------------------
    def upcoming(self) -> int:
        """Index of the next rising edge; only valid at a falling-edge time."""
        q, r = divmod(get_sim_time("step") - self.t0, self.T)
        assert r == 0, f"bench not at a falling edge (t={get_sim_time('step')}, t0={self.t0})"
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

    def edge_at(self, t: int) -> int:
        """Rising-edge index of time ``t`` (must be a rising-edge time)."""
        q, r = divmod(t - self.t0 - self.T // 2, self.T)
        assert r == 0, f"signal changed at t={t} steps, not at a rising clock edge"
        return q

    async def goto(self, e: int):
        """Move to the falling edge right before rising edge ``e`` (strictly in the future)."""
        now = get_sim_time("step")
        target = self.t0 + e * self.T
        assert target > now, f"goto({e}) is not in the future"
        await Timer(target - now - self.T // 2, "step")   # lands on rising edge e-1
        await FallingEdge(self.dut.clk)
        assert get_sim_time("step") == target

    # ---- start / reset ----------------------------------------------------------------
    def drive_inputs(self, values: dict | None, leg: int | None = None):
        """Drive target ``values`` ({input: int}) for ``leg`` (robot top); None: random port
        junk (i_valid is low)."""
        for i in self.inputs:
            if values is None:
                lo, hi = i.port_range
                v = int(self.rng.integers(lo, hi + 1))
            else:
                v = int(values[i.name])
            self.i_sig[i.name].value = v
        if self.i_leg is not None:
            self.i_leg.value = int(self.rng.integers(self.legs)) if values is None or leg is None else int(leg)

    def random_legs(self, n: int) -> np.ndarray:
        """Random leg per target (all 0 for the leg top)."""
        return self.rng.integers(0, self.legs, n) if self.robot else np.zeros(n, dtype=np.int64)

    async def start(self, reset_cycles: int = 3):
        dut = self.dut
        dut.rst.value = 1
        dut.i_valid.value = 0
        dut.o_ready.value = 0
        self.drive_inputs(None)
        self.t0 = get_sim_time("step")
        # C clock (GPI): about 1.5x faster than the Python one on Icarus
        self.clock = Clock(dut.clk, CLK_NS, unit="ns", impl="gpi")
        self.clock.start(start_high=False)
        chk = Checker("reset state")
        for c in range(reset_cycles):
            await FallingEdge(dut.clk)
            await ReadOnly()
            # after a reset edge: pipeline empty, PWM outputs low
            chk(int(dut.o_valid.value) == 0, f"o_valid high after {c + 1} reset edge(s)")
            for s, sig in self.pwm_sig.items():
                chk(int(sig.value) == 0, f"pwm_{s} high after {c + 1} reset edge(s)")
        chk.done()
        await FallingEdge(dut.clk)
        dut.rst.value = 0
        self.e1 = self.upcoming()

    def stop(self):
        if self.clock is not None:
            self.clock.stop()
            self.clock = None

    # ---- streaming ----------------------------------------------------------------------
    async def stream(self, targets: dict, regimes, regime_len: int = 64, legs=None):
        """Offer ``targets`` in order and collect the outputs.

        ``regimes``: list of (p_valid, p_ready); every ``regime_len`` cycles one is chosen at
        random. i_valid is offered with probability p_valid, o_ready with p_ready (1.0 =
        always). ``legs``: leg of each target (robot top). Checks the handshake rules on the
        way; returns (outputs, in edges, out edges, stall edges, handshake checker); the
        outputs include ``"leg"`` (o_leg, 0 on the leg top).
        """
        dut, rng = self.dut, self.rng
        n = len(next(iter(targets.values())))
        legs = np.zeros(n, dtype=np.int64) if legs is None else legs
        got = {s: [] for s in self.servos}
        got_leg = []
        in_e, out_e, stall_e = [], [], []
        hs = Checker("stream handshake")
        k, held, cycle, drain = 0, None, 0, 0
        phase = None        # modulo core: the bench's copy of the phase counter
        p_valid, p_ready = regimes[0]
        limit = 50 * n * self.ii + 10 * self.latency + 1000
        while drain <= self.latency + 4:
            await FallingEdge(dut.clk)
            e = self.upcoming()
            if cycle % regime_len == 0:
                p_valid, p_ready = regimes[rng.integers(len(regimes))]
            offer = k < n and (p_valid >= 1 or rng.random() < p_valid)
            ready = p_ready >= 1 or rng.random() < p_ready
            dut.i_valid.value = int(offer)
            self.drive_inputs({name: targets[name][k] for name in targets} if offer else None,
                              legs[k] if offer else None)
            dut.o_ready.value = int(ready)
            await ReadOnly()
            ov, ir = int(dut.o_valid.value), int(dut.i_ready.value)
            pay = None
            if ov:
                pay = tuple(int(self.o_sig[s].value) for s in self.servos) + (
                    (int(self.o_leg.value),) if self.o_leg is not None else (0,))
            if self.arch == "modulo":
                if phase is None:   # nothing sent since reset release: en high in every cycle since
                    phase = (e - self.e1) % self.ii
                en = int(not ov or ready)
                hs(ir == int(en and phase == 0),
                   lambda: f"edge {e}: i_ready {ir}, expected {int(en and phase == 0)} (modulo schedule: "
                           f"phase {phase} of II {self.ii}, o_valid {ov}, o_ready {int(ready)})")
                phase = (phase + en) % self.ii
            elif self.ii == 1:
                hs(ir or not ready, lambda: f"edge {e}: i_ready low while o_ready high (stalls the stream)")
                hs(not (ov and not ready and ir), lambda: f"edge {e}: i_ready high while o_valid & !o_ready")
            else:
                # one evaluation at a time: ready iff none in flight or its output transfers now
                idle = len(in_e) == len(out_e)
                hs(ir == int(idle or (ov and ready)),
                   lambda: f"edge {e}: i_ready {ir} with {len(in_e) - len(out_e)} target(s) in flight, "
                           f"o_valid {ov}, o_ready {int(ready)}")
            if held is not None:
                hs(ov and pay == held, lambda: f"edge {e}: o_valid/o payload changed while stalled: "
                                               f"{held} -> {pay if ov else 'o_valid low'}")
            held = pay if ov and not ready else None
            if offer and ir:
                in_e.append(e)
                k += 1
            if ov and ready:
                if hs(len(out_e) < n, lambda: f"edge {e}: output beyond the {n} targets sent: {pay}"):
                    out_e.append(e)
                    for s, v in zip(self.servos, pay):
                        got[s].append(v)
                    got_leg.append(pay[-1])
            if ov and not ready:
                stall_e.append(e)
            if len(out_e) == n:
                drain += 1
            cycle += 1
            if not hs(cycle < limit, f"no progress: {len(in_e)} inputs and {len(out_e)} outputs "
                                     f"of {n} after {cycle} cycles"):
                break
        await FallingEdge(dut.clk)
        dut.i_valid.value = 0
        dut.o_ready.value = 1
        got = {s: np.array(v, dtype=np.int64) for s, v in got.items()}
        got["leg"] = np.array(got_leg, dtype=np.int64)
        return got, in_e, out_e, stall_e, hs

    def check_stream(self, targets, got, in_e, out_e, stall_e, hs, exact_latency: bool, legs=None):
        """Bit-exact and in-order vs golden (and o_leg == the target's leg on the robot top);
        latency per target (stall cycles subtracted); input transfers >= II cycles apart."""
        n = len(next(iter(targets.values())))
        exp = golden.outputs(self.plan, targets)
        hs.done()
        cnt = Checker("transfer count")
        cnt(len(in_e) == n, f"{len(in_e)} input transfers for {n} targets")
        cnt(len(out_e) == n, f"{len(out_e)} output transfers for {n} targets")
        cnt.done()
        bits = Checker(f"outputs vs golden model ({n} targets)")
        for j in range(n):
            bad = [s for s in self.servos if got[s][j] != exp[s][j]]
            bits(not bad, lambda: (f"target {j} " + str({nm: int(v[j]) for nm, v in targets.items()})
                                   + ": " + ", ".join(f"{s} got {int(got[s][j])} expected {int(exp[s][j])}"
                                                      for s in bad)))
        bits.done()
        if self.o_leg is not None:
            legc = Checker(f"o_leg vs i_leg ({n} targets)")
            for j in range(n):
                legc(got["leg"][j] == legs[j], lambda: f"target {j}: o_leg {int(got['leg'][j])}, "
                                                       f"sent to leg {int(legs[j])}")
            legc.done()
        gap = Checker(f"initiation interval (input transfers >= {self.ii} cycles apart)")
        for j, d in enumerate(np.diff(in_e)):
            gap(d >= self.ii, lambda: f"targets {j} and {j + 1}: input edges {in_e[j]} and {in_e[j + 1]}, "
                                      f"{d} cycle(s) apart")
        gap.done()
        lat = Checker(f"latency (expected {self.latency} cycles)")
        for j, (a, b) in enumerate(zip(in_e, out_e)):
            stalls = bisect.bisect_left(stall_e, b) - bisect.bisect_right(stall_e, a)
            if exact_latency:
                lat(b - a == self.latency and stalls == 0,
                    lambda: f"target {j}: input edge {a}, output edge {b}: {b - a} cycles")
            else:
                lat(b - a - stalls == self.latency,
                    lambda: f"target {j}: input edge {a}, output edge {b}: {b - a} cycles "
                            f"including {stalls} stall cycle(s) -> {b - a - stalls}")
        lat.done()
        return exp


@cocotb.test()
async def test_back_to_back(dut):
    """Corner + random targets offered every cycle, o_ready always high: bit-exact outputs in
    order (robot top: each to a random leg, returned on o_leg), one input and one output transfer
    every II cycles exactly (II = 1: i_ready never low, one output per cycle), latency ==
    IKSERIES_LATENCY for every target."""
    leg = Leg(dut, 1)
    try:
        await leg.start()
        targets = concat(corner_targets(leg.plan, port_extremes=True), random_targets(leg.plan, leg.n_random, leg.rng))
        n = len(next(iter(targets.values())))
        legs = leg.random_legs(n)
        got, in_e, out_e, stall_e, hs = await leg.stream(targets, [(1.0, 1.0)], legs=legs)
        leg.check_stream(targets, got, in_e, out_e, stall_e, hs, exact_latency=True, legs=legs)
        if leg.ii == 1:
            thr = Checker("throughput (one target per cycle)")
            thr(np.all(np.diff(in_e) == 1), "input transfers not on consecutive edges")
            thr(np.all(np.diff(out_e) == 1), "output transfers not on consecutive edges")
        else:
            thr = Checker(f"throughput (one target every {leg.ii} cycles)")
            thr(np.all(np.diff(in_e) == leg.ii), lambda: f"input transfer gaps {sorted(set(np.diff(in_e).tolist()))}")
            thr(np.all(np.diff(out_e) == leg.ii), lambda: f"output transfer gaps {sorted(set(np.diff(out_e).tolist()))}")
        thr.done()
        leg.log.info("%d targets (%d corner) back to back, one every %d cycle(s)%s: bit-exact, latency %d "
                     "cycles each, edges %d..%d", n, n - leg.n_random, leg.ii,
                     f", legs {sorted(set(legs.tolist()))}" if leg.robot else "", leg.latency, in_e[0], out_e[-1])
    finally:
        leg.stop()


@cocotb.test()
async def test_backpressure(dut):
    """Random i_valid gaps and random o_ready backpressure: outputs bit-exact, in order, none
    dropped or duplicated; o_valid and payload hold while stalled; i_ready high whenever o_ready
    is high and low while o_valid & !o_ready (II > 1: i_ready high exactly when nothing is in
    flight or the output transfers; modulo core: i_ready high exactly when en and the phase is 0);
    inputs >= II cycles apart; robot top: o_leg == the target's random leg; latency == expected +
    stall cycles in between."""
    leg = Leg(dut, 2)
    try:
        await leg.start()
        targets = concat(corner_targets(leg.plan, port_extremes=True), random_targets(leg.plan, max(leg.n_random // 2, 1), leg.rng))
        n = len(next(iter(targets.values())))
        legs = leg.random_legs(n)
        regimes = [(0.5, 0.5), (0.9, 0.3), (0.3, 0.9), (1.0, 0.7), (0.8, 1.0), (0.1, 0.1), (1.0, 0.0)]
        # regimes last ~48 cycles, or ~2 evaluations of a core with II > 1
        got, in_e, out_e, stall_e, hs = await leg.stream(targets, regimes, regime_len=max(48, 2 * leg.ii),
                                                         legs=legs)
        leg.check_stream(targets, got, in_e, out_e, stall_e, hs, exact_latency=False, legs=legs)
        cycles = out_e[-1] - in_e[0] + 1
        leg.log.info("%d targets over %d cycles with %d stall cycles: bit-exact, in order, "
                     "latency %d + stalls", n, cycles, len(stall_e), leg.latency)
    finally:
        leg.stop()


def _pwm_expected(transfers, period: int, n_end: int) -> np.ndarray:
    """Expected pwm value after each relative edge 1..n_end for one servo.

    ``transfers``: list of (relative transfer edge, width). The width latched at relative edge
    k*period (the last transfer at an edge <= k*period; 0 before any) is active in period k,
    and the registered output is high after edges k*period + 1 .. k*period + width.
    """
    n = np.arange(1, n_end + 1)
    k_max = (n_end - 1) // period
    active = np.zeros(k_max + 1, dtype=np.int64)
    for k in range(1, k_max + 1):
        before = [w for t, w in transfers if t <= k * period]
        active[k] = before[-1] if before else 0
    return ((n - 1) % period < active[(n - 1) // period]).astype(np.int64)


def _transitions(values: np.ndarray, first_edge: int = 1, initial: int = 0) -> list[tuple[int, int]]:
    """(edge, new value) wherever ``values`` (after edges first_edge, ...) changes; starts from
    ``initial``."""
    v = np.concatenate([[initial], values])
    idx = np.flatnonzero(np.diff(v))
    return [(int(i) + first_edge, int(v[i + 1])) for i in idx]


def _modulo_timing(sched_rel: dict, L: int, II: int):
    """Input edges, output arrival edges and the i_ready model of the PWM test on a modulo core.

    ``sched_rel``: scheduled output transfer edge of A, B, C, D, F (relative edges); o_ready is
    high only in the cycles before those edges. Pairs (A, B), (C, D), then F and G (F again,
    never accepted) enter at the first edge with phase 0 after the previous group's last
    transfer (the second II edges later). The first of a group arrives L - 1 edges after its
    input (o_valid high after that edge); one behind a waiting output arrives II - 1 edges after
    that output transfers. A cycle with o_valid high and o_ready low freezes the phase.

    Returns (input edge per name, arrival edge per name, ``ready(r)``: expected i_ready sampled
    by relative edges ``r`` (an array)).
    """
    waits: list = []        # (arrival edge, transfer edge or None) of every output

    def ready(r):
        r = np.asarray(r, dtype=np.int64)
        frozen_before = np.zeros_like(r)
        frozen_now = np.zeros(r.shape, dtype=bool)
        for arr, t in waits:
            end = r if t is None else np.minimum(r, t)
            frozen_before += np.maximum(end - arr - 1, 0)
            frozen_now |= (r > arr) & ((r < t) if t is not None else True)
        return (~frozen_now & ((r - 1 - frozen_before) % II == 0)).astype(np.int64)

    in_rel, arrive = {}, {}
    start = 2                   # relative edge 1 has already been driven by the reset release
    for group in (("A", "B"), ("C", "D"), ("F",), ("G",)):
        a = start
        while not ready(a):
            a += 1
        prev = None
        for j, nm in enumerate(group):
            in_rel[nm] = a + j * II
            arrive[nm] = a + L - 1 if prev is None else sched_rel[prev] + II - 1
            t = sched_rel.get(nm)
            assert t is None or arrive[nm] < t, f"PWM test: {nm} arrives after edge {arrive[nm]}, due at {t}"
            waits.append((arrive[nm], t))
            prev = nm
        start = sched_rel.get(group[-1], 0) + 1
    return in_rel, arrive, ready


async def _watch(sig, log: list):
    while True:
        await ValueChange(sig)
        log.append((get_sim_time("step"), int(sig.value)))


@cocotb.test()
async def test_pwm(dut):
    """PWM waveforms against the widths transferred on o (o_ready held high).

    Relative edge 1 is the first rising edge after reset; period k starts at relative edge
    k*P (P = IKSERIES_PERIOD). Schedule of output transfers: A at P/2 and B at P/2+1 (B
    replaces A), C at P (the boundary edge itself: applies to period 1), D at P+1 (during C's
    pulse: applies to period 2 only), F at 2P+5 (during D's pulse), nothing afterwards (F
    repeats in periods 3 and 4). F has a width >= P on some servo if such a target exists
    (constant high across the period boundary). Checks: low after reset and through period 0
    although A, B, C arrive in it; every rising edge at a period start, one period apart;
    high time == the width last transferred up to that period start; the exact list of pwm
    (and o_valid, i_ready) transitions equals the model's; reset at the end forces every output low.

    With an initiation interval II > 1, B and D come II edges after A and C (folded core: B's input
    transfers at A's output edge). A modulo core gets its inputs early and o_ready only at the
    scheduled edges (see the module docstring). The robot top gets every target for its last leg:
    that leg's pwm outputs are checked as above, o_leg must name it, every other leg's pwm outputs
    must stay low, and period_start must be high exactly after relative edges k*P + 1.
    """
    leg = Leg(dut, 3)
    P, L, II = leg.period, leg.latency, leg.ii
    sel = leg.legs - 1                          # the robot top's leg under test
    try:
        assert P // 2 - L >= 2 and P // 2 >= 2 * II, \
            f"PWM test needs a period of at least {max(2 * L + 4, 4 * II)} cycles, got {P}"
        # pick targets by their golden widths
        pool = random_targets(leg.plan, 4000, leg.rng)
        w = golden.outputs(leg.plan, pool)
        W = np.stack([w[s] for s in leg.servos], axis=1)
        short = np.flatnonzero(np.all((W > 0) & (W < P), axis=1))
        long_ = np.flatnonzero(np.any(W >= P, axis=1) & np.any(W < P, axis=1))
        assert len(short) >= 4, (f"PWM test needs targets whose widths are all below the period "
                                 f"{P}; golden widths span {W.min()}..{W.max()}")
        picks: list[int] = []
        for j in short:        # A, B, C, D: widths differ per servo from the ones already picked
            if all(np.all(W[j] != W[p]) for p in picks):
                picks.append(int(j))
            if len(picks) == 4:
                break
        # F: a target with a width >= P if there is one, preferring short other widths (their
        # pulses in period 4 bound the simulated time)
        f_pool = [int(j) for j in (long_ if len(long_) else short)
                  if all(np.all(W[j] != W[p]) for p in picks)]
        picks.append(min(f_pool, key=lambda j: int(np.max(W[j], initial=0, where=W[j] < P))))
        if not len(long_):
            leg.log.info("no target has a width >= the period %d: constant-high case not covered", P)
        names = "ABCDF"
        sched_rel = {"A": P // 2, "B": P // 2 + II, "C": P, "D": P + II, "F": 2 * P + 5}  # output edges
        modulo = leg.arch == "modulo"
        in_rel = {nm: sched_rel[nm] - L for nm in names}   # input transfer edges
        if modulo:
            assert P // 2 >= L + 2 * II + 1 and II < L, \
                f"PWM test of a modulo core needs a period of at least {2 * (L + 2 * II + 1)} cycles and II < latency"
            in_rel, arrive, ir_model = _modulo_timing(sched_rel, L, II)
        tgt = {nm: {i.name: int(pool[i.name][j]) for i in leg.inputs} for nm, j in zip(names, picks)}
        tgt["G"] = tgt["F"]
        wid = {nm: {s: int(W[j, c]) for c, s in enumerate(leg.servos)} for nm, j in zip(names, picks)}
        for nm in names:
            leg.log.info("target %s %s at relative output edge %d: widths %s", nm, tgt[nm],
                         sched_rel[nm], wid[nm])
        f_short = [wid["F"][s] for s in leg.servos if wid["F"][s] < P]
        n_end = 4 * P + 1 + (max(f_short) if f_short else 0) + 8   # last relative edge observed

        await leg.start()
        dut.o_ready.value = int(not modulo)
        rel0 = leg.e1 - 1                       # absolute edge = rel0 + relative edge
        await ReadOnly()
        chk = Checker("PWM at reset release")
        for s, sig in leg.pwm_sig.items():
            chk(int(sig.value) == 0, f"{sig._name} high at reset release")
        chk.done()
        # pwm of the servos under test (leg top: all; robot top: leg `sel`'s)
        pwm_sel = {s: leg.pwm_sig[(sel, s) if leg.robot else s] for s in leg.servos}
        others = {k: sig for k, sig in leg.pwm_sig.items() if leg.robot and k[0] != sel}
        logs = {s: [] for s in leg.servos}
        other_logs = {k: [] for k in others}
        ov_log, ir_log, ps_log = [], [], []
        for s in leg.servos:
            cocotb.start_soon(_watch(pwm_sel[s], logs[s]))
        for k, sig in others.items():
            cocotb.start_soon(_watch(sig, other_logs[k]))
        cocotb.start_soon(_watch(dut.o_valid, ov_log))
        cocotb.start_soon(_watch(dut.i_ready, ir_log))
        if leg.robot:
            cocotb.start_soon(_watch(dut.period_start, ps_log))

        # drive: input at in_rel (pipelined, folded: output edge - L); sample the output payload
        # before its transfer edge; modulo: o_ready high only in the cycles before transfer edges
        actions: dict = {}
        for nm, r in in_rel.items():
            actions.setdefault(rel0 + r, {})["drive"] = nm
        for nm in names:
            actions.setdefault(rel0 + sched_rel[nm], {}).setdefault("sample", []).append(nm)
            if modulo:
                actions[rel0 + sched_rel[nm]]["ready"] = 1
        if modulo:
            for nm in names:
                actions.setdefault(rel0 + sched_rel[nm] + 1, {}).setdefault("ready", 0)
        for e in [e for e, a in actions.items() if a.get("drive")]:
            if not actions.get(e + 1, {}).get("drive"):
                actions.setdefault(e + 1, {})["drive"] = ""        # i_valid low again
        io = Checker("o transfers in the PWM test")
        for e in sorted(actions):
            act = actions[e]
            await leg.goto(e)
            if "drive" in act:
                dut.i_valid.value = int(bool(act["drive"]))
                leg.drive_inputs(tgt[act["drive"]] if act["drive"] else None, sel)
            if "ready" in act:
                dut.o_ready.value = act["ready"]
            await ReadOnly()
            if act.get("drive"):
                io(int(dut.i_ready.value) == 1, f"i_ready low at the input edge of {act['drive']}")
            for nm in act.get("sample", []):
                got = {s: int(leg.o_sig[s].value) for s in leg.servos}
                io(int(dut.o_valid.value) == 1 and got == wid[nm],
                   f"{nm}: o_valid={dut.o_valid.value} o={got} before edge {e}, expected {wid[nm]}")
                if leg.o_leg is not None:
                    io(int(leg.o_leg.value) == sel, f"{nm}: o_leg={int(leg.o_leg.value)}, expected {sel}")
        io.done()

        # run freely to the end of the observation window, then reset while F is still active
        await leg.goto(rel0 + n_end + 1)
        dut.rst.value = 1
        await FallingEdge(dut.clk)
        await ReadOnly()
        rst_chk = Checker("reset while pulsing")
        before = {s: [v for t, v in logs[s] if leg.edge_at(t) - rel0 <= n_end] for s in leg.servos}
        for s, sig in leg.pwm_sig.items():
            rst_chk(int(sig.value) == 0, f"{sig._name} still high one edge after rst")
        rst_chk(int(dut.o_valid.value) == 0, "o_valid high after rst")
        high_at_reset = [s for s in leg.servos if before[s] and before[s][-1] == 1]
        rst_chk(bool(high_at_reset) or not len(long_),
                f"no output high when rst was raised, though F has a width >= {P}: {wid['F']}")

        # ---- compare the recorded waveforms with the model --------------------------------
        transfers = {s: [(sched_rel[nm], wid[nm][s]) for nm in names] for s in leg.servos}
        pulse = Checker(f"PWM pulses (period {P})")
        wave = Checker("PWM transitions vs model")
        for s in leg.servos:
            rec = [(leg.edge_at(t) - rel0, v) for t, v in logs[s]]
            rec = [(n, v) for n, v in rec if n <= n_end]
            exp_tr = _transitions(_pwm_expected(transfers[s], P, n_end))
            wave(rec == exp_tr, lambda: f"pwm_{s}: recorded (relative edge, value) {rec[:12]} "
                                        f"expected {exp_tr[:12]}")
            # the brief's measurements, made on the recording itself
            rises = [n for n, v in rec if v == 1]
            falls = [n for n, v in rec if v == 0]
            first_start = (sched_rel["A"] // P + 1) * P + 1
            pulse(not rises or rises[0] >= first_start,
                  f"pwm_{s}: pulse at relative edge {rises[:1]} before the first period start "
                  f"after the first target ({first_start})")
            for r in rises:
                k, off = divmod(r - 1, P)
                pulse(off == 0, f"pwm_{s}: rising edge at relative edge {r}, not at a period start")
                last = [wv for t, wv in transfers[s] if t <= k * P]
                want = last[-1] if last else 0
                fall = next((x for x in falls if x > r), None)
                if want < P:
                    pulse(fall == r + want, f"pwm_{s}: period {k}: high {None if fall is None else fall - r} "
                                            f"cycles, expected {want} (the width last transferred)")
            for a, b in zip(rises, rises[1:]):
                pulse((b - a) % P == 0, f"pwm_{s}: rising edges {a} and {b} are "
                                        f"{b - a} cycles apart, period {P}")
            leg.log.info("%s: rising edges (relative) %s, falling %s; expected widths per period %s",
                         pwm_sel[s]._name, rises, falls, [([wv for t, wv in transfers[s] if t <= k * P] or [0])[-1]
                                           for k in range((n_end - 1) // P + 1)])
            pulse(len(rises) >= 3, f"pwm_{s}: only {len(rises)} pulses seen")
        # o_valid: high exactly in the cycle before each output transfer edge
        ov_rec = [(leg.edge_at(t) - rel0, v) for t, v in ov_log]
        ov_vals = np.zeros(n_end, dtype=np.int64)
        for nm in names:
            ov_vals[sched_rel[nm] - 2] = 1      # high after relative edge (transfer edge - 1)
            if modulo:                          # and from its arrival on (waiting, o_ready low)
                ov_vals[arrive[nm] - 1:sched_rel[nm] - 1] = 1
        if modulo:
            ov_vals[arrive["G"] - 1:] = 1       # G waits until the final reset
        ov_exp = _transitions(ov_vals)
        wave([x for x in ov_rec if x[0] <= n_end] == ov_exp,
             lambda: f"o_valid: recorded {ov_rec[:12]} expected {ov_exp}")
        # i_ready (o_ready high): II = 1 always high; folded: low after an input transfer edge
        # until one cycle before its output transfer edge; modulo: en & phase 0 (the model)
        ir_vals = np.ones(n_end, dtype=np.int64)
        if modulo:
            ir_vals = ir_model(np.arange(2, n_end + 2))     # after edge n: what edge n + 1 sees
        elif II > 1:
            for nm in names:
                ir_vals[sched_rel[nm] - L - 1:sched_rel[nm] - 2] = 0   # relative edges in .. out-2
        # modulo: i_ready = en & phase 0 follows o_ready (driven at falling edges) at once;
        # what counts is the value each rising edge sees
        ir_rec = ([(n - rel0, v) for n, v in leg.seen_by_edges(ir_log)] if modulo else
                  [(leg.edge_at(t) - rel0, v) for t, v in ir_log])
        ir_exp = _transitions(ir_vals, initial=1)
        wave([x for x in ir_rec if x[0] <= n_end] == ir_exp,
             lambda: f"i_ready: recorded {ir_rec[:12]} expected {ir_exp[:12]}")
        for (g, s), lg in other_logs.items():
            wave(not [x for x in lg if leg.edge_at(x[0]) - rel0 <= n_end],
                 lambda: f"pwm_l{g}_{s} (no target sent to leg {g}) changed: {lg[:6]}")
        if leg.robot:
            ps_rec = [(leg.edge_at(t) - rel0, v) for t, v in ps_log]
            ps_exp = _transitions((np.arange(n_end) % P == 0).astype(np.int64))
            wave([x for x in ps_rec if x[0] <= n_end] == ps_exp,
                 lambda: f"period_start: recorded {ps_rec[:12]} expected {ps_exp[:12]}")
        wave.done()
        pulse.done()
        rst_chk.done()
        leg.log.info("PWM: %d relative edges observed, waveforms match; reset with %s high "
                     "drove every output low", n_end, high_at_reset or "no output")
    finally:
        leg.stop()
