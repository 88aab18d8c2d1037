"""Bit-exact per-period model of :class:`ikseries.hdl.servo.ServoController`.

The controller's integer rules live here in plain Python (the hardware documents the same
rules and the tests compare the two period by period). One call of :meth:`ServoModel.period`
is one engine pass: it runs at a PWM period start and its widths show in the same period, on
pulses that rise after the pass (at most ``period - lead`` wide, which this model leaves to the
caller).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..hdl.servo_fields import ChannelField, FailsafeAction

__all__ = ["ChannelState", "ServoModel", "profile_step"]


@dataclass
class ChannelState:
    """One channel's parameters and motion state (all integers, ticks and periods)."""
    trim: int = 0
    min: int = 0
    max: int = 0
    speed: int = 0
    accel: int = 0
    home: int = 0
    enable: int = 0
    failsafe: int = int(FailsafeAction.HOLD)
    staged: bool = False
    staged_pulse: int = 0
    staged_time: int = 0            # 0 = an untimed move
    target: int = 0
    pos: int = 0
    step: int = 0                   # |last step| of the accelerated profile (0 = at rest)
    down: bool = False              # direction of that step: True = decreasing pulse
    stop: int = 0                   # ticks the profile needs to stop from ``step``
    act_accel: int = 0              # the acceleration in force for the current profile
    periods_left: int = 0           # of a timed move (0 = none)


def profile_step(remaining: int, step: int, stop: int, accel: int, speed: int,
                 first: int) -> tuple[int, int]:
    """The next (step, stop distance) of the accelerated profile, both >= 0.

    ``remaining`` is the signed distance to the target along the motion's direction, ``step``
    the last step (0 at rest, then ``remaining >= 0``), ``stop`` the distance that step needs
    to stop (the sum step + (step - accel) + ... of its positive terms), ``accel >= 1``,
    ``speed`` the limit (0 = none), ``first`` the first step from rest. Candidates in order:
    land (step exactly onto the target), up (faster by ``accel``, or ``first`` from rest),
    hold, down (slower by ``accel``, not below 0); the first that keeps the speed limit and
    still lets the channel stop on the target wins (down always does).
    """
    unlimited = speed == 0
    if 0 <= remaining <= accel and remaining + accel >= step and (unlimited or remaining <= speed):
        return remaining, remaining
    up = first if step == 0 else step + accel
    up_stop = up + (0 if step == 0 else stop)
    if remaining >= 0 and (unlimited or up <= speed) and up_stop <= remaining:
        return up, up_stop
    if step != 0 and remaining >= 0 and (unlimited or step <= speed) and stop <= remaining:
        return step, stop
    nxt = max(step - accel, 0)
    return nxt, (max(stop - step, 0) if nxt else 0)


@dataclass
class ServoModel:
    """The controller's channels, staging and failsafe, one :meth:`period` per engine pass."""
    channels: int
    width_bits: int
    time_bits: int = 16
    home_at_reset: list[int] | None = None
    ik_servos: int = 1
    ik_legs: int | None = None
    timeout: int = 0
    count: int = 0
    fired: bool = False
    failsafe: bool = False
    commit_pending: bool = False
    ch: list[ChannelState] = field(default_factory=list)

    def __post_init__(self):
        full = (1 << self.width_bits) - 1
        home = self.home_at_reset or [0] * self.channels
        on = int(self.home_at_reset is not None)
        self.ch = [ChannelState(max=full, home=h, enable=on, target=h, pos=h) for h in home]
        if self.ik_legs is None:
            self.ik_legs = self.channels // self.ik_servos

    # host side (between passes)
    def write(self, channel: int, fld: int, value: int) -> bool:
        """A parameter write; False (nothing changed) when the value is out of its field's range."""
        w = self.width_bits
        if not -(1 << w) <= value < (1 << w):
            raise ValueError(f"value must fit signed({w + 1}), not {value!r}")
        full = (1 << w) - 1
        ranges = {ChannelField.TRIM: (-(1 << w), full), ChannelField.ENABLE: (0, 1),
                  ChannelField.FAILSAFE: (0, len(FailsafeAction) - 1)}
        if fld not in set(ChannelField):
            return False
        lo, hi = ranges.get(ChannelField(fld), (0, full))
        if not lo <= value <= hi:
            return False
        self.failsafe = False
        if fld == ChannelField.TIMEOUT:
            self.timeout, self.count, self.fired = value, 0, False
            return True
        name = ChannelField(fld).name.lower()
        setattr(self.ch[channel], name, value)
        return True

    def stage(self, channel: int, pulse: int, time: int = 0):
        c = self.ch[channel]
        c.staged, c.staged_pulse, c.staged_time = True, pulse, time
        self.failsafe = False

    def commit(self):
        self.commit_pending = True

    def ik(self, leg: int, widths: list[int]) -> bool:
        """Stage one leg's widths and commit; False (dropped) for a leg out of range."""
        if leg >= self.ik_legs:
            return False
        for j, wd in enumerate(widths):
            self.stage(leg * self.ik_servos + j, wd)
        self.commit_pending = True
        return True

    def keepalive(self):
        self.count, self.fired = 0, False

    def read(self, channel: int) -> tuple[int, int, bool, bool]:
        """(target, current pulse, moving, enabled) as the ``status`` stream gives them."""
        c = self.ch[channel]
        return c.target, c.pos, c.pos != c.target or c.step != 0, bool(c.enable)

    # the engine pass
    def period(self) -> tuple[list[int], int]:
        """Run one pass; the widths it loads (0 for a relaxed channel) and the clamp count."""
        commit, self.commit_pending = self.commit_pending, False
        fire = False
        if self.timeout and not self.fired:
            self.count += 1
            if self.count >= self.timeout:
                fire = self.fired = self.failsafe = True
        clamped = 0
        widths = []
        for c in self.ch:
            if commit and c.staged:
                clamped += self._apply_staged(c)
            if fire:
                self._failsafe(c)
            self._move(c)
            widths.append(c.pos if c.enable else 0)
        return widths, clamped

    @staticmethod
    def _apply_staged(c: ChannelState) -> int:
        t = c.staged_pulse + c.trim
        x = min(max(t, c.min), c.max)
        c.target, c.periods_left, c.staged = x, c.staged_time, False
        return int(x != t)

    @staticmethod
    def _failsafe(c: ChannelState):
        if c.failsafe == FailsafeAction.HOLD:
            c.target, c.step, c.stop, c.periods_left = c.pos, 0, 0, 0
        elif c.failsafe == FailsafeAction.RELAX:
            c.enable = 0
        else:
            c.target, c.periods_left = c.home, 0

    def _move(self, c: ChannelState):
        if not c.enable or c.pos == 0:
            if c.enable:            # no pulse has placed the servo yet: start at the target
                c.pos = c.target
            c.step = c.stop = c.periods_left = 0
            return
        if c.periods_left:
            d = c.target - c.pos
            q = abs(d) // c.periods_left
            c.pos += -q if d < 0 else q
            c.periods_left -= 1
            c.step = c.stop = 0
            return
        if c.step == 0:
            c.act_accel = c.accel
            c.down = c.target < c.pos
        remaining = c.pos - c.target if c.down else c.target - c.pos
        a, s = c.act_accel, c.speed
        if a == 0:
            step, stop = (remaining if s == 0 or remaining <= s else s), 0
            new_step = 0
        else:
            first = a if s == 0 else (s - 1) % a + 1
            step, stop = profile_step(remaining, c.step, c.stop, a, s, first)
            new_step = step
        c.pos += -step if c.down else step
        c.step, c.stop = new_step, stop
