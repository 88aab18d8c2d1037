"""The controller's command dispatcher: a request from the link in, its effect on the IK core
and the servo controller, its answer back to the link. A microcoded byte-serial machine; its
program and assembler are ``hdl/dispatch_microcode.py``."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, ResetSignal, Signal, unsigned
from amaranth.lib import wiring
from amaranth.lib.memory import Memory

from . import protocol as P
from .answers import answer_bytes, answer_constant
from .bram import falling_edge_write_port
from .dispatch_microcode import (CONDS, MOVE_TIME_WORD, OPS, SOURCES, STROBES, Geometry, assemble, encode, fields,
                                 program)

__all__ = ["Dispatcher"]

_C = {c.name: c for c in P.COMMANDS}
#: answers the dispatcher builds in its memory
_BUILT = (_C["status"].answer, _C["channel_status"].answer, P.NACK_FIELDS)


class _Regs:
    """The machine's registers."""

    def __init__(self, d):
        self.cmd = Signal(8)
        self.f = Signal(32)                                 # the field register
        self.b_ = Signal()                                  # the borrow
        self.bl = Signal()                                  # a borrow kept (below; the second mask)
        self.tg = Signal(16 * d._coords)                    # one leg's target, saturated
        self.ra = Signal(range(d._max_request + 1))         # next payload byte to read
        self.ch = Signal(max(3, d._channels.bit_length()))
        self.lm = Signal(d._legs)                           # legs of a move, rotated a leg at a time
        self.leg = Signal(range(d._legs + 1))
        self.s = Signal(8)
        self.out = Signal()                                 # a coordinate of this leg was saturated
        # answer byte being built, then (as the link's answer_index) the count of those sent
        self.b = Signal(range(max(d._region, d._max_answer + 1)))
        self.nack, self.ident, self.sending = Signal(), Signal(), Signal()
        self.pending, self.started = Signal(), Signal()     # a commit not yet applied; its pass began
        self.mt = Signal()                                  # the memory's move time word was written


