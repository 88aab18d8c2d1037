"""The servo controller's channel memory and its microcoded engine (one pass per PWM period).

One adder does every rule of ``sim/servo_model.py`` in turn (trim, clamp, failsafe counter,
profile, divisions), its operands and temporaries streamed from the channel memory: the logic
is the adder, the accumulator, a division register, the branch multiplexer and the host ports'
multiplexers into the memory; the program (``hdl/servo_microcode.py``) sits in a ROM.
"""
from __future__ import annotations

import enum

from amaranth.hdl import Cat, Const, Module, Mux, ResetSignal, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from .bram import falling_edge_write_port
from .servo_fields import ChannelField, FailsafeAction
from .servo_microcode import BASE_CONDS, CONDS, OPS, SPECIALS, Scratch, assemble, program

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
    STAGED = 8          # pulse | from a target << (A - 2) | staged << (A - 1)
    STAGED_TIME = 9
    TARGET = 10
    POS = 11            # current pulse
    VEL = 12            # profile step | down << W
    STOP = 13           # the profile's stop distance
    ACT_ACCEL = 14      # acceleration in force for the profile
    TIMED = 15          # periods left of a timed move


def word_defaults(width_bits: int, home: int, enabled: bool) -> list[int]:
    """A channel's 16 words after reset."""
    w = [0] * WORDS_PER_CHANNEL
    w[Word.MAX] = (1 << width_bits) - 1
    w[Word.HOME] = w[Word.TARGET] = w[Word.POS] = home
    w[Word.ENABLE] = int(enabled)
    return w




# ROM word fields, low bits first: (name, bits); `to` takes the bits the program's length needs
_MODES = {"add": (0, 0), "sub": (1, 1), "inc": (0, 1), "dec": (1, 0), "div": (2, 2), "dir": (3, 3)}


def _fields(to_bits):
    return (("asel", 2), ("ben", 1), ("inv", 2), ("cin", 2), ("accwe", 1), ("q", 2), ("bh", 1),
            ("mask", 1), ("rdf", 5), ("rdt", 5), ("we", 1), ("ww", 5), ("cond", 5), ("idle", 1),
            ("to", to_bits), ("nxt", to_bits)) + tuple((name, 1) for name in SPECIALS[1:])


def _operand(o):
    return 0 if o is None else o[1] | o[0] << 4


def _encode(asm, to_bits) -> list[int]:
    words = []
    for i, s in enumerate(asm.ins):
        asel, ben, mode, accwe, q = OPS[s.op]
        inv, cin = _MODES[mode]
        v = {"asel": asel, "ben": ben, "inv": inv, "cin": cin, "accwe": accwe,
             "q": {None: 0, "load": 1, "shift": 2}[q], "bh": int(s.op == "LDH"), "mask": int(s.mask),
             "rdf": _operand(asm.rdf[i]), "rdt": _operand(asm.rdt[i]), "we": int(s.st is not None),
             "ww": _operand(s.st), "cond": CONDS[s.cond][0] | CONDS[s.cond][1] << 4,
             "idle": int(s.idle), "to": 0 if s.to is None else asm.labels[s.to],
             "nxt": (i + 1) % len(asm.ins)}
        v.update({name: int(s.sp == name) for name in SPECIALS[1:]})
        word, off = 0, 0
        for name, bits in _fields(to_bits):
            word |= v[name] << off
            off += bits
        words.append(word)
    return words


