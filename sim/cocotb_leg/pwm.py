"""Pieces of the PWM test: targets chosen by their golden widths, the output transfer schedule,
the drive actions, and the comparison of recorded waveforms with the model.

Relative edge 1 is the first rising edge after reset; period k starts at relative edge k*P.
Output transfers (:func:`output_schedule`): A at P/2 and B at P/2 + II (B replaces A), C at P
(the boundary edge itself: applies to period 1), D at P + II (during C's pulse: applies to
period 2 only), F at 2P + 5 (during D's pulse), nothing afterwards (F repeats in periods 3 and
4). The inputs, the o_ready pattern and the expected o_valid and i_ready waveforms come from the
core's timing rule (:meth:`ikseries.sim.cocotb_leg.rules.TimingRule.pwm_timing`).
"""
from __future__ import annotations

import numpy as np

from ikseries.sim.targets import random_targets

from .model import Model, pwm_wave, transitions
from .rules import PwmTiming
from .scoreboard import Checker

__all__ = ["NAMES", "output_schedule", "pick_targets", "window_end", "actions", "check_pulses"]

NAMES = "ABCDF"     # targets with a scheduled output transfer (a modulo core adds G, never accepted)


def output_schedule(period: int, ii: int) -> dict:
    """Relative output transfer edge of each of :data:`NAMES`."""
    P = period
    return {"A": P // 2, "B": P // 2 + ii, "C": P, "D": P + ii, "F": 2 * P + 5}


def pick_targets(model: Model, servos, period: int, rng, log, leg: int = 0) -> tuple[dict, dict, bool]:
    """Targets A, B, C, D, F chosen by their golden widths: A..D with every width below the
    period and each servo's width differing from the ones already picked; F with a width >=
    the period if there is such a target (constant high across the period boundary), preferring
    short other widths (their pulses in period 4 bound the simulated time).

    ``model``: the bench's (widths of the channels of ``leg``, the leg under test).

    Returns ({name: target}, {name: {servo: width}}, whether F has a width >= the period).
    """
    P, plan = period, model.plan
    pool = random_targets(plan, 4000, rng)
    w = model.outputs(pool, leg)
    W = np.stack([w[s] for s in servos], axis=1)
    short = np.flatnonzero(np.all((W > 0) & (W < P), axis=1))
    long_ = np.flatnonzero(np.any(W >= P, axis=1) & np.any(W < P, axis=1))
    assert len(short) >= 4, (f"PWM test needs targets whose widths are all below the period "
                             f"{P}; golden widths span {W.min()}..{W.max()}")
    picks: list[int] = []
    for j in short:
        if all(np.all(W[j] != W[p]) for p in picks):
            picks.append(int(j))
        if len(picks) == 4:
            break
    f_pool = [int(j) for j in (long_ if len(long_) else short) if all(np.all(W[j] != W[p]) for p in picks)]
    picks.append(min(f_pool, key=lambda j: int(np.max(W[j], initial=0, where=W[j] < P))))
    if not len(long_):
        log.info("no target has a width >= the period %d: constant-high case not covered", P)
    tgt = {nm: {i.name: int(pool[i.name][j]) for i in plan.inputs} for nm, j in zip(NAMES, picks)}
    wid = {nm: {s: int(W[j, c]) for c, s in enumerate(servos)} for nm, j in zip(NAMES, picks)}
    return tgt, wid, bool(len(long_))


def window_end(wid: dict, servos, period: int) -> int:
    """Last relative edge observed: F's short pulses in period 4, and a margin."""
    f_short = [wid["F"][s] for s in servos if wid["F"][s] < period]
    return 4 * period + 1 + (max(f_short) if f_short else 0) + 8


def actions(sched: dict, timing: PwmTiming, rel0: int) -> dict:
    """{absolute edge: {"drive": name or "" (i_valid low), "sample": [names], "ready": 0/1}}: what
    the bench does at the falling edge before each edge (``rel0``: absolute edge of relative 0).
    Inputs at the rule's input edges; the output payload sampled before its transfer edge; with
    ``ready_pulses`` o_ready high only in the cycles before transfer edges."""
    act: dict = {}
    for nm, r in timing.inputs.items():
        act.setdefault(rel0 + r, {})["drive"] = nm
    for nm in NAMES:
        act.setdefault(rel0 + sched[nm], {}).setdefault("sample", []).append(nm)
        if timing.ready_pulses:
            act[rel0 + sched[nm]]["ready"] = 1
    if timing.ready_pulses:
        for nm in NAMES:
            act.setdefault(rel0 + sched[nm] + 1, {}).setdefault("ready", 0)
    for e in [e for e, a in act.items() if a.get("drive")]:
        if not act.get(e + 1, {}).get("drive"):
            act.setdefault(e + 1, {})["drive"] = ""        # i_valid low again
    return act


def check_pulses(pulse: Checker, wave: Checker, name: str, rec: list, transfers: list, period: int,
                 n_end: int, first_start: int) -> tuple[list, list]:
    """One servo's recorded (relative edge, value) transitions ``rec`` against the model: the
    exact transition list, rising edges at period starts one period apart, high time == the
    width last transferred before that period's last cycle, at least 3 pulses. Returns (rises, falls)."""
    P = period
    exp_tr = transitions(pwm_wave(transfers, P, n_end))
    wave(rec == exp_tr, lambda: f"{name}: recorded (relative edge, value) {rec[:12]} expected {exp_tr[:12]}")
    rises = [n for n, v in rec if v == 1]
    falls = [n for n, v in rec if v == 0]
    pulse(not rises or rises[0] >= first_start,
          f"{name}: pulse at relative edge {rises[:1]} before the first period start "
          f"after the first target ({first_start})")
    for r in rises:
        k, off = divmod(r - 1, P)
        pulse(off == 0, f"{name}: rising edge at relative edge {r}, not at a period start")
        last = [wv for t, wv in transfers if t < k * P]
        want = last[-1] if last else 0
        fall = next((x for x in falls if x > r), None)
        if want < P:
            pulse(fall == r + want, f"{name}: period {k}: high {None if fall is None else fall - r} "
                                    f"cycles, expected {want} (the width last transferred)")
    for a, b in zip(rises, rises[1:]):
        pulse((b - a) % P == 0, f"{name}: rising edges {a} and {b} are {b - a} cycles apart, period {P}")
    pulse(len(rises) >= 3, f"{name}: only {len(rises)} pulses seen")
    return rises, falls
