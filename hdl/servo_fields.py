"""Codes shared by the servo controller's hardware and its model: parameter fields, failsafe actions."""
from __future__ import annotations

import enum

__all__ = ["ChannelField", "FailsafeAction"]


class ChannelField(enum.IntEnum):
    """Field code of a parameter write (``ServoController.write``), in ticks and PWM periods.

    Codes 0-7 are per-channel parameters and also their word addresses in the controller's
    channel memory; ``TIMEOUT`` is global (the channel of its write is ignored).
    """
    TRIM = 0        # signed ticks added to every staged target
    MIN = 1         # lowest committed target, ticks
    MAX = 2         # highest committed target, ticks
    SPEED = 3       # largest step, ticks per period (0 = unlimited)
    ACCEL = 4       # largest change of step, ticks per period per period (0 = unlimited)
    HOME = 5        # the failsafe "home" pulse, ticks
    ENABLE = 6      # 1 = pulses, 0 = relaxed (output held low)
    FAILSAFE = 7    # a FailsafeAction
    TIMEOUT = 8     # failsafe timeout in PWM periods (0 = off), global


class FailsafeAction(enum.IntEnum):
    """What a channel does when the failsafe timeout expires."""
    HOLD = 0        # stop at once where it is (target := current pulse)
    RELAX = 1       # no more pulses (enable := 0)
    HOME = 2        # move to the home pulse, limited like any move