class ServoEngine(wiring.Component):
    """Channel memory, host ports and the per-period engine of :class:`ServoController`.

    Parameters (``trusted_writes`` too) and stream layouts as documented there; ``load`` gives one channel's width per
    transfer for the PWM bank, ``ik`` stages one servo per transfer (``last`` commits).

    The engine is a microcoded accumulator machine (``hdl/servo_microcode.py``): one adder,
    one ``W``-bit shift register for its divisions, its program in a ROM, its operands and
    temporaries in the channel memory (``16 * (channels + 1)`` words of ``A = max(W + 3,
    time_bits + 2)`` bits, the last row scratch, see :class:`~ikseries.hdl.servo_microcode.Scratch`).

    Latency
    -------
    ``init_cycles = 16 * channels + 1`` cycles of initialisation after reset; a pass starts
    at most ``max(servos, 6) + 2`` cycles after ``period_start`` (an ``ik`` leg or a status
    read in progress finishes first) and takes at most ``8 + channels * C`` cycles, ``C`` the
    longest path through the per-channel microprogram (``pass_cycles`` in all).

    Throughput
    ----------
    One pass per period; the host ports as in :class:`ServoController`.
    """

    def __init__(self, channels, width_bits, time_bits, home_at_reset, servos, trusted_writes=False):
        self._c, self._w, self._tb = channels, width_bits, time_bits
        self._trusted = bool(trusted_writes)
        self._home, self._servos = home_at_reset, servos
        self._aw = max(width_bits + 3, time_bits + 2)
        self._home_rom = home_at_reset is not None and any(home_at_reset)
        self._asm = assemble(program(width_bits, self._home_rom, home_at_reset is not None))
        self._to_bits = max(1, (len(self._asm.ins) - 1).bit_length())
        self.write_layout = data.StructLayout({"channel": range(channels), "field": 4,
                                               "value": signed(width_bits + 1)})
        self.target_layout = data.StructLayout({"channel": range(channels),
                                                "pulse": width_bits, "time": time_bits})
        # one pulse a read, target or current: a reader taking bytes needs one at a time
        self.read_layout = data.StructLayout({"channel": range(channels), "current": 1})
        self.status_layout = data.StructLayout({"pulse": width_bits, "moving": 1, "enabled": 1})
        super().__init__({
            "write": In(stream.Signature(self.write_layout)),
            "target": In(stream.Signature(self.target_layout)),
            "ik": In(stream.Signature(data.StructLayout({"channel": range(channels),
                                                         "pulse": width_bits, "last": 1}))),
            "read": In(stream.Signature(self.read_layout)),
            "status": Out(stream.Signature(self.status_layout)),
            "load": Out(stream.Signature(data.StructLayout({"channel": range(channels),
                                                           "width": width_bits}))),
            "commit": In(1), "keepalive": In(1), "period_start": In(1), "status_shift": In(1),
            "failsafe": Out(1), "clamped": Out(1), "bad_write": Out(1), "busy": Out(1),
        })

    @property
    def init_cycles(self) -> int:
        a = self._asm
        return 1 + self._c * a.longest("INITCH", lambda i: a.ins[i].sp == "INITNEXT")

    @property
    def target_cycles(self) -> int:
        """Cycles of one ``target`` transfer while idle: one memory write per word it stages
        (the pulse with its flags, then its time)."""
        return len((Word.STAGED, Word.STAGED_TIME))

    @property
    def channel_cycles(self) -> int:
        """The longest path of one channel through the microprogram."""
        a = self._asm
        return a.longest("CH0", lambda i: a.ins[i].sp == "LOADNEXT")

    @property
    def read_cycles(self) -> int:
        """Most cycles from a ``read`` offered while the engine idles to ``status.valid``: to
        its accepting instruction (it alternates with the pass test), the status path."""
        a = self._asm
        return 2 + a.longest("S0", lambda i: a.ins[i].sp == "ST_E") + 1

    @property
    def pass_cycles(self) -> int:
        a = self._asm
        status = a.longest("S0", lambda i: a.ins[i].sp == "ST_E")
        start = a.longest("PASS", lambda i: a.ins[i].label == "CH0") - 1
        # wait for the host (an ik leg, a status read, a timed target's second word), see the
        # pending pass in IDLE0, the globals, the channels, back to IDLE0
        return max(self._servos, status + 1, 2) + 2 + start + self._c * self.channel_cycles + 1

    def _defaults(self):
        home = self._home or [0] * self._c
        words = [v for h in home for v in word_defaults(self._w, h, self._home is not None)]
        scratch = [0] * WORDS_PER_CHANNEL
        scratch[Scratch.FULL] = (1 << self._w) - 1
        return words + scratch

    def elaborate(self, platform):
        m = Module()
        m.submodules.mem = mem = Memory(shape=unsigned(self._aw), depth=WORDS_PER_CHANNEL * (self._c + 1),
                                        init=self._defaults())
        m.submodules.rom = rom = Memory(shape=unsigned(sum(b for _, b in _fields(self._to_bits))),
                                        depth=len(self._asm.ins), init=_encode(self._asm, self._to_bits))
        rd, wr, rp = mem.read_port(), falling_edge_write_port(m, mem), rom.read_port()
        g = _Globals(self)
        u = self._decode(m, rp.data, g)
        host_idle = self._host(m, wr, g, u)
        self._sequencer(m, rp, rd, g, u, host_idle)
        self._datapath(m, rd.data, wr, g, u)
        self._specials(m, rd.data, g, u)
        return m

    def _decode(self, m, word, g):
        """The fields of the instruction in hand (one bit per special strobe: no decoder); the
        sequencer reads word 0 (INIT) in every reset cycle, so they are an instruction's from
        the first cycle after a reset (after configuration without one, 0: a no-op to INIT)."""
        u, off = {}, 0
        for name, bits in _fields(self._to_bits):
            u[name] = word[off:off + bits]
            off += bits
        u["is"] = lambda name: u[name]  # noqa: E731
        return u

    # -- host side: parameter writes and staging, while the engine idles
    def _host(self, m, wr, g, u):
        aw = self._aw
        second = Signal()                   # a timed target's second word (its time)
        host_idle = ~second
        m.d.comb += g.free.eq(u["idle"] & ~g.pass_pending & host_idle)
        wp, tp, ip = self.write.payload, self.target.payload, self.ik.payload
        staged = Const(1 << (aw - 1), aw)
        we, addr, value = Signal(), Signal(len(wr.addr)), Signal(aw)
        with m.If(g.free & self.write.valid):
            m.d.comb += self.write.ready.eq(1)
            # a trusted writer sends only values in range: no check (ServoController)
            ok = Const(1) if self._trusted else self._param_ok(m, wp)
            m.d.comb += self.bad_write.eq(~ok)
            # TIMEOUT (8) lands on word 0 of the scratch row
            m.d.comb += [we.eq(ok), addr.eq(Cat(wp.field[:3], Const(0, 1),
                                                Mux(wp.field[3], self._c, wp.channel))),
                         value.eq(wp.value)]
            with m.If(ok):
                m.d.sync += g.failsafe.eq(0)
                with m.If(wp.field == ChannelField.TIMEOUT):
                    m.d.sync += [g.tvalid.eq(1), g.ka.eq(1), g.fired.eq(0)]
        with m.Elif(g.free & self.target.valid):
            # the "timed" flag marks a target (its time, 0 = untimed, follows) from an ik servo
            m.d.comb += [we.eq(1), addr.eq(Cat(Const(Word.STAGED, 4), tp.channel)),
                         value.eq(staged | tp.pulse | (1 << (aw - 2)))]
            m.d.sync += [g.failsafe.eq(0), second.eq(1)]
        with m.Elif((g.free | g.ik_open & u["idle"] & host_idle) & self.ik.valid):
            m.d.comb += [self.ik.ready.eq(1), we.eq(1), addr.eq(Cat(Const(Word.STAGED, 4), ip.channel)),
                         value.eq(staged | ip.pulse)]
            m.d.sync += [g.failsafe.eq(0), g.ik_open.eq(~ip.last)]
            with m.If(ip.last):
                m.d.sync += g.commit_pending.eq(1)
        with m.If(second):
            m.d.comb += [self.target.ready.eq(1), we.eq(1),
                         addr.eq(Cat(Const(Word.STAGED_TIME, 4), tp.channel)), value.eq(tp.time)]
            m.d.sync += second.eq(0)
        m.d.comb += [g.host_we.eq(we), g.host_addr.eq(addr), g.host_data.eq(value)]
        return host_idle

    def _param_ok(self, m, wp):
        """Whether a :class:`ChannelField` write is in its field's range."""
        v, ok = wp.value, Signal()
        with m.Switch(wp.field):
            with m.Case(ChannelField.TRIM):
                m.d.comb += ok.eq(1)
            with m.Case(ChannelField.MIN, ChannelField.MAX, ChannelField.SPEED, ChannelField.ACCEL,
                        ChannelField.HOME, ChannelField.TIMEOUT):
                m.d.comb += ok.eq(v >= 0)
            with m.Case(ChannelField.ENABLE):
                m.d.comb += ok.eq((v >= 0) & (v <= 1))
            with m.Case(ChannelField.FAILSAFE):
                m.d.comb += ok.eq((v >= 0) & (v <= max(FailsafeAction)))
        return ok

    # -- the microprogram's sequencer: conditions, next instruction, operand address
    def _sequencer(self, m, rp, rd, g, u, host_idle):
        w, aw, c = self._w, self._aw, self._c
        d = rd.data
        # the adder's flags come last (through its carry chain and the zero test): the tree
        # chooses among the other conditions (0 for n, z, le; nocount's other terms), the flags
        # join after it, one LUT level before the addresses (they were at the tree's leaves)
        base = {"0": Const(0, 1), "n": Const(0, 1), "z": Const(0, 1), "le": Const(0, 1),
                "staged": g.commit_now & d[aw - 1], "fs_now": g.fs_now, "D0": d[0], "D1": d[1], "DW": d[w],
                "tflag": g.tflag, "last": g.ch == c - 1, "ka": g.ka, "nocount": g.fired | ~g.tvalid,
                "go": g.pass_pending & host_idle & ~g.ik_open, "rdreq": g.rdreq}
        m.d.comb += g.rdreq.eq(g.free & self.read.valid & ~g.st_valid)
        # a binary tree of 2:1 multiplexers (an indexed Array maps to a much larger shifter)
        level = [base[k] for k in BASE_CONDS]
        for bit in range(4):
            level = [Mux(u["cond"][bit], hi, lo) for lo, hi in zip(level[::2], level[1::2])]
        code = u["cond"][:4]
        on = {k: code == BASE_CONDS.index(k) for k in ("n", "z", "le", "nocount")}
        uses_n, uses_z = on["n"] | on["le"], on["z"] | on["le"] | on["nocount"]
        m.d.comb += g.take.eq((level[0] | (uses_n & g.n) | (uses_z & g.z)) ^ u["cond"][4])
        # the fall-through address is a ROM field too: no program counter, no incrementer
        m.d.comb += rp.addr.eq(Mux(ResetSignal(allow_reset_less=True), 0, Mux(g.take, u["to"], u["nxt"])))
        # the last instruction of a channel already reads the next channel's first operand
        ch_next = Mux(u["is"]("LOADNEXT") | u["is"]("INITNEXT"), g.ch + 1, g.ch)
        # both successors' addresses, then the branch's choice: take (the adder's flags through
        # the condition multiplexer, the engine's longest path) meets one multiplexer level only
        addr = [Cat(o[:4], Mux(o[4], c, ch_next)) for o in (u["rdf"], u["rdt"])]
        m.d.comb += rd.addr.eq(Mux(g.take, addr[1], addr[0]))
        m.d.comb += self.busy.eq(~u["idle"] | g.pass_pending)

    # -- the single adder, the accumulator, the division register, the memory write
    def _datapath(self, m, d, wr, g, u):
        w, aw, c = self._w, self._aw, self._c
        acc, q = g.acc, g.q
        deff = Cat(d[:w], Mux(u["mask"], 0, d[w:]))
        if self._home_rom:
            m.submodules.home_rom = rom = Memory(shape=unsigned(w), depth=c, init=self._home)
            hp = rom.read_port()
            m.d.comb += hp.addr.eq(g.ch)
            deff = Mux(u["bh"], hp.data, deff)
        b = Mux(u["ben"], deff, 0)
        sign = acc[aw - 1]
        inv, cin = Signal(), Signal()
        for sig, f in ((inv, u["inv"]), (cin, u["cin"])):
            m.d.comb += sig.eq(Mux(f[1], Mux(f[0], g.down, ~sign), f[0]))
        sel = u["asel"]
        shifted = Cat(q[w - 1], acc[:aw - 1])
        a = Mux(sel[1], Mux(sel[0], ~acc, shifted), Mux(sel[0], acc, 0))
        r = Signal(aw)
        m.d.comb += [r.eq(a + (b ^ inv.replicate(aw)) + cin), g.n.eq(r[aw - 1]), g.z.eq(r == 0)]
        with m.If(u["accwe"]):
            m.d.sync += acc.eq(r)
        with m.Switch(u["q"]):
            with m.Case(1):
                m.d.sync += q.eq(acc[:w])
            with m.Case(2):
                m.d.sync += q.eq(Cat(~r[aw - 1], q[:w - 1]))
        # a VEL write carries the direction of the motion at bit W
        vel = u["ww"] == Word.VEL
        eng_data = Cat(acc[:w], acc[w] | (g.down & vel), acc[w + 1:])
        m.d.comb += [wr.en.eq(g.host_we | u["we"]),
                     wr.addr.eq(Mux(g.host_we, g.host_addr, Cat(u["ww"][:4], Mux(u["ww"][4], c, g.ch)))),
                     wr.data.eq(Mux(g.host_we, g.host_data, eng_data))]
        m.d.comb += [self.load.valid.eq(u["is"]("LOADNEXT")), self.load.payload.channel.eq(g.ch),
                     self.load.payload.width.eq(acc[:w])]

    # -- strobes of the instruction in hand; the controller-wide flags
    def _specials(self, m, d, g, u):
        w, aw, s = self._w, self._aw, u["is"]
        st = g.st
        m.d.comb += [self.status.valid.eq(g.st_valid), self.status.payload.eq(st),
                     self.failsafe.eq(g.failsafe), self.read.ready.eq(s("ACCEPT") & g.rdreq)]
        with m.If(self.status.valid & self.status.ready):
            m.d.sync += g.st_valid.eq(0)
        with m.If(self.period_start):
            m.d.sync += g.pass_pending.eq(1)
        with m.If(self.commit):
            m.d.sync += g.commit_pending.eq(1)
        m.d.sync += self.clamped.eq(s("CLAMPED"))
        with m.If(s("CH0")):
            m.d.sync += g.ch.eq(0)
        with m.If(s("START")):
            m.d.sync += [g.pass_pending.eq(0), g.commit_pending.eq(self.commit), g.ch.eq(0),
                         g.commit_now.eq(g.commit_pending), g.fs_now.eq(0)]
        with m.If(s("CLRKA")):
            m.d.sync += g.ka.eq(0)
        with m.If(s("FIRE")):
            m.d.sync += [g.fs_now.eq(1), g.fired.eq(1), g.failsafe.eq(1)]
        with m.If(s("TCAP")):
            m.d.sync += g.tflag.eq(d[aw - 2])
        with m.If(s("CAPTURE")):
            m.d.sync += g.down.eq(g.take)
        with m.If(s("LOADNEXT") | s("INITNEXT")):
            m.d.sync += g.ch.eq(g.ch + 1)
        with m.If(s("ACCEPT") & g.rdreq):
            m.d.sync += [g.ch.eq(self.read.payload.channel), g.st_current.eq(self.read.payload.current)]
        # a byte-serial reader takes the pulse a byte at a time from its low byte (no choice
        # of bytes); a status read starts only once the offered one is taken, so its loads
        # never meet a shift
        with m.If(self.status_shift):
            m.d.sync += st.pulse.eq(st.pulse >> 8)
        with m.If(s("ST_T") & ~g.st_current):
            m.d.sync += st.pulse.eq(d[:w])
        with m.If(s("ST_C") & g.st_current):
            m.d.sync += st.pulse.eq(d[:w])
        with m.If(s("ST_C")):
            m.d.sync += st.moving.eq(~g.z)
        with m.If(s("ST_M") & ~g.z):
            m.d.sync += st.moving.eq(1)
        with m.If(s("ST_E")):
            m.d.sync += [st.enabled.eq(d[0]), g.st_valid.eq(1)]
        # a keepalive restarts the count at the next pass and wins over a firing in this cycle
        with m.If(self.keepalive):
            m.d.sync += [g.ka.eq(1), g.fired.eq(0)]


class _Globals:
    """Controller-wide registers and the engine's wires between its parts."""

    def __init__(self, eng):
        w, aw, c = eng._w, eng._aw, eng._c
        self.ch = Signal(range(c + 1))
        self.acc, self.q = Signal(aw), Signal(w)
        self.n, self.z, self.take = Signal(), Signal(), Signal()
        self.tflag, self.down = Signal(), Signal()
        self.fired, self.failsafe, self.tvalid, self.ka = Signal(), Signal(), Signal(), Signal()
        self.commit_pending, self.commit_now, self.fs_now = Signal(), Signal(), Signal()
        self.pass_pending, self.ik_open, self.free, self.rdreq = Signal(), Signal(), Signal(), Signal()
        self.host_we, self.host_addr = Signal(), Signal(4 + (c).bit_length())
        self.host_data = Signal(aw)
        self.st, self.st_valid = Signal(eng.status_layout), Signal()
        self.st_current = Signal()      # the read in progress asked for the current pulse