class Dispatcher(wiring.Component):
    """Executes the link's requests (``docs/protocol.md``) on an IK core and a servo controller.

    A request is read from the link's payload memory a field at a time, a byte at a time into
    one 32-bit field register (zero- or sign-extended), checked, executed, then answered: an
    acknowledgement, an answer, or NACK ``bad_value`` for a field out of range for this robot (a
    channel, a leg, a leg or channel mask, a pulse, trim, speed, acceleration, home or failsafe
    timeout that does not fit ``width_bits``, limits with min > max, an unknown failsafe
    action). A NACKed request changes nothing. Every request taken pulses ``keepalive`` (the
    cycle after). An answer header waits until the servo controller has taken the writes,
    targets and commit. Requests arrive at the line rate, thousands of cycles apart, so
    everything is byte-serial, run by a microprogram (``hdl/dispatch_microcode.py``) in a ROM:
    every range check and each target coordinate's saturation is a comparison of the field
    register's bytes with the program's constants by one 8-bit subtract-with-borrow unit;
    answers are built a byte a cycle in block RAM. The streams to the servo controller and the
    core are driven by the ROM's output register and by registers, and so is the answer header
    (valid and length from the ROM while its instruction waits for the link to take it, its code
    from the request's and the NACK flag); the conditions a wait ends on are the one
    combinational path in from them.

    Moves: each leg of a ``move_leg``/``move_legs`` target goes through the IK core, one leg at
    a time; a coordinate is saturated to the plan input's ``[lo, hi]`` first (``status`` counts
    the leg targets that were outside in ``clamped``), so a port never sees a value it cannot
    carry. The widths are buffered (one word per channel), then all staged on the servo
    controller's ``target`` stream with the current move time and committed by one strobe,
    in a part of the PWM period where the engine's pass cannot start before the commit: the
    channels of one request always change together, at one period start. Leg ``l`` servo ``j``
    is channel ``l * servos + j``. ``set_pulse`` stages its one channel the same way, so a
    move time applies to it as well.

    One memory (block RAM) holds the width buffer, the answer being built (status, channel_status,
    NACK) and the identity answer (its initial contents); the link pulls answer bytes from it.

    Parameters
    ----------
    plan : Plan
        The leg plan (its inputs are the target coordinates, in order).
    legs : int
    core, servo, link : wiring.Component
        The :class:`~ikseries.hdl.shared.RobotCore`, :class:`~ikseries.hdl.servo.ServoController`
        and :class:`~ikseries.hdl.link.Link` this dispatcher sits between (only their signatures
        are read).
    width_bits : int
        The servo controller's ``width_bits``.
    identity : dict
        The identity answer's fields (``version`` .. ``name``).

    Attributes
    ----------
    request, rd_addr, rd_data, counter_addr, counter_data, answer, answer_data, answer_index,
    answer_done
        To the link's ports of the same names.
    clamped
        To the link's ``clamped``: a pulse (registered) per leg target that was saturated; the
        link counts it in its counter memory (word ``CLAMPED_WORD``).
    ik_i, ik_o, ik_rotate
        To the core's ``i``, ``o`` and ``rotate`` (a :class:`~ikseries.hdl.shared.RobotCore` with
        ``held_input`` and ``rotate_outputs``).
    write, target, commit, read, status, status_shift, keepalive, busy, period_start, phase
        To the servo controller's ports of the same names.

    Reset state: idle, no answer pending, move time 0 (the status answer's counters are the
    link's: its error counters, the uptime in words ``UPTIME_WORD`` and the next, and
    ``clamped`` in word ``CLAMPED_WORD`` of its counter memory). The reset is the ``sync``
    domain's own (not a ``ResetInserter``'s): the program ROM reads its first word in every reset
    cycle, so its output is an instruction from the first cycle after it.

    Latency
    -------
    One instruction a cycle; from ``request.valid`` to the answer header: a byte-serial field
    takes 5 cycles (the payload memory's latency, then its 4 bytes), a second comparison of it 4
    more; each wait for the servo controller (a write, a read, the staging window) as long as it
    takes it, its engine's pass (``pass_cycles``) at most. Moves: :meth:`move_cycles` to the
    commit strobe (per selected leg its ``C`` coordinates, the core's latency and ``servos``
    cycles; a wait of at most ``stage_cycles + pass_cycles`` for the staging window and
    ``stage_cycles`` to stage and commit), the header (a register) 2 cycles after the strobe.
    Status: a read of the servo controller per channel and flag of its two masks, then a cycle
    per answer byte (the link's counters read as they are then); channel_status: once the last
    commit has been applied by a pass (so its answer shows every earlier move) and in the
    staging window (so that no pass comes between them), the channel's two reads (target,
    current), a cycle per answer byte. The widths reach the pins in the period after the commit
    (its pass, then the pulses ``lead`` cycles after that period's start: the servo
    controller's latency). The answer's bytes are offered
    on ``answer_data`` in order, each the cycle after the previous one is taken (``answer_index``
    counts them: the link's transmitter ends the payload at its length). A request waits
    in the link until the previous answer's payload has been sent (an empty one's CMD byte: the
    link's transmitter reads the answer code from here as it sends it).

    Throughput
    ----------
    One request at a time. A full ``move_legs`` takes at most ``move_cycles(legs)``, about
    ``legs * (11 C + latency + servos + 5) + pass_cycles + 2 * stage_cycles`` cycles, far below
    the line time of its frame at the rates :func:`~ikseries.hdl.uart.uart_divisor` allows for
    a clock of tens of MHz (see ``tests/test_controller.py``, which measures it): the UART
    is the limit.
    """

    def __init__(self, plan, legs: int, core, servo, link, width_bits: int, identity: dict):
        self._plan, self._legs = plan, legs
        self._coords, self._servos = len(plan.inputs), len(core.servos)
        self._channels, self._w, self._period = servo.channels, width_bits, servo.period
        self._time_bits = len(servo.target.payload.time)
        self._shape = P.Shape(legs, self._coords, self._channels)
        self._max_request = P.max_request_payload(self._shape)
        self._max_answer = link.transmitter.max_payload
        self._identity = answer_constant(_C["identity"].answer, identity)
        # three regions of one size in the memory: widths, the answer being built, identity;
        # an address is the region above the offset, so no adder
        # the answer region also holds the move time, after every answer built there
        biggest = max([self._channels, len(self._identity), MOVE_TIME_WORD + 1] + [answer_bytes(f) for f in _BUILT])
        self._region = 1 << (biggest - 1).bit_length()
        self._geometry = Geometry(self._channels, legs, self._servos, width_bits,
                                  tuple((inp.lo, inp.hi) for inp in plan.inputs), len(self._identity))
        self._asm = assemble(program(self._geometry))
        # from the cycle the staging window is seen open to the commit strobe on the port, every
        # leg selected (a read cycle and a target transfer per channel), plus a margin cycle
        staging = 1 + legs * (1 + self._servos * (1 + servo.target_cycles)) + 3
        # channel_status's two reads (target, current) in the window too: no pass between them
        reads = self._asm.longest("CSR", ("CSHDR",)) + 2 * servo.read_cycles
        self._stage_cycles = max(staging, reads)
        self._pass_cycles, self._core_latency = servo.pass_cycles, core.latency
        ls, cs, ss = link.signature.members, core.signature.members, servo.signature.members
        super().__init__({
            **{n: ls[n].flip() for n in ("request", "rd_addr", "rd_data", "counter_addr",
                                         "counter_data", "answer", "answer_data", "answer_index",
                                         "answer_done",
                                         "clamped")},
            "ik_i": cs["i"].flip(), "ik_o": cs["o"].flip(), "ik_rotate": cs["rotate"].flip(),
            **{n: ss[n].flip() for n in ("write", "target", "commit", "read", "status",
                                         "keepalive", "busy", "period_start", "phase", "status_shift")},
        })
        self._servo_names = core.servos

    @property
    def shape(self) -> P.Shape:
        return self._shape

    @property
    def stage_cycles(self) -> int:
        """Cycles from the decision to stage a group of widths to its commit strobe, inclusive
        of a margin cycle, or more (channel_status's reads): staging starts only with this many
        cycles left before a period start."""
        return self._stage_cycles

    @property
    def program_words(self) -> tuple[int, int]:
        """Instructions of the microprogram and the words of its ROM."""
        return sum(w is not None for w in self._asm.words), len(self._asm.words)

    def move_cycles(self, legs: int) -> int:
        """Most cycles from ``request.valid`` of a move of ``legs`` legs to its commit strobe:
        the command and the leg field (the longest path through the program), each leg through
        the core (unselected legs ``servos + 2`` cycles each), a wait for the staging window (it
        may just have closed: the rest of the period and a pass), and the staging itself. A
        ``set_pulse`` is a move of no legs."""
        a = self._asm
        fetch = max(a.longest("IDLE", ("LEG", "NACK"), _C[n].code) for n in ("move_leg", "move_legs"))
        fetch = max(fetch, a.longest("IDLE", ("SPW", "NACK"), _C["set_pulse"].code))
        # the leg's head and coordinates, the offer (the core idle within 2 cycles), its
        # latency, the other servos' widths, the loop's tail
        per_leg = 1 + a.longest("K0", ("OFFER",)) + 2 + self._core_latency + self._servos + 1
        return (fetch + (self._legs - legs) * (self._servos + 2) + legs * per_leg + 1
                + self._pass_cycles + 2 * self._stage_cycles)

    def elaborate(self, platform):
        m = Module()
        r = _Regs(self)
        m.submodules.mem = mem = Memory(shape=max(self._w, 8), depth=3 * self._region,
                                        init=[0] * (2 * self._region) + list(self._identity))
        wr, rd = falling_edge_write_port(m, mem), mem.read_port()
        width = sum(b for _, b in fields(len(self._asm.words)))
        m.submodules.rom = rom = Memory(shape=unsigned(width), depth=len(self._asm.words),
                                        init=encode(self._asm))
        rp = rom.read_port()
        u, off = {}, 0
        for name, bits in fields(len(self._asm.words)):
            u[name] = rp.data[off:off + bits]
            off += bits
        # sz and bsel are the immediate's low bits (dispatch_microcode.encode)
        u["sz"], u["bsel"] = u["imm"][1], u["imm"][0]
        take, fire = self._sequencer(m, r, u, rp)
        # a wait's register effects wait for its condition (assemble allows a wait only the
        # channel, memory, CLI and HDR effects): the others need not see the condition, whose
        # path from the servo controller, core and link is the longest of the design
        s = {name: u[name] for name in STROBES}
        e = {name: u[name] & fire if name in ("CLI", "HDR") else u[name] for name in STROBES}
        x = self._source(m, r, u)
        self._datapath(m, r, u, x, fire, e)
        self._memory(m, r, u, x, fire, wr, rd)
        self._ports(m, r, u, s, e, rd)
        return m

    def _op(self, m, u, name, fire=None):
        """One-cycle enables of the operations of ROM field ``name`` (as a wait ends: ``fire``)."""
        return {op: u[f"{name}_{op}"] if fire is None else u[f"{name}_{op}"] & fire for op in OPS[name]}

    # -- conditions and the next address
    def _sequencer(self, m, r, u, rp):
        c = self._channels
        # the window: fewer than period - stage_cycles - 1 cycles since the last period start,
        # registered a cycle late (the count has moved on by one, or restarted: then it errs
        # closed). period_start is high at phase 1, so those are phases 2 .. period -
        # stage_cycles, seen at phases 3 .. period - stage_cycles + 1: a flag set by
        # period_start, cleared by one comparison of the PWM bank's counter with a constant (a
        # few LUTs, no counter of the dispatcher's own). It opens a cycle early, at phase 2,
        # where the servo controller is busy with the pass period_start began: the window
        # opens no sooner
        early = Signal()
        with m.If(self.period_start):
            m.d.sync += early.eq(1)
        with m.Elif(self.phase == self._period - self._stage_cycles + 1):
            m.d.sync += early.eq(0)
        window = ~self.busy & early
        base = {"0": Const(0, 1), "B": r.b_, "BL": r.bl,
                "reqok": self.request.valid & ~r.sending,
                "ik_ready": self.ik_i.ready, "ik_valid": self.ik_o.valid, "wr_ready": self.write.ready,
                "tg_ready": self.target.ready, "rd_ready": self.read.ready, "st_valid": self.status.valid,
                "ans_ready": self.answer.ready, "window": window, "LM0": r.lm[0], "S0": r.s[0],
                "leglast": r.leg == self._legs - 1, "chlast": r.ch == c - 1, "chlow0": r.ch[:3] == 0,
                "applied": ~r.pending & window}
        # a binary tree of 2:1 multiplexers over the condition index
        level = [base[k] for k in CONDS] + [Const(0, 1)] * (32 - len(CONDS))
        for bit in range(5):
            level = [Mux(u["cond"][bit], hi, lo) for lo, hi in zip(level[::2], level[1::2])]
        take = Signal()
        m.d.comb += take.eq(level[0] ^ u["inv"])
        # a wait's effects happen as it ends; the waits that have effects are those assemble
        # allows, each ended by one stream's handshake: fire sees only that, not the whole
        # condition multiplexer
        ends = ((u["TGV"] & self.target.ready) | (u["wm_width"] & self.ik_o.valid)
                | (u["IKV"] & self.ik_i.ready) | (u["HDR"] & self.answer.ready))
        fire = ~u["hold"] | ends
        cmd = r.cmd
        # the dispatch index of the command code (dispatch_microcode.command_index)
        index = Cat(cmd[:2], cmd[2] ^ ~cmd[5], cmd[3] ^ cmd[4])
        # a dispatch's nxt field holds its table's address (encode): only the entry's index is
        # chosen here
        nxt = Cat(Mux(u["DISP"], index, u["nxt"][:4]), u["nxt"][4:])
        # every reset cycle reads word 0 (IDLE), so the ROM's output is an instruction from the
        # first cycle after a reset, and no effect needs gating in that cycle; without a reset
        # (after configuration) the output register is 0: a no-op (condition never, next 0)
        rst = ResetSignal(allow_reset_less=True)
        m.d.comb += rp.addr.eq(Mux(rst, 0, Mux(take, u["to"], nxt)))
        return take, fire

    # -- the byte X: payload, field register, answer sources
    def _source(self, m, r, u):
        st, imm, cd = self.status.payload, u["imm"], self.counter_data
        flag = Mux(u["bsel"] | r.bl, st.enabled, st.moving)
        src = {"IMM": imm, "RD": self.rd_data, "F0": r.f[:8], "SEXT": r.f[31].replicate(8),
               "CNT": Mux(imm[4], cd[8:16], cd[:8]), "S": r.s, "FLAG": flag, "CMD": r.cmd,
               "STB": st.pulse[:8]}
        # STB's byte is the low byte of the status's pulse; the servo controller then shifts
        # it a byte down
        m.d.comb += self.status_shift.eq(u["src"] == SOURCES.index("STB"))
        x = Signal(8)
        with m.Switch(u["src"]):
            for name, sig in src.items():
                with m.Case(SOURCES.index(name)):
                    m.d.comb += x.eq(sig)
        self._flag = flag
        return x

    def _datapath(self, m, r, u, x, fire, e):
        imm = u["imm"]
        y = Mux(u["ysel"], r.f[:8], imm)
        # X - Y - borrow, bit 7 of both flipped for a signed comparison's top byte
        xb, yb = Cat(x[:7], x[7] ^ u["bias"]), Cat(y[:7], y[7] ^ u["bias"])
        # a first byte's borrow in: sz, when Y is F (the immediate is free then)
        cin = Mux(u["first"], u["sz"] & u["ysel"], r.b_)
        total = Signal(9)
        m.d.comb += total.eq(xb + (~yb)[:8] + ~cin)
        with m.If(u["alu"]):
            m.d.sync += r.b_.eq(~total[8])
        with m.If(e["LATCH"]):
            m.d.sync += r.bl.eq(r.b_)
        with m.If(u["shf"]):
            m.d.sync += r.f.eq(Cat(r.f[8:], x))
        with m.If(u["tg"]):
            m.d.sync += r.tg.eq(Cat(r.tg[8:], y))
        ra = self._op(m, u, "ra")
        with m.If(ra["inc"]):
            m.d.sync += r.ra.eq(r.ra + 1)
        with m.If(ra["set"]):
            m.d.sync += r.ra.eq(imm)
        with m.If(ra["clear"]):
            m.d.sync += r.ra.eq(0)
        ch = self._op(m, u, "ch", fire)
        with m.If(ch["inc"]):
            m.d.sync += r.ch.eq(r.ch + 1)
        with m.If(ch["load"]):
            m.d.sync += r.ch.eq(r.f[:len(r.ch)])
        lm = self._op(m, u, "lm")
        with m.If(lm["rot"]):
            m.d.sync += [r.lm.eq(Cat(r.lm[1:], r.lm[0])), r.leg.eq(r.leg + 1)]
        with m.If(lm["mask"]):
            m.d.sync += [r.lm.eq(r.f[:self._legs]), r.leg.eq(0)]
        with m.If(lm["one"]):
            m.d.sync += [r.lm.eq(Const(1, self._legs) << r.f[:max(1, (self._legs - 1).bit_length())]),
                         r.leg.eq(0)]
        with m.If(ch["clear"]):
            m.d.sync += [r.ch.eq(0), r.leg.eq(0)]
        sh = self._op(m, u, "s")
        with m.If(sh["shift"]):
            m.d.sync += r.s.eq(Cat(r.s[1:], self._flag & ~u["sz"]))
        with m.If(sh["load"]):
            m.d.sync += r.s.eq(self.rd_data)
        # one-register strobes, in this order (a later one wins in the same cycle)
        for strobe, reg, value in (("CLRO", r.out, 0), ("OUTS", r.out, 1), ("MT", r.mt, 1),
                                   ("NACK", r.nack, 1), ("IDENT", r.ident, 1)):
            with m.If(e[strobe]):
                m.d.sync += reg.eq(value)
        # every cycle of the idle wait: the request's command is held while it is offered; the
        # previous answer's code (the command and NACK flag) and the identity answer's region
        # are kept while it is sent (the link's transmitter reads the code as it sends it)
        with m.If(e["TAKE"]):
            m.d.sync += [r.ra.eq(0), r.bl.eq(0)]
            with m.If(~r.sending):
                m.d.sync += [r.cmd.eq(self.request.payload.command), r.b.eq(0), r.nack.eq(0), r.ident.eq(0)]
        # a leg target saturated: counted in the link's counter memory (registered: one pulse)
        m.d.sync += self.clamped.eq(e["CLI"] & r.out)

    def _region_addr(self, region: int, offset):
        return Cat(offset[:(self._region - 1).bit_length()], Const(region, 2))

    def _memory(self, m, r, u, x, fire, wr, rd):
        wm = self._op(m, u, "wm", fire)
        # the core's output moves a servo on per width taken (RobotCore rotate_outputs): the
        # first servo's is every width in turn, no choice of three
        widths = self.ik_o.payload.widths[self._servo_names[0]]
        m.d.comb += self.ik_rotate.eq(wm["width"])
        # B builds an answer, then counts its bytes as the link takes them (answer_index)
        taken = self.answer_data.valid & self.answer_data.ready
        with m.If(wm["ans"] | taken):
            m.d.sync += r.b.eq(r.b + 1)
        with m.If(u["BSET"]):
            m.d.sync += r.b.eq(u["imm"])
        # the address and data follow the ROM's wm bits alone (a pulse's low byte comes as X =
        # F0): they matter only with the enable, so neither waits for fire; an answer byte's
        # bits above 8 are never read
        m.d.comb += [wr.en.eq(wm["ans"] | wm["width"] | wm["pulse"]),
                     wr.addr.eq(Mux(u["wm_ans"], self._region_addr(1, r.b), r.ch)),
                     wr.data.eq(Mux(u["wm_width"], widths, Cat(x, r.f[8:self._w])))]
        # the read port serves the answer being sent or else the staging of widths; a byte is
        # valid once the memory shows the one B names (not in the cycle after B moved on)
        idx = r.b
        shown, moved = Signal(), Signal()
        m.d.sync += [shown.eq(r.sending), moved.eq(taken)]
        # MTRD addresses the move time's word (MOVE_TIME_WORD of the answer region) for FMT
        stage = Mux(u["MTRD"], self._region_addr(1, Const(MOVE_TIME_WORD, 8)), r.ch)
        m.d.comb += [rd.addr.eq(Mux(r.sending, Mux(r.ident, self._region_addr(2, idx), self._region_addr(1, idx)),
                                    stage)),
                     self.answer_data.valid.eq(r.sending & shown & ~moved), self.answer_index.eq(r.b),
                     self.answer_data.payload.eq(rd.data[:8])]
        # the link's transmitter has taken the last payload byte (it knows the length)
        with m.If(self.answer_done):
            m.d.sync += r.sending.eq(0)
        # the move time into F for the staging (the target's time is F's low bits, and so is
        # a write's value: one source for both in the servo controller's memory write); F's
        # low 24 bits shift in from F itself, so the load takes no cell of its own there; 0
        # until set_move_time wrote the word (the memory keeps it over a reset)
        with m.If(u["FMT"]):
            m.d.sync += r.f[:self._time_bits].eq(rd.data[:self._time_bits] & r.mt.replicate(self._time_bits))

    def _ports(self, m, r, u, s, e, rd):
        imm = u["imm"]
        # a commit is applied by the pass of the next period start (staged in the window before it)
        with m.If(self.period_start & r.pending):
            m.d.sync += r.started.eq(1)
        with m.If(r.started & ~self.busy):
            m.d.sync += [r.pending.eq(0), r.started.eq(0)]
        with m.If(e["COMMIT"]):
            m.d.sync += [r.pending.eq(1), r.started.eq(0)]
        # registered: the request's acceptance depends on the field checks
        m.d.sync += [self.keepalive.eq(self.request.valid & self.request.ready), self.commit.eq(e["COMMIT"])]
        m.d.comb += [self.request.ready.eq(e["ACC"]), self.counter_addr.eq(imm[:4]), self.rd_addr.eq(r.ra),
                     self.answer.valid.eq(s["HDR"]), self.answer.payload.length.eq(imm),
                     self.answer.payload.command.eq(Mux(r.nack, P.NACK, r.cmd | P.ANSWER_BIT)),
                     self.ik_i.valid.eq(s["IKV"]), self.ik_i.payload.leg.eq(r.leg), self.ik_o.ready.eq(s["IKR"]),
                     self.write.valid.eq(s["WRV"]), self.write.payload.channel.eq(r.ch),
                     self.write.payload.field.eq(imm[:4]), self.write.payload.value.eq(r.f),
                     self.target.valid.eq(s["TGV"]), self.target.payload.channel.eq(r.ch),
                     self.target.payload.pulse.eq(rd.data), self.target.payload.time.eq(r.f[:self._time_bits]),
                     self.read.valid.eq(s["RDV"]), self.read.payload.channel.eq(r.ch),
                     self.read.payload.current.eq(u["bias"]), self.status.ready.eq(e["STR"])]
        m.d.comb += [self.ik_i.payload.target[inp.name].eq(r.tg[16 * k:16 * k + 16])
                     for k, inp in enumerate(self._plan.inputs)]
        # the header from the ROM, offered while its instruction waits (the link's transmitter
        # registers its length as it takes it, and reads its code, held here, when it sends
        # it); its payload is then pulled from memory. Sending until the payload's end (at once
        # after CMD for an empty one): the next request waits until then
        with m.If(e["HDR"]):
            m.d.sync += [r.sending.eq(1), r.b.eq(0)]
