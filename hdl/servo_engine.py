"""The servo controller's channel memory and its sequential engine (one pass per PWM period)."""
from __future__ import annotations

import enum

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from .servo_fields import ChannelField, FailsafeAction

__all__ = ["ServoEngine", "Word", "WORDS_PER_CHANNEL", "word_defaults"]

WORDS_PER_CHANNEL = 16


class Word(enum.IntEnum):
    """Word address within a channel's 16 (0-7 are the :class:`ChannelField` parameters)."""
    TRIM = ChannelField.TRIM
    MIN = ChannelField.MIN
    MAX = ChannelField.MAX
    SPEED = ChannelField.SPEED
    ACCEL = ChannelField.ACCEL
    HOME = ChannelField.HOME
    ENABLE = ChannelField.ENABLE
    FAILSAFE = ChannelField.FAILSAFE
    STAGED = 8          # pulse | staged << W | timed << (W + 1)
    STAGED_TIME = 9
    TARGET = 10
    POS = 11            # current pulse
    VEL = 12            # profile step | down << W
    STOP = 13           # the profile's stop distance
    ACT_ACCEL = 14      # acceleration in force for the profile
    TIMED = 15          # periods left of a timed move


# the engine's read order per channel (capture registers are named after the words)
_READS = (Word.FAILSAFE, Word.ENABLE, Word.HOME, Word.TARGET, Word.POS, Word.VEL, Word.TIMED,
          Word.SPEED, Word.ACCEL, Word.ACT_ACCEL, Word.STOP)
_WRITES = (Word.ENABLE, Word.TARGET, Word.POS, Word.VEL, Word.STOP, Word.ACT_ACCEL, Word.TIMED)
# cycles per channel besides the divider: begin, staged, trim, min, max, time, reads + 1,
# apply failsafe, decide, step, writes
_CHANNEL_CYCLES = 6 + len(_READS) + 1 + 3 + len(_WRITES)


def word_defaults(width_bits: int, home: int, enabled: bool) -> list[int]:
    """A channel's 16 words after reset."""
    w = [0] * WORDS_PER_CHANNEL
    w[Word.MAX] = (1 << width_bits) - 1
    w[Word.HOME] = w[Word.TARGET] = w[Word.POS] = home
    w[Word.ENABLE] = int(enabled)
    return w


