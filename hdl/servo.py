"""Per-channel servo controller: trims, limits, speed and acceleration profiles, timed and
atomic group moves, failsafe, between the IK widths and the servo pins."""
from __future__ import annotations

from amaranth.hdl import Module, Shape, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .pwmbank import check_int
from .pwmcounters import ServoPWMCounters
from .servo_engine import ServoEngine
from .servo_fields import ChannelField, FailsafeAction

__all__ = ["ServoController", "ChannelField", "FailsafeAction"]


def _ik_servos(ik_layout, width_bits) -> list[str]:
    """The servo names of a robot core's output layout (``leg`` and ``widths.<servo>``)."""
    if not isinstance(ik_layout, data.StructLayout) or set(ik_layout.members) != {"leg", "widths"} \
            or not isinstance(ik_layout.members["widths"], data.StructLayout):
        raise ValueError(f"ik_layout must be a StructLayout of 'leg' and 'widths' (a StructLayout), "
                         f"not {ik_layout!r}")
    names = list(ik_layout.members["widths"].members)
    for n, shape in ik_layout.members["widths"].members.items():
        s = Shape.cast(shape)
        if s.width - s.signed > width_bits:
            raise ValueError(f"ik_layout widths.{n} must fit width_bits={width_bits}, not {s!r}")
    return names


