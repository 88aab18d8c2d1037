"""The golden model of the bench: the plan's integer evaluation (:mod:`ikseries.sim.golden`) and
the PWM generators' expected waveforms."""
from __future__ import annotations

import numpy as np

from ikseries.sim import golden

__all__ = ["Model", "pwm_wave", "transitions"]


class Model:
    """Expected output widths of the plan's targets, never from the design itself.

    Parameters
    ----------
    plan : Plan
        The plan the design was generated from.
    table : ChannelTable, optional
        A robot top's channel table (from its manifest): the widths are its channels'.
    """

    def __init__(self, plan, table=None):
        self.plan, self.table = plan, table

    def outputs(self, targets: dict, legs=None) -> dict:
        """{servo: int64 array} of the widths for ``targets`` ({input: array}) sent to ``legs``
        (one leg per target, or one for all; None: leg 0)."""
        n = len(next(iter(targets.values())))
        legs = np.broadcast_to(np.asarray(0 if legs is None else legs, dtype=np.int64), (n,))
        return golden.robot_outputs(self.plan, self.table, legs, targets)


def pwm_wave(transfers, period: int, n_end: int) -> np.ndarray:
    """Expected pwm value after each relative edge 1..n_end for one servo.

    ``transfers``: list of (relative transfer edge, width). The width stored by relative edge
    k*period - 1 (the last transfer at an edge < k*period; 0 before any) is active in period k:
    a transfer at edge k*period itself, in the period's last cycle, waits a period more (see
    :class:`~ikseries.hdl.pwm.ServoPWM`). The registered output is high after edges
    k*period + 1 .. k*period + width.
    """
    n = np.arange(1, n_end + 1)
    k_max = (n_end - 1) // period
    active = np.zeros(k_max + 1, dtype=np.int64)
    for k in range(1, k_max + 1):
        before = [w for t, w in transfers if t < k * period]
        active[k] = before[-1] if before else 0
    return ((n - 1) % period < active[(n - 1) // period]).astype(np.int64)


def transitions(values: np.ndarray, first_edge: int = 1, initial: int = 0) -> list[tuple[int, int]]:
    """(edge, new value) wherever ``values`` (after edges first_edge, ...) changes; starts from
    ``initial``."""
    v = np.concatenate([[initial], values])
    idx = np.flatnonzero(np.diff(v))
    return [(int(i) + first_edge, int(v[i + 1])) for i in idx]