class ServoEngine(wiring.Component):
    """Channel memory, host ports and the per-period engine of :class:`ServoController`.

    Parameters and stream layouts as documented there; ``load`` gives one channel's width per
    transfer for the PWM bank, ``ik`` stages one servo per transfer (``last`` commits).

    Latency
    -------
    ``16 * channels + 1`` cycles of initialisation after reset; a pass starts at most
    ``servos + 7`` cycles after ``period_start`` and takes ``channels * (28 + W)`` cycles
    at most (``pass_cycles`` in all).

    Throughput
    ----------
    One pass per period; the host ports as in :class:`ServoController`.
    """

    def __init__(self, channels, width_bits, time_bits, home_at_reset, servos):
        self._c, self._w, self._tb = channels, width_bits, time_bits
        self._home, self._servos = home_at_reset, servos
        self._mw = max(width_bits + 2, time_bits)
        self.write_layout = data.StructLayout({"channel": range(channels), "field": 4,
                                               "value": signed(width_bits + 1)})
        self.target_layout = data.StructLayout({"channel": range(channels),
                                                "pulse": width_bits, "time": time_bits})
        self.status_layout = data.StructLayout({"target": width_bits, "current": width_bits,
                                                "moving": 1, "enabled": 1})
        super().__init__({
            "write": In(stream.Signature(self.write_layout)),
            "target": In(stream.Signature(self.target_layout)),
            "ik": In(stream.Signature(data.StructLayout({"channel": range(channels),
                                                         "pulse": width_bits, "last": 1}))),
            "read": In(stream.Signature(range(channels))),
            "status": Out(stream.Signature(self.status_layout)),
            "load": Out(stream.Signature(data.StructLayout({"channel": range(channels),
                                                           "width": width_bits}))),
            "commit": In(1), "keepalive": In(1), "period_start": In(1),
            "failsafe": Out(1), "clamped": Out(1), "bad_write": Out(1), "busy": Out(1),
        })

    @property
    def pass_cycles(self) -> int:
        return self._servos + 6 + 1 + self._c * (_CHANNEL_CYCLES + self._w)

    def _defaults(self):
        home = self._home or [0] * self._c
        return [v for h in home for v in word_defaults(self._w, h, self._home is not None)]

    def elaborate(self, platform):
        m = Module()
        m.submodules.mem = mem = Memory(shape=unsigned(self._mw), depth=WORDS_PER_CHANNEL * self._c,
                                        init=self._defaults())
        rd, wr = mem.read_port(), mem.write_port()
        g = _Globals(self._w)
        host_idle = self._host(m, rd, wr, g)
        self._engine(m, rd, wr, g, host_idle)
        return m

    # -- host side: parameter writes, staging, status reads (only while the engine is idle)
    def _host(self, m, rd, wr, g):
        w = self._w
        state = Signal(range(3))            # 0 idle, 1 second word of a timed target, 2 status read
        rk = Signal(range(6))
        ch = Signal(range(self._c))
        st = Signal(self.status_layout)
        st_valid = Signal()
        idle = (state == 0)
        free = idle & g.eng_idle & ~g.pass_pending
        m.d.comb += [self.status.valid.eq(st_valid), self.status.payload.eq(st)]
        with m.If(self.status.valid & self.status.ready):
            m.d.sync += st_valid.eq(0)
        wp, tp, ip = self.write.payload, self.target.payload, self.ik.payload
        with m.If(free & self.write.valid):
            m.d.comb += self.write.ready.eq(1)
            self._param_write(m, wr, wp, g)
        with m.Elif(free & self.target.valid):
            timed = tp.time != 0
            m.d.comb += [wr.en.eq(1), wr.addr.eq(Cat(Const(Word.STAGED, 4), tp.channel)),
                         wr.data.eq(Cat(tp.pulse, Const(1, 1), timed))]
            m.d.sync += g.failsafe.eq(0)
            with m.If(timed):
                m.d.sync += state.eq(1)
            with m.Else():
                m.d.comb += self.target.ready.eq(1)
        with m.Elif((free | g.ik_open & idle & g.eng_idle) & self.ik.valid):
            m.d.comb += [self.ik.ready.eq(1), wr.en.eq(1),
                         wr.addr.eq(Cat(Const(Word.STAGED, 4), ip.channel)),
                         wr.data.eq(Cat(ip.pulse, Const(1, 1), Const(0, 1)))]
            m.d.sync += [g.failsafe.eq(0), g.ik_open.eq(~ip.last)]
            with m.If(ip.last):
                m.d.sync += g.commit_pending.eq(1)
        with m.Elif(free & self.read.valid & ~st_valid):
            m.d.comb += self.read.ready.eq(1)
            m.d.sync += [state.eq(2), rk.eq(0), ch.eq(self.read.payload)]
        with m.If(state == 1):
            m.d.comb += [self.target.ready.eq(1), wr.en.eq(1),
                         wr.addr.eq(Cat(Const(Word.STAGED_TIME, 4), tp.channel)),
                         wr.data.eq(tp.time)]
            m.d.sync += state.eq(0)
        reads = (Word.TARGET, Word.POS, Word.VEL, Word.ENABLE)
        with m.If(state == 2):
            with m.Switch(rk):
                for i, word in enumerate(reads):
                    with m.Case(i):
                        m.d.comb += rd.addr.eq(Cat(Const(word, 4), ch))
            d = rd.data
            with m.Switch(rk):
                with m.Case(1):
                    m.d.sync += st.target.eq(d[:w])
                with m.Case(2):
                    m.d.sync += st.current.eq(d[:w])
                with m.Case(3):
                    m.d.sync += st.moving.eq((st.target != st.current) | (d[:w] != 0))
                with m.Case(4):
                    m.d.sync += [st.enabled.eq(d[0]), st_valid.eq(1), state.eq(0)]
            m.d.sync += rk.eq(rk + 1)
        return idle

    def _param_write(self, m, wr, wp, g):
        """One :class:`ChannelField` write, refused (``bad_write``) when out of range."""
        v, f = wp.value, wp.field
        ok = Signal()
        with m.Switch(f):
            with m.Case(ChannelField.TRIM):
                m.d.comb += ok.eq(1)
            with m.Case(ChannelField.MIN, ChannelField.MAX, ChannelField.SPEED, ChannelField.ACCEL,
                        ChannelField.HOME, ChannelField.TIMEOUT):
                m.d.comb += ok.eq(v >= 0)
            with m.Case(ChannelField.ENABLE):
                m.d.comb += ok.eq((v >= 0) & (v <= 1))
            with m.Case(ChannelField.FAILSAFE):
                m.d.comb += ok.eq((v >= 0) & (v <= max(FailsafeAction)))
        m.d.comb += self.bad_write.eq(~ok)
        with m.If(ok):
            m.d.sync += g.failsafe.eq(0)
            with m.If(f == ChannelField.TIMEOUT):
                m.d.sync += [g.timeout.eq(v[:self._w]), g.count.eq(0), g.fired.eq(0)]
            with m.Else():
                m.d.comb += [wr.en.eq(1), wr.addr.eq(Cat(f[:3], Const(0, 1), wp.channel)),
                             wr.data.eq(v)]

    # -- the engine
    def _engine(self, m, rd, wr, g, host_idle):
        w, c = self._w, self._c
        r = _Regs(w, self._tb, c)
        with m.If(self.period_start):
            m.d.sync += g.pass_pending.eq(1)
        m.d.comb += self.busy.eq(~g.eng_idle | g.pass_pending)
        with m.If(self.commit):
            m.d.sync += g.commit_pending.eq(1)
        with m.If(self.keepalive):
            m.d.sync += [g.count.eq(0), g.fired.eq(0)]
        m.d.comb += self.failsafe.eq(g.failsafe)
        addr = lambda word: Cat(Const(word, 4), r.ch)  # noqa: E731
        issue = lambda word: m.d.comb.__iadd__(rd.addr.eq(addr(word)))  # noqa: E731
        put = lambda word, value: m.d.comb.__iadd__(  # noqa: E731
            [wr.en.eq(1), wr.addr.eq(addr(word)), wr.data.eq(value)])
        with m.FSM(init="INIT"):
            self._init_states(m, wr, r)
            with m.State("IDLE"):
                m.d.comb += g.eng_idle.eq(1)
                with m.If(g.pass_pending & host_idle & ~g.ik_open):
                    self._start_pass(m, g, r)
                    m.next = "BEGIN"
            with m.State("BEGIN"):
                issue(Word.STAGED)
                m.next = "STAGED"
            self._commit_states(m, rd, r, g, issue, put)
            self._read_states(m, rd, r, g, issue)
            self._motion_states(m, r)
            with m.State("WB"):
                self._writeback(m, r, put)
        return m

    def _init_states(self, m, wr, r):
        """Every word to its reset value (the memory keeps its contents through a reset)."""
        w = self._w
        n = WORDS_PER_CHANNEL * self._c
        home = Signal(w)
        if self._home is not None and any(self._home):
            m.submodules.home_rom = rom = Memory(shape=unsigned(w), depth=self._c, init=self._home)
            rp = rom.read_port()
            nxt = r.init_addr + 1
            m.d.comb += [rp.addr.eq(nxt[4:]), home.eq(rp.data)]
        with m.State("INIT"):
            word = r.init_addr[:4]
            value = Signal(self._mw)
            with m.Switch(word):
                with m.Case(Word.HOME, Word.TARGET, Word.POS):
                    m.d.comb += value.eq(home)
                with m.Case(Word.MAX):
                    m.d.comb += value.eq((1 << w) - 1)
                with m.Case(Word.ENABLE):
                    m.d.comb += value.eq(int(self._home is not None))
            m.d.comb += [wr.en.eq(r.init_started), wr.addr.eq(r.init_addr), wr.data.eq(value)]
            # the first cycle only reads the home ROM's first word
            m.d.sync += r.init_started.eq(1)
            with m.If(r.init_started):
                m.d.sync += r.init_addr.eq(r.init_addr + 1)
                with m.If(r.init_addr == n - 1):
                    m.next = "IDLE"

    def _start_pass(self, m, g, r):
        # a commit strobe in this very cycle counts for the next pass; a keepalive restarts
        # the count without this pass counting
        counting = (g.timeout != 0) & ~g.fired & ~self.keepalive
        expire = counting & (g.count + 1 >= g.timeout)
        m.d.sync += [g.pass_pending.eq(0), g.commit_pending.eq(self.commit),
                     g.commit_now.eq(g.commit_pending), r.ch.eq(0), g.fs_now.eq(expire)]
        with m.If(counting):
            m.d.sync += g.count.eq(g.count + 1)
        with m.If(expire):
            m.d.sync += [g.fired.eq(1), g.failsafe.eq(1)]

    def _commit_states(self, m, rd, r, g, issue, put):
        w = self._w
        d = rd.data
        with m.State("STAGED"):
            m.d.sync += [r.t.eq(d[:w]), r.timed.eq(d[w + 1]), r.rk.eq(0)]
            with m.If(g.commit_now & d[w]):
                put(Word.STAGED, 0)
                issue(Word.TRIM)
                m.next = "TRIM"
            with m.Else():
                m.next = "READ"
        with m.State("TRIM"):
            m.d.sync += [r.t.eq(r.t + d[:w + 1].as_signed()), r.cl.eq(0)]
            issue(Word.MIN)
            m.next = "MIN"
        with m.State("MIN"):
            with m.If(r.t < d[:w]):
                m.d.sync += [r.t.eq(d[:w]), r.cl.eq(1)]
            issue(Word.MAX)
            m.next = "MAX"
        with m.State("MAX"):
            over = r.t > d[:w]
            put(Word.TARGET, Mux(over, d[:w], r.t[:w]))
            m.d.comb += self.clamped.eq(r.cl | over)
            issue(Word.STAGED_TIME)
            m.next = "TIME"
        with m.State("TIME"):
            put(Word.TIMED, Mux(r.timed, d[:self._tb], 0))
            m.next = "READ"

    def _read_states(self, m, rd, r, g, issue):
        w, d = self._w, rd.data
        with m.State("READ"):
            with m.Switch(r.rk):
                for i, word in enumerate(_READS):
                    with m.Case(i):
                        issue(word)
            capture = {
                Word.FAILSAFE: [r.act.eq(d[:2])],
                Word.ENABLE: [r.en.eq(d[0])],
                Word.HOME: [r.x.eq(d[:w])],
                Word.POS: [r.p.eq(d[:w])],
                Word.VEL: [r.u.eq(d[:w]), r.down.eq(d[w])],
                Word.TIMED: [r.n.eq(d[:self._tb])],
                Word.SPEED: [r.sm.eq(d[:w])],
                Word.ACCEL: [r.a.eq(d[:w])],
                Word.STOP: [r.s.eq(d[:w])],
            }
            with m.Switch(r.rk):
                for i, word in enumerate(_READS):
                    with m.Case(i + 1):
                        if word == Word.TARGET:
                            with m.If(~(g.fs_now & (r.act == FailsafeAction.HOME))):
                                m.d.sync += r.x.eq(d[:w])
                        elif word == Word.ACT_ACCEL:
                            # a hold stops the profile: the new acceleration applies at once
                            with m.If((r.u != 0) & ~(g.fs_now & (r.act == FailsafeAction.HOLD))):
                                m.d.sync += r.a.eq(d[:w])
                        else:
                            m.d.sync += capture[word]
            m.d.sync += r.rk.eq(r.rk + 1)
            with m.If(r.rk == len(_READS)):
                m.next = "FAILSAFE"
        with m.State("FAILSAFE"):
            with m.If(g.fs_now):
                with m.Switch(r.act):
                    with m.Case(FailsafeAction.HOLD):
                        m.d.sync += [r.x.eq(r.p), r.u.eq(0), r.s.eq(0), r.n.eq(0)]
                    with m.Case(FailsafeAction.RELAX):
                        m.d.sync += r.en.eq(0)
                    with m.Case(FailsafeAction.HOME):
                        m.d.sync += r.n.eq(0)
            m.next = "DECIDE"

    def _motion_states(self, m, r):
        w, dw = self._w, max(self._w, self._tb)
        rest = [r.u.eq(0), r.s.eq(0)]
        with m.State("DECIDE"):
            m.d.sync += [r.dn.eq(Mux(r.x < r.p, r.p - r.x, r.x - r.p)), r.dd.eq(r.n), r.dr.eq(0),
                         r.dcnt.eq(0), r.div_timed.eq(1), r.wk.eq(0)]
            with m.If(~r.en):
                m.d.sync += rest + [r.n.eq(0)]
                m.next = "WB"
            with m.Elif(r.p == 0):
                m.d.sync += rest + [r.n.eq(0), r.p.eq(r.x)]
                m.next = "WB"
            with m.Elif(r.n != 0):
                m.d.sync += r.down.eq(r.x < r.p)
                m.next = "DIV"
            with m.Else():
                with m.If(r.u == 0):
                    m.d.sync += r.down.eq(r.x < r.p)
                with m.If(r.a == 0):
                    m.next = "UNLIMITED"
                with m.Elif((r.u == 0) & (r.sm != 0)):
                    m.d.sync += [r.dn.eq(r.sm - 1), r.dd.eq(r.a), r.div_timed.eq(0)]
                    m.next = "DIV"
                with m.Else():
                    m.d.sync += r.dr.eq(r.a - 1)
                    m.next = "PROFILE"
        with m.State("DIV"):
            # restoring division, one quotient bit per cycle shifted into dn
            trial = Cat(r.dn[w - 1], r.dr)
            fits = trial >= r.dd
            m.d.sync += [r.dr.eq(Mux(fits, trial - r.dd, trial)[:dw]), r.dn.eq(Cat(fits, r.dn[:w - 1])),
                         r.dcnt.eq(r.dcnt + 1)]
            with m.If(r.dcnt == w - 1):
                with m.If(r.div_timed):
                    m.next = "TIMED_STEP"
                with m.Else():
                    m.next = "PROFILE"
        # one adder moves the pulse for every kind of step, one subtractor gives the distance
        # along the motion: p - s = ~(~p + s), p - x = ~p - ~x
        flip = r.down.replicate(w)
        mv_step, p_next = Signal(w), Signal(w)
        m.d.comb += p_next.eq(((r.p ^ flip) + mv_step)[:w] ^ flip)
        remaining = Signal(signed(w + 2))
        m.d.comb += remaining.eq((r.x ^ flip) - (r.p ^ flip))
        with m.State("TIMED_STEP"):
            m.d.comb += mv_step.eq(r.dn)
            m.d.sync += rest + [r.n.eq(r.n - 1), r.p.eq(p_next)]
            m.next = "WB"
        with m.State("UNLIMITED"):
            m.d.comb += mv_step.eq(Mux((r.sm != 0) & (remaining > r.sm), r.sm, remaining[:w]))
            m.d.sync += rest + [r.p.eq(p_next)]
            m.next = "WB"
        with m.State("PROFILE"):
            step, stop = self._profile(m, r, remaining)
            m.d.comb += mv_step.eq(step)
            m.d.sync += [r.u.eq(step), r.s.eq(stop), r.p.eq(p_next)]
            m.next = "WB"

    def _profile(self, m, r, remaining):
        """The step and stop distance of ``profile_step`` (``sim/servo_model.py``)."""
        w = self._w
        free = r.sm == 0
        rem_ok = remaining >= 0
        first = r.dr[:w] + 1
        up = Signal(w + 1)
        up_stop = Signal(w + 2)
        m.d.comb += [up.eq(Mux(r.u == 0, first, r.u + r.a)),
                     up_stop.eq(up + Mux(r.u == 0, 0, r.s))]
        land = rem_ok & (remaining <= r.a) & (remaining + r.a >= r.u) & (free | (remaining <= r.sm))
        go_up = rem_ok & (free | (up <= r.sm)) & (up_stop <= remaining)
        hold = (r.u != 0) & rem_ok & (free | (r.u <= r.sm)) & (r.s <= remaining)
        nxt = Mux(r.u > r.a, r.u - r.a, 0)
        step, stop = Signal(w), Signal(w)
        with m.If(land):
            m.d.comb += [step.eq(remaining[:w]), stop.eq(remaining[:w])]
        with m.Elif(go_up):
            m.d.comb += [step.eq(up[:w]), stop.eq(up_stop[:w])]
        with m.Elif(hold):
            m.d.comb += [step.eq(r.u), stop.eq(r.s)]
        with m.Else():
            m.d.comb += [step.eq(nxt[:w]), stop.eq(Mux((nxt == 0) | (r.s <= r.u), 0, r.s - r.u))]
        return step, stop

    def _writeback(self, m, r, put):
        values = {Word.ENABLE: r.en, Word.TARGET: r.x, Word.POS: r.p, Word.VEL: Cat(r.u, r.down),
                  Word.STOP: r.s, Word.ACT_ACCEL: r.a, Word.TIMED: r.n}
        with m.Switch(r.wk):
            for i, word in enumerate(_WRITES):
                with m.Case(i):
                    put(word, values[word])
        with m.If(r.wk == 0):
            m.d.comb += [self.load.valid.eq(1), self.load.payload.channel.eq(r.ch),
                         self.load.payload.width.eq(Mux(r.en, r.p, 0))]
        m.d.sync += r.wk.eq(r.wk + 1)
        with m.If(r.wk == len(_WRITES) - 1):
            m.d.sync += r.ch.eq(r.ch + 1)
            m.next = "BEGIN"
            with m.If(r.ch == self._c - 1):
                m.next = "IDLE"