class ServoController(wiring.Component):
    """What a Pololu Maestro or SSC-32 does between host and pulse, for ``channels`` servos.

    Parameters, staging and motion state of every channel live in one block RAM
    (16 words per channel, see :class:`~ikseries.hdl.servo_engine.Word`, and a scratch row);
    a microcoded single-adder engine (:class:`~ikseries.hdl.servo_engine.ServoEngine`, its
    program in ``hdl/servo_microcode.py``) updates every channel once per PWM period, in a
    pass at the period start, and loads the width of each into a pulse counter
    (:class:`~ikseries.hdl.pwmcounters.ServoPWMCounters`). The pins are low during the pass;
    every channel's pulse then rises ``lead = pass_cycles + 2`` cycles after ``period_start``,
    all together: a pulse is never cut or stretched and channels committed together change
    in the same period. A pulse is at most ``max_width = period - lead`` cycles (a wider
    width is shown as that).
    All units are clock ticks and PWM periods; ``W = width_bits``.

    Rules, per channel and pass (``sim/servo_model.py`` is their bit-exact model):

    * Commit: a staged target ``t`` becomes the target ``min(max(t + trim, MIN), MAX)``
      (``MAX`` wins when ``MIN > MAX``); ``clamped`` pulses once when that differs from
      ``t + trim``. Its move time (0 = untimed) replaces a timed move in progress.
    * Failsafe (the timeout expired this pass): HOLD stops at once (target := current
      pulse); RELAX clears enable; HOME makes the home pulse the (untimed) target.
    * Relaxed: no pulse, nothing moves. Current pulse 0 (no pulse has placed the servo, as
      after reset without ``home_at_reset``): the current pulse jumps to the target
      (unlimited, like a Maestro's first target). The first move after enable otherwise
      starts at the current pulse and is limited like any other.
    * Timed move with ``n`` periods left: step ``floor(|target - current| / n)`` toward the
      target, then ``n -= 1``; it arrives exactly after the move's time ``T`` with steps
      ``floor(d / T)`` or ``ceil(d / T)``. A timed move is not speed or acceleration limited.
    * Acceleration 0: step ``min(distance, SPEED)`` (``SPEED`` 0 = unlimited).
    * Otherwise the trapezoid of :func:`~ikseries.sim.servo_model.profile_step`: candidate
      steps land, up, hold, down; ``|step| <= SPEED`` (when set), ``|Δstep| <= ACCEL``, no
      overshoot and exact arrival for a target that stays put (proved exhaustively at small
      sizes by the tests). ``SPEED`` applies at once; ``ACCEL`` at the channel's next
      start from rest; a new target mid-move decelerates along the profile first.

    Parameters
    ----------
    channels : int
        Number of servo channels.
    width_bits : int
        Bits of a pulse width, limit, home pulse, speed and acceleration (``W``).
    period : int
        PWM period in clock cycles; at least ``init_cycles + pass_cycles + 2``.
    time_bits : int
        Bits of a move time (periods), default 16.
    home_at_reset : list of int, optional
        Per-channel home pulses: from reset every channel is enabled there (target and current
        pulse). Without it every channel is relaxed (no pulse) until enabled.
    ik_layout : data.StructLayout, optional
        The robot core's ``o`` payload layout (``robot_output_layout``); adds the ``ik`` stream.
    ik_legs : int, optional
        Legs on ``ik`` (default ``channels // servos``); leg ``l`` servo ``j`` is channel
        ``l * servos + j``.
    trusted_writes : bool
        Every ``write`` value is in its field's range (its sender checked it, as the
        :class:`~ikseries.hdl.dispatch.Dispatcher` does: it NACKs the others), so the range
        check is left out (about 12 iCE40 LUTs) and a write never pulses ``bad_write``.
        Default False: checked.

    Attributes
    ----------
    write : In(stream.Signature(StructLayout({"channel": range(channels), "field": 4, "value": signed(W + 1)})))
        A :class:`ChannelField` write. A value out of its field's range (negative for an
        unsigned field, enable > 1, an unknown action or field code) changes nothing and
        pulses ``bad_write``.
    target : In(stream.Signature(StructLayout({"channel", "pulse": W, "time": time_bits})))
        Stages a target pulse (before trim and clamp) with a move time in periods (0 = untimed).
    commit : In(1)
        Strobe: every staged target is applied at the next pass (sticky until then; targets
        staged after the strobe and before that pass are applied too).
    ik : In(stream.Signature(ik_layout))
        Stages one leg's widths (untimed) and commits (present with ``ik_layout``); a leg out of
        range is dropped and pulses ``bad_write``.
    read : In(stream.Signature(StructLayout({"channel": range(channels), "current": 1})))
        Status request for a channel: its target pulse, or with ``current`` its current pulse.
    status : Out(stream.Signature(StructLayout({"pulse": W, "moving": 1, "enabled": 1})))
        The answer: the pulse asked for, the flags (``moving``: current pulse != target or the
        profile has a nonzero step). One pulse a read: a byte-serial reader takes one at a
        time, and the second register it would need costs more than a second read.
    status_shift : In(1)
        Strobe while ``status`` is offered: its ``pulse`` shifts right by 8 bits (zeros in),
        for a reader that takes it a byte at a time from its low byte. Tie it low to keep the
        answer as it is until taken.
    keepalive : In(1)
        Strobe: restarts the failsafe timeout (the link pulses it on every valid frame).
    failsafe : Out(1)
        Set when the timeout expires, cleared by the next accepted ``write``, ``target`` or ``ik``.
    clamped, bad_write : Out(1)
        One-cycle strobes (count them): a committed target changed by the clamp; a write refused.
    pwm : Out(channels)
        The servo signals, registered; low for a relaxed channel. Pulses rise ``lead`` cycles
        after ``period_start``.
    period_start : Out(1)
        High for one cycle when a PWM period starts; the engine pass starts then.
    phase : Out(range(2 ** bits))
        The period counter (:class:`~ikseries.hdl.pwmcounters.ServoPWMCounters` ``phase``):
        ``period_start`` is high while it is 1.
    busy : Out(1)
        The engine is initialising or in a pass (the host streams wait).

    Latency
    -------
    A write, target or commit accepted before a pass is applied by that pass and shows on the
    pins ``lead`` cycles after that pass's period start (within one period). After reset (the
    ``sync`` domain's own, not a ``ResetInserter``'s: the engine's ROM reads its first word in
    every reset cycle) the engine initialises the memory for ``init_cycles = 16 * channels + 1``
    cycles; every pin is low for a period, then the first period starts (``period + 1`` cycles
    after reset; the first pulses, the home pose with ``home_at_reset``, ``lead`` cycles
    later). A status answer is valid 6 cycles after its
    request.

    Throughput
    ----------
    While the engine is idle: one ``write`` per cycle, one ``target`` per ``target_cycles``
    (2) cycles, one ``ik`` leg per ``servos`` cycles, one ``read`` per 6 cycles (less while
    ``status`` is not taken).
    The engine takes at most ``pass_cycles`` cycles from a period start (the longest path
    through its microprogram, computed by its assembler: 1,024 for 18 channels of 16 bits,
    85 µs at 12 MHz; the host ports wait meanwhile).
    """

    def __init__(self, channels: int, width_bits: int, period: int, *, time_bits: int = 16,
                 home_at_reset: list[int] | None = None, ik_layout=None, ik_legs: int | None = None,
                 trusted_writes: bool = False):
        check_int("channels", channels, 1)
        check_int("width_bits", width_bits, 2)
        check_int("period", period, 2)
        check_int("time_bits", time_bits, 1)
        full = (1 << width_bits) - 1
        if home_at_reset is not None:
            home_at_reset = list(home_at_reset)
            if len(home_at_reset) != channels or not all(
                    isinstance(h, int) and not isinstance(h, bool) and 0 <= h <= full for h in home_at_reset):
                raise ValueError(f"home_at_reset must be {channels} integers in [0, {full}], "
                                 f"not {home_at_reset!r}")
        self._servos = [] if ik_layout is None else _ik_servos(ik_layout, width_bits)
        if ik_layout is None and ik_legs is not None:
            raise ValueError(f"ik_legs needs an ik_layout, not ik_legs={ik_legs!r} alone")
        if ik_layout is not None:
            legs = channels // len(self._servos) if ik_legs is None else ik_legs
            check_int("ik_legs", legs, 1)
            if legs * len(self._servos) > channels:
                raise ValueError(f"ik_legs * servos must be <= channels={channels}, not "
                                 f"{legs} * {len(self._servos)}")
            self._ik_legs = legs
        self._channels, self._w, self._tb, self._period = channels, width_bits, time_bits, period
        self._home = home_at_reset
        self._engine = ServoEngine(channels, width_bits, time_bits, home_at_reset,
                                   max(len(self._servos), 1), trusted_writes)
        # the first pass follows the memory initialisation within the first period
        least = self._engine.init_cycles + self._engine.pass_cycles + 2
        if period < least:
            raise ValueError(f"period must be >= {least} cycles for {channels} channels of "
                             f"{width_bits} bits, not {period!r}")
        # a pass loads every channel once, in order, within pass_cycles of its period start
        # (the microprogram's LOADNEXT ends each channel's path); the first period starts a
        # period after reset, the memory initialised (period >= init + pass cycles)
        self._bank = ServoPWMCounters(period, width_bits, channels, lead=self._engine.pass_cycles + 2)
        sig = {
            "write": In(stream.Signature(self._engine.write_layout)),
            "target": In(stream.Signature(self._engine.target_layout)),
            "commit": In(1),
            "read": In(stream.Signature(self._engine.read_layout)),
            "status": Out(stream.Signature(self._engine.status_layout)),
            "keepalive": In(1), "status_shift": In(1),
            "failsafe": Out(1), "clamped": Out(1), "bad_write": Out(1), "busy": Out(1),
            "pwm": Out(channels), "period_start": Out(1), "phase": Out((period - 1).bit_length()),
        }
        if ik_layout is not None:
            sig["ik"] = In(stream.Signature(ik_layout))
        super().__init__(sig)

    @property
    def channels(self) -> int:
        return self._channels

    @property
    def period(self) -> int:
        return self._period

    @property
    def lead(self) -> int:
        """Cycles from ``period_start`` to the rise of the pulses (the pass before them)."""
        return self._bank.lead

    @property
    def max_width(self) -> int:
        """The widest pulse shown, ``period - lead`` cycles."""
        return self._bank.max_width

    @property
    def servos(self) -> list[str]:
        return list(self._servos)

    @property
    def init_cycles(self) -> int:
        """Cycles of the memory initialisation after reset."""
        return self._engine.init_cycles

    @property
    def target_cycles(self) -> int:
        """Cycles of one ``target`` transfer while the engine is idle."""
        return self._engine.target_cycles

    @property
    def read_cycles(self) -> int:
        """Most cycles from a ``read`` offered while the engine is idle to ``status.valid``."""
        return self._engine.read_cycles

    @property
    def pass_cycles(self) -> int:
        """Most cycles from a period start to the end of its engine pass."""
        return self._engine.pass_cycles

    def elaborate(self, platform):
        m = Module()
        m.submodules.engine = eng = self._engine
        m.submodules.bank = bank = self._bank
        wiring.connect(m, wiring.flipped(self.write), eng.write)
        wiring.connect(m, wiring.flipped(self.target), eng.target)
        wiring.connect(m, wiring.flipped(self.read), eng.read)
        wiring.connect(m, eng.status, wiring.flipped(self.status))
        m.d.comb += [eng.commit.eq(self.commit), eng.keepalive.eq(self.keepalive), eng.status_shift.eq(self.status_shift),
                     eng.period_start.eq(bank.period_start),
                     self.failsafe.eq(eng.failsafe), self.clamped.eq(eng.clamped),
                     self.bad_write.eq(eng.bad_write), self.busy.eq(eng.busy),
                     bank.i.valid.eq(eng.load.valid), bank.i.payload.width.eq(eng.load.payload.width),
                     eng.load.ready.eq(1),
                     self.pwm.eq(bank.pwm), self.period_start.eq(bank.period_start),
                     self.phase.eq(bank.phase)]
        if self._servos:
            self._wire_ik(m, eng)
        return m

    def _wire_ik(self, m, eng):
        """Present one servo of the ``ik`` leg at a time to the engine's staging port."""
        k = len(self._servos)
        j = Signal(range(k))
        leg = self.ik.payload.leg
        ok = leg < self._ik_legs
        m.d.comb += [eng.ik.valid.eq(self.ik.valid & ok),
                     eng.ik.payload.channel.eq(leg * k + j),
                     eng.ik.payload.last.eq(j == k - 1)]
        with m.Switch(j):
            for i, name in enumerate(self._servos):
                with m.Case(i):
                    m.d.comb += eng.ik.payload.pulse.eq(self.ik.payload.widths[name])
        with m.If(self.ik.valid & ~ok & ~eng.busy):
            m.d.comb += [self.ik.ready.eq(1), self.bad_write.eq(1)]
        with m.If(eng.ik.valid & eng.ik.ready):
            m.d.sync += j.eq(0)
            with m.If(j != k - 1):
                m.d.sync += j.eq(j + 1)
            with m.Else():
                m.d.comb += self.ik.ready.eq(1)
