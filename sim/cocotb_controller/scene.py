"""The test scene: a box of leg targets around a reference, the trims that bring every golden
width of the box into the short test period, and the end-of-test checks every test runs."""
from __future__ import annotations

import itertools

from .checker import answer_mismatches, expected_widths, misaligned, width_mismatches
from .model import ControllerModel, golden_widths

__all__ = ["REF", "Scene", "final_checks"]

#: a target inside the small plan's workspace (tests/test_controller.py's), the box's half sizes
REF, HALF = (240, 100, 160), (2, 4, 1)
#: shortest pulse after the trims; room left before the period's end
MARGIN, ROOM = 30, 20


class Scene:
    """Targets (corners of the box around :data:`REF`), per-servo golden range and trims."""

    def __init__(self, plan, legs: int, max_width: int):
        self.plan, self.legs = plan, legs
        self.box = [(r - h, r + h) for r, h in zip(REF, HALF)]
        g = [golden_widths(plan, t) for t in itertools.product(*self.box)] + [golden_widths(plan, REF)]
        lo = [min(w[j] for w in g) for j in range(len(plan.outputs))]
        hi = [max(w[j] for w in g) for j in range(len(plan.outputs))]
        assert max(h - l for h, l in zip(hi, lo)) + MARGIN < max_width - ROOM, \
            "target box too wide for the widest pulse of the period"
        self.trims = [MARGIN - l for l in lo] * legs
        #: set_pulse values (before the trim) whose pins stay below the widest pulse
        self.pulses = [(l, h) for l, h in zip(lo, hi)] * legs
        #: whether every golden width of the box leaves room below the widest pulse untrimmed
        self.fits_untrimmed = max(hi) + ROOM < max_width

    def corner(self, which: int):
        """Corner ``which`` (0 .. 7) of the box."""
        return list(itertools.product(*self.box))[which]

    def pins(self, leg: int, target) -> list[int]:
        """The pin widths of ``leg``'s channels for ``target`` (golden + trims)."""
        n = len(self.plan.outputs)
        return [w + t for w, t in zip(golden_widths(self.plan, target), self.trims[leg * n:(leg + 1) * n])]

    async def set_trims(self, host) -> None:
        for c, t in enumerate(self.trims):
            await host.request("set_trim", channel=c, trim=t)


def final_checks(host, unaligned: int = 2) -> dict:
    """Every period's widths against the model (after the first ``unaligned`` requests settled),
    pulses on the period grid, answers against requests, aligned answers away from period
    starts, a clean tx line. Returns the measured widths {period: widths}; raises on a mismatch."""
    pwm, cfg = host.pwm, host.config
    first = pwm.index(host.reset_at) + 2
    last = pwm.index(host.cycle()) - 1
    measured = pwm.high_times(first, last)
    expected = expected_widths(ControllerModel(host.plan, cfg.legs, cfg.period), host.acked, pwm, first, last)
    since = pwm.index(host.acked[unaligned - 1][0]) + 3
    problems = width_mismatches(expected, measured, since)
    problems += [f"rise off the period grid at cycle {c}, channel {ch}" for c, ch in pwm.off_grid_rises()[:3]]
    problems += answer_mismatches(host.requests, host.rx.answers)
    problems += [f"answer at cycle {c} within a period start" for c in misaligned(pwm, [a for a, _ in host.acked[unaligned:]])]
    if host.rx.framing or any(host.rx.decoder.counters.values()):
        problems.append(f"tx line not clean: framing {host.rx.framing}, decoder {host.rx.decoder.counters}")
    assert not problems, "\n".join(problems)
    return measured
