"""Timing rules: what i_ready must be at each edge and when an output may arrive, one rule per
stream rule of the manifest (``"stream_rule"``, :func:`ikseries.hdl.export.stream_rule`).

A rule serves both kinds of test:

* streaming (back to back, backpressure): :meth:`TimingRule.check` is called for every sampled
  cycle, before its transfers are recorded, and returns the violations of the i_ready rule;
* the PWM test: :meth:`TimingRule.pwm_timing` turns the scheduled output transfer edges into the
  input edges, the o_ready pattern and the whole expected o_valid and i_ready waveforms.

Rules
-----
``pipelined`` (:class:`Pipelined`)
    Global stall, one target per cycle: i_ready high whenever o_ready is high, low while
    o_valid & !o_ready.
``folded`` (:class:`Folded`)
    One evaluation in flight: i_ready high exactly when none is in flight or its output
    transfers in that cycle, so input transfers are at least II cycles apart.
``modulo`` (:class:`Modulo`)
    Several targets in flight, one entering every II cycles: a free-running phase counter
    (0..II-1, 0 after reset) advances in every cycle with en = !o_valid | o_ready and freezes
    with the whole pipeline in a stall; i_ready is en & (phase == 0), whether i_valid is high or
    not (an un-offered slot is a bubble). The rule keeps its own copy of the phase (0 in the
    cycle before relative edge 1, advanced after every cycle in which en was sampled high).
``buffered`` (:class:`Buffered`)
    One target per cycle into a pipeline that never stalls, its outputs buffered in a FIFO of
    latency + 1 words: i_ready high exactly while fewer targets than that are in flight.

Adding a timing rule for a new architecture
-------------------------------------------
1. Give the core's stream rule a name in :data:`ikseries.hdl.architectures.STREAM_RULES` and return it
   from :func:`ikseries.hdl.export.stream_rule` for that core, so its manifest says it.
2. Subclass :class:`TimingRule` here: ``name`` (that string), :meth:`~TimingRule.check` (the
   i_ready rule of one cycle; keep any state it needs, reset in :meth:`~TimingRule.start`),
   and, if the PWM test's default schedule (inputs ``latency`` edges before their output edges,
   o_ready always high) does not fit it, :meth:`~TimingRule.pwm_timing` and
   :meth:`~TimingRule.pwm_period_problem`.
3. Add the class to :data:`RULES`; the tests pick the rule from the manifest, nothing else
   changes. Give the core a cocotb run in ``tests/test_cocotb.py`` and a run told a wrong
   latency or interval, to show the rule can fail.

This module does not import cocotb (the run configuration validates manifests against
:data:`RULES` outside the simulator).
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .monitor import Sample

__all__ = ["PwmTiming", "TimingRule", "Pipelined", "Folded", "Modulo", "Buffered", "RULES", "timing_rule"]


@dataclasses.dataclass(frozen=True)
class PwmTiming:
    """The PWM test's stream timing on one core (relative edges: 1 = first edge after reset).

    Attributes
    ----------
    inputs : dict
        Input transfer edge per target name.
    ready_pulses : bool
        o_ready is high only in the cycle before each scheduled output transfer edge (else
        always high).
    o_valid : numpy array
        Expected o_valid after relative edges 1..n_end.
    i_ready : numpy array
        Expected i_ready after relative edges 1..n_end (what edges 2..n_end + 1 see).
    i_ready_combinational : bool
        i_ready follows o_ready (driven at falling edges) at once: compare what each rising edge
        sees rather than when it changes.
    """
    inputs: dict
    ready_pulses: bool
    o_valid: np.ndarray
    i_ready: np.ndarray
    i_ready_combinational: bool


def _transfer_o_valid(sched: dict, n_end: int) -> np.ndarray:
    """o_valid high exactly in the cycle before each output transfer edge."""
    ov = np.zeros(n_end, dtype=np.int64)
    for t in sched.values():
        ov[t - 2] = 1       # high after relative edge (transfer edge - 1)
    return ov


class TimingRule:
    """Base of the timing rules; see the module docstring.

    Parameters
    ----------
    latency : int
        Expected latency, input transfer edge -> output transfer edge, cycles.
    initiation_interval : int
        Cycles between input transfers.
    """

    name = ""

    def __init__(self, latency: int, initiation_interval: int):
        self.latency, self.ii = latency, initiation_interval

    def start(self, first_edge: int) -> None:
        """Reset release: ``first_edge`` is the absolute index of relative edge 1."""

    def check(self, s: "Sample", in_flight: int) -> list[str]:
        """Violations of the i_ready rule in sample ``s`` (``in_flight``: targets in the core
        before this cycle's transfers)."""
        raise NotImplementedError

    def pwm_period_problem(self, period: int) -> str | None:
        """Why the PWM test cannot run at ``period`` cycles (None: it can)."""
        P, L, II = period, self.latency, self.ii
        if P // 2 - L >= 2 and P // 2 >= 2 * II:
            return None
        return f"PWM test needs a period of at least {max(2 * L + 4, 4 * II)} cycles, got {P}"

    def pwm_timing(self, sched: dict, n_end: int) -> PwmTiming:
        """Inputs ``latency`` edges before their scheduled output edges ``sched``, o_ready high."""
        return PwmTiming({nm: t - self.latency for nm, t in sched.items()}, False,
                         _transfer_o_valid(sched, n_end), self._pwm_i_ready(sched, n_end), False)

    def _pwm_i_ready(self, sched: dict, n_end: int) -> np.ndarray:
        return np.ones(n_end, dtype=np.int64)


class Pipelined(TimingRule):
    """Global stall, one target per cycle: i_ready = o_ready | ~o_valid."""

    name = "pipelined"

    def check(self, s: "Sample", in_flight: int) -> list[str]:
        bad = []
        if not s.i_ready and s.o_ready:
            bad.append(f"edge {s.edge}: i_ready low while o_ready high (stalls the stream)")
        if s.stall and s.i_ready:
            bad.append(f"edge {s.edge}: i_ready high while o_valid & !o_ready")
        return bad


class Folded(TimingRule):
    """One evaluation in flight: i_ready high iff none is in flight or its output transfers now."""

    name = "folded"

    def check(self, s: "Sample", in_flight: int) -> list[str]:
        want = in_flight == 0 or s.output_transfer
        if s.i_ready == want:
            return []
        return [f"edge {s.edge}: i_ready {int(s.i_ready)} with {in_flight} target(s) in flight, "
                f"o_valid {int(s.o_valid)}, o_ready {int(s.o_ready)}"]

    def _pwm_i_ready(self, sched: dict, n_end: int) -> np.ndarray:
        # low after an input transfer edge until one cycle before its output transfer edge
        ir = np.ones(n_end, dtype=np.int64)
        for t in sched.values():
            ir[t - self.latency - 1:t - 2] = 0       # relative edges in .. out-2
        return ir


class Modulo(TimingRule):
    """Global stall, a target enters when the phase counter is 0: i_ready = en & (phase == 0).

    The PWM test keeps its output schedule on a modulo core, but not its input schedule (input
    edges depend on the phase): each pair of targets (A B, C D, then F) enters at the first
    phase-0 edge after the previous pair has transferred (the second II edges later) and waits
    at the output, o_valid high and o_ready low, until its scheduled transfer edge, where
    o_ready is raised for one cycle; a last target G (F again) arrives after F and is never
    accepted. So the scheduled edges are met for any period the test accepts, and the pipeline
    is frozen (en low) nearly all the time, which is what makes the ~5 simulated periods
    affordable on Icarus (the running modulo pipeline simulates at a few thousand cycles per
    second there); o_valid held with o_ready low must not load the PWM generators.
    """

    name = "modulo"

    def start(self, first_edge: int) -> None:
        self.first_edge, self.phase = first_edge, None

    def check(self, s: "Sample", in_flight: int) -> list[str]:
        if self.phase is None:      # nothing sent since reset release: en high in every cycle since
            self.phase = (s.edge - self.first_edge) % self.ii
        en = not s.o_valid or s.o_ready
        want = en and self.phase == 0
        bad = [] if s.i_ready == want else [
            f"edge {s.edge}: i_ready {int(s.i_ready)}, expected {int(want)} (modulo schedule: "
            f"phase {self.phase} of II {self.ii}, o_valid {int(s.o_valid)}, o_ready {int(s.o_ready)})"]
        self.phase = (self.phase + en) % self.ii
        return bad

    def pwm_period_problem(self, period: int) -> str | None:
        base = super().pwm_period_problem(period)
        if base is not None:
            return base
        L, II = self.latency, self.ii
        if period // 2 >= L + 2 * II + 1 and II < L:
            return None
        return f"PWM test of a modulo core needs a period of at least {2 * (L + 2 * II + 1)} cycles and II < latency"

    def pwm_timing(self, sched: dict, n_end: int) -> PwmTiming:
        inputs, arrive, ready = self._schedule(sched)
        ov = _transfer_o_valid(sched, n_end)
        for nm, t in sched.items():
            ov[arrive[nm] - 1:t - 1] = 1        # from its arrival on (waiting, o_ready low)
        ov[arrive["G"] - 1:] = 1                # G waits until the final reset
        return PwmTiming(inputs, True, ov, ready(np.arange(2, n_end + 2)), True)

    def _schedule(self, sched: dict):
        """Input edges, output arrival edges and the i_ready model of the PWM test.

        ``sched``: scheduled output transfer edge of A, B, C, D, F (relative edges); o_ready is
        high only in the cycles before those edges. Pairs (A, B), (C, D), then F and G (F again,
        never accepted) enter at the first edge with phase 0 after the previous group's last
        transfer (the second II edges later). The first of a group arrives L - 1 edges after its
        input (o_valid high after that edge); one behind a waiting output arrives II - 1 edges
        after that output transfers. A cycle with o_valid high and o_ready low freezes the phase.

        Returns (input edge per name, arrival edge per name, ``ready(r)``: expected i_ready
        sampled by relative edges ``r`` (an array)).
        """
        L, II = self.latency, self.ii
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

        inputs, arrive = {}, {}
        start = 2                   # relative edge 1 has already been driven by the reset release
        for group in (("A", "B"), ("C", "D"), ("F",), ("G",)):
            a = start
            while not ready(a):
                a += 1
            prev = None
            for j, nm in enumerate(group):
                inputs[nm] = a + j * II
                arrive[nm] = a + L - 1 if prev is None else sched[prev] + II - 1
                t = sched.get(nm)
                assert t is None or arrive[nm] < t, f"PWM test: {nm} arrives after edge {arrive[nm]}, due at {t}"
                waits.append((arrive[nm], t))
                prev = nm
            start = sched.get(group[-1], 0) + 1
        return inputs, arrive, ready


class Buffered(TimingRule):
    """A pipeline that never stalls, its outputs buffered: i_ready = in flight < latency + 1.

    The buffer has a word for every target in flight, so with o_ready high in every cycle (the
    PWM test's default schedule) i_ready never falls.
    """

    name = "buffered"

    def check(self, s: "Sample", in_flight: int) -> list[str]:
        want = in_flight < self.latency + 1
        if s.i_ready == want:
            return []
        return [f"edge {s.edge}: i_ready {int(s.i_ready)} with {in_flight} target(s) in flight, expected "
                f"{int(want)} (an output buffer of {self.latency + 1} words)"]


#: the timing rule of each stream rule
RULES = {r.name: r for r in (Pipelined, Folded, Modulo, Buffered)}


def timing_rule(stream_rule: str, latency: int, initiation_interval: int) -> TimingRule:
    """The timing rule of ``stream_rule`` (a key of :data:`RULES`) for a core's timing."""
    if stream_rule not in RULES:
        raise ValueError(f"stream rule must be one of {', '.join(RULES)}, not {stream_rule!r}")
    return RULES[stream_rule](latency, initiation_interval)
