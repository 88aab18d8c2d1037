"""Checks of what the pins showed against the model: every period's widths, when a request's
widths arrive, the answers against the requests."""
from __future__ import annotations

from .model import ControllerModel

__all__ = ["SLACK", "expected_widths", "width_mismatches", "first_period_with", "misaligned", "answer_mismatches"]

#: cycles around a period start where a request's effect and its answer's start bit may fall
#: on different sides of it (the answer leaves a few cycles after the dispatcher's commit)
SLACK = 8


def expected_widths(model: ControllerModel, acked: list, pwm, first: int, last: int) -> dict[int, list[int]]:
    """{period k: widths} for ``first <= k < last`` from a fresh ``model``.

    ``acked``: [(cycle of the answer's first start bit, request Message)] in order. The pass at
    period start ``k`` sees every request answered before it and its widths show in period
    ``k``, after the pass, none wider than the period holds after it (``period - lead``).
    Passes run from period ``first``, the first after reset."""
    out, i = {}, 0
    for k in range(first, last):
        s = pwm.start(k)
        while i < len(acked) and acked[i][0] < s:
            model.request(acked[i][1])
            i += 1
        out[k] = [min(w, pwm.period - pwm.lead) for w in model.period()]
    return out


def width_mismatches(expected: dict, measured: dict, since: int, limit: int = 5) -> list[str]:
    """Lines naming the periods from ``since`` where the pins differ from the model."""
    bad = [f"period {k}: pins {measured[k]}, model {expected[k]}"
           for k in sorted(expected) if k >= since and measured[k] != expected[k]]
    return bad[:limit] + ([f"... {len(bad) - limit} more"] if len(bad) > limit else [])


def first_period_with(measured: dict, channels, widths, since: int) -> int | None:
    """The first period from ``since`` where ``channels`` show ``widths``."""
    for k in sorted(measured):
        if k >= since and [measured[k][c] for c in channels] == list(widths):
            return k
    return None


def misaligned(pwm, cycles) -> list[int]:
    """The cycles within :data:`SLACK` of a period start (where the model's order is unsure)."""
    return [c for c in cycles if min((c - pwm.phase) % pwm.period, -(c - pwm.phase) % pwm.period) < SLACK]


def answer_mismatches(requests: list, answers: list) -> list[str]:
    """Each request must have exactly one answer, its own command, no NACK, in order."""
    bad = []
    if len(answers) != len(requests):
        bad.append(f"{len(answers)} answers to {len(requests)} requests")
    for n, (req, ans) in enumerate(zip(requests, answers)):
        if ans.message.command != req.command or ans.message.nack:
            bad.append(f"request {n} {req.command}: answered {ans.message}")
    return bad[:5]