class _Globals:
    """Controller-wide registers (failsafe, commit, pass handshake)."""

    def __init__(self, w):
        self.timeout, self.count = Signal(w), Signal(w)
        self.fired, self.failsafe = Signal(), Signal()
        self.commit_pending, self.commit_now, self.fs_now = Signal(), Signal(), Signal()
        self.pass_pending, self.eng_idle, self.ik_open = Signal(), Signal(), Signal()


class _Regs:
    """The engine's working registers for the channel in hand."""

    def __init__(self, w, tb, c):
        dw = max(w, tb)
        self.ch = Signal(range(c))
        self.init_addr = Signal(range(WORDS_PER_CHANNEL * c))
        self.init_started = Signal()
        self.t = Signal(signed(w + 2))
        self.timed, self.cl = Signal(), Signal()
        self.rk = Signal(range(len(_READS) + 1))
        self.wk = Signal(range(len(_WRITES)))
        self.act, self.en, self.down = Signal(2), Signal(), Signal()
        self.x, self.p, self.u, self.s, self.a, self.sm = (Signal(w) for _ in range(6))
        self.n = Signal(tb)
        self.dn, self.dr, self.dd = Signal(w), Signal(dw), Signal(dw)
        self.dcnt = Signal(range(w))
        self.div_timed = Signal()
