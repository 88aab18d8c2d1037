"""Compares what the monitor recorded with the model: bit-exact outputs in order, transfer
counts, o_leg, initiation interval, latency and throughput. Each check is a :class:`Checker`
that counts its failures and fails the test listing the first ones."""
from __future__ import annotations

import bisect

import numpy as np

from .monitor import Monitor, Sample

__all__ = ["MAX_ERRORS", "Checker", "Scoreboard"]

MAX_ERRORS = 12     # messages kept per check


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


class Scoreboard:
    """The checks of one streamed sequence of targets.

    Parameters
    ----------
    servos : list of str
        Output fields, in payload order.
    latency : int
        Expected latency (input transfer edge -> output transfer edge, stall cycles excluded).
    initiation_interval : int
        Expected cycles between input transfers.
    buffered : bool
        The core never stalls, its outputs wait in a buffer (stream rule ``"buffered"``): an
        output transfers ``latency`` edges after its input, or, if it has to wait, at the first
        edge without a stall once the output before it is out.
    """

    def __init__(self, servos, latency: int, initiation_interval: int, buffered: bool = False):
        self.servos, self.latency, self.ii = list(servos), latency, initiation_interval
        self.buffered = buffered
        self.handshake = Checker("stream handshake")
        self._held = None

    def hold(self, s: Sample) -> None:
        """o_valid and the payload must hold while the output waits (o_valid & !o_ready)."""
        if self._held is not None:
            self.handshake(s.o_valid and s.payload == self._held,
                           lambda: f"edge {s.edge}: o_valid/o payload changed while stalled: "
                                   f"{self._held} -> {s.payload if s.o_valid else 'o_valid low'}")
        self._held = s.payload if s.stall else None

    def output_expected(self, s: Sample, n: int, sent_out: int) -> bool:
        """An output transfer must be one of the ``n`` targets sent (``sent_out`` already out)."""
        return self.handshake(sent_out < n, lambda: f"edge {s.edge}: output beyond the {n} targets sent: {s.payload}")

    def check(self, targets: dict, expected: dict, mon: Monitor, exact_latency: bool, legs=None) -> None:
        """Bit-exact and in-order vs ``expected`` (and o_leg == the target's leg where the core
        has o_leg); latency per target (stall cycles subtracted unless ``exact_latency``, which
        requires none); input transfers >= II cycles apart."""
        n = len(next(iter(targets.values())))
        self.handshake.done()
        cnt = Checker("transfer count")
        cnt(len(mon.in_edges) == n, f"{len(mon.in_edges)} input transfers for {n} targets")
        cnt(len(mon.out_edges) == n, f"{len(mon.out_edges)} output transfers for {n} targets")
        cnt.done()
        got = {s: np.array([p[c] for p in mon.outputs], dtype=np.int64) for c, s in enumerate(self.servos)}
        bits = Checker(f"outputs vs golden model ({n} targets)")
        for j in range(n):
            bad = [s for s in self.servos if got[s][j] != expected[s][j]]
            bits(not bad, lambda: (f"target {j} " + str({nm: int(v[j]) for nm, v in targets.items()})
                                   + ": " + ", ".join(f"{s} got {int(got[s][j])} expected {int(expected[s][j])}"
                                                      for s in bad)))
        bits.done()
        if legs is not None:
            legc = Checker(f"o_leg vs i_leg ({n} targets)")
            for j, p in enumerate(mon.outputs):
                legc(p[-1] == legs[j], lambda: f"target {j}: o_leg {p[-1]}, sent to leg {int(legs[j])}")
            legc.done()
        self._interval(mon.in_edges)
        self._latency(mon, exact_latency)

    def _interval(self, in_e) -> None:
        gap = Checker(f"initiation interval (input transfers >= {self.ii} cycles apart)")
        for j, d in enumerate(np.diff(in_e)):
            gap(d >= self.ii, lambda: f"targets {j} and {j + 1}: input edges {in_e[j]} and {in_e[j + 1]}, "
                                      f"{d} cycle(s) apart")
        gap.done()

    def _latency(self, mon: Monitor, exact: bool) -> None:
        lat = Checker(f"latency (expected {self.latency} cycles)")
        if self.buffered and not exact:
            self._buffered_latency(mon, lat)
            return
        for j, (a, b) in enumerate(zip(mon.in_edges, mon.out_edges)):
            stalls = bisect.bisect_left(mon.stall_edges, b) - bisect.bisect_right(mon.stall_edges, a)
            if exact:
                lat(b - a == self.latency and stalls == 0,
                    lambda: f"target {j}: input edge {a}, output edge {b}: {b - a} cycles")
            else:
                lat(b - a - stalls == self.latency,
                    lambda: f"target {j}: input edge {a}, output edge {b}: {b - a} cycles "
                            f"including {stalls} stall cycle(s) -> {b - a - stalls}")
        lat.done()

    def _buffered_latency(self, mon: Monitor, lat: Checker) -> None:
        """An output of a buffered core is ready ``latency`` edges after its input or when the
        one before it has transferred, whichever is later; from then on every edge until its
        own transfer must be a stall (o_valid high, o_ready low)."""
        prev = None
        for j, (a, b) in enumerate(zip(mon.in_edges, mon.out_edges)):
            free = a + self.latency if prev is None else max(a + self.latency, prev + 1)
            stalls = bisect.bisect_left(mon.stall_edges, b) - bisect.bisect_left(mon.stall_edges, free)
            lat(b >= free and b - free == stalls,
                lambda: f"target {j}: input edge {a}, output edge {b}, ready from edge {free}, "
                        f"{stalls} stall(s) in between")
            prev = b
        lat.done()

    def throughput(self, mon: Monitor) -> None:
        """Back to back: one input and one output transfer every II cycles exactly."""
        d_in, d_out = np.diff(mon.in_edges), np.diff(mon.out_edges)
        if self.ii == 1:
            thr = Checker("throughput (one target per cycle)")
            thr(np.all(d_in == 1), "input transfers not on consecutive edges")
            thr(np.all(d_out == 1), "output transfers not on consecutive edges")
        else:
            thr = Checker(f"throughput (one target every {self.ii} cycles)")
            thr(np.all(d_in == self.ii), lambda: f"input transfer gaps {sorted(set(d_in.tolist()))}")
            thr(np.all(d_out == self.ii), lambda: f"output transfer gaps {sorted(set(d_out.tolist()))}")
        thr.done()
