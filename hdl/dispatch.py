"""The controller's command dispatcher: a request from the link in, its effect on the IK core
and the servo controller, its answer back to the link."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import wiring
from amaranth.lib.memory import Memory

from . import protocol as P
from .answers import answer_bytes, field_value, has_targets, head_bytes, pack_answer
from .bram import falling_edge_write_port
from .servo_fields import ChannelField, FailsafeAction

__all__ = ["Dispatcher"]

_C = {c.name: c for c in P.COMMANDS}
_REASON = {name: i + 1 for i, (name, _) in enumerate(P.NACK_REASONS)}
_STATUS_FIELDS = _C["status"].answer
_CHANNEL_FIELDS = _C["channel_status"].answer


def _field_word(fields, name: str) -> int:
    """Index of answer field ``name`` in its payload counted in link counter words (the status
    answer's counters are consecutive words of that size)."""
    bits = 0
    for f in fields:
        if f.name == name:
            assert bits % P.COUNTER_BITS == 0 and 8 * P.KINDS[f.kind][0] == P.COUNTER_BITS
            return bits // P.COUNTER_BITS
        bits += 8 * f.group_bytes(None)
    raise ValueError(f"no answer field {name!r}")


def _saturating_increment(m, counter, event):
    with m.If(event & (counter != (1 << len(counter)) - 1)):
        m.d.sync += counter.eq(counter + 1)


class _Regs:
    """The dispatcher's registers, shared by its groups of states."""

    def __init__(self, d):
        self.cmd = Signal(8)
        self.length = Signal(range(d._max_request + 1))
        self.ra = Signal(range(d._max_request + 2))         # payload byte being read
        self.args = Signal(8 * d._head)                     # the request's leading bytes
        self.tgt = Signal(16 * d._coords)                   # one leg's target, as sent
        self.legs = Signal(d._legs)                         # legs of a move still to do
        self.leg = Signal(range(d._legs + 1))
        self.j = Signal(range(d._servos))
        self.ch = Signal(range(d._channels + 1))
        self.pending = Signal(d._channels)                  # channels with a staged width
        self.mask = Signal(d._channels)                     # enable/relax channels
        self.level = Signal()                               # enable (1) or relax (0)
        self.moving, self.enabled = Signal(d._channels), Signal(d._channels)
        self.move_time = Signal(d._time_bits)
        self.w_ch = Signal(range(d._channels))
        self.w_field = Signal(4)
        self.w_value, self.w_then = Signal(signed(d._w + 1)), Signal(signed(d._w + 1))
        self.w_more = Signal()                              # set_limits: MAX follows MIN
        self.buf = Signal(8 * d._buf_bytes)                 # a computed answer's payload
        self.ans_code = Signal(8)
        self.ans_len = Signal(range(d._max_answer + 1))
        self.ans_ident = Signal()                           # the payload is the identity constant
        self.sending = Signal()                             # answer payload still being pulled
        self.uptime = Signal(32)
        self.since = Signal(range(d._period + 1))           # cycles since the last period start
        self.clamped = Signal(P.COUNTER_BITS)
        self.cnt = Signal(range(len(P.RECEIVER_COUNTERS) + 1))   # link counter being read


class Dispatcher(wiring.Component):
    """Executes the link's requests (``docs/protocol.md``) on an IK core and a servo controller.

    A request is read from the link's payload memory, checked, executed, then answered: an
    acknowledgement, an answer, or NACK ``bad_value`` for a field out of range for this robot
    (a channel, a leg, a leg or channel mask, a pulse, trim, speed, acceleration, home or
    failsafe timeout that does not fit ``width_bits``, limits with min > max, an unknown
    failsafe action). A NACKed request changes nothing. Every request taken pulses
    ``keepalive``.

    Moves: each leg of a ``move_leg``/``move_legs`` target goes through the IK core, one leg at
    a time; a coordinate is saturated to the plan input's ``[lo, hi]`` first (``status`` counts
    the leg targets that were outside in ``clamped``), so a port never sees a value it cannot
    carry. The widths are buffered (one word per channel), then all staged on the servo
    controller's ``target`` stream with the current move time and committed by one strobe,
    in a part of the PWM period where the engine's pass cannot start before the commit: the
    channels of one request always change together, at one period start. Leg ``l`` servo ``j``
    is channel ``l * servos + j``. ``set_pulse`` takes the same path for one channel, so a
    move time applies to it as well.

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
    request, rd_addr, rd_data, counter_addr, counter_data, answer, answer_data, answer_index
        To the link's ports of the same names.
    ik_i, ik_o
        To the core's ``i`` and ``o``.
    write, target, commit, read, status, keepalive, busy, period_start
        To the servo controller's ports of the same names.

    Latency
    -------
    Cycles from ``request.valid`` to the answer header: identity, set_move_time: ``H + 2``
    (``H`` payload bytes read, at most :func:`~ikseries.hdl.answers.head_bytes`); parameter
    writes and enable/relax: ``H + 3`` plus a cycle per channel scanned, plus any wait for the
    engine's pass (``pass_cycles`` at most); channel_status and status: ``H + 8`` cycles per
    channel read, for status after ``len(RECEIVER_COUNTERS) + 1`` cycles reading the link's
    counters (each as it was up to 10 cycles before); moves: per leg ``2 C + 3`` cycles, the core's latency and ``servos`` cycles,
    then a wait of at most ``stage_cycles + pass_cycles`` for the staging window (the end of
    a period, the pass) and ``stage_cycles`` to stage and commit (``stage_cycles = channels *
    (1 + target_cycles) + 2``, the servo controller's ``target_cycles``); :meth:`move_cycles`
    adds these up. The widths reach the pins at the second period start after the commit at
    the latest (the servo controller's latency). A request
    waits in the link while the previous answer's payload is still being sent.

    Throughput
    ----------
    One request at a time. A full ``move_legs`` takes at most ``move_cycles(legs)``, about
    ``legs * (2 C + latency + servos + 3) + pass_cycles + 2 * stage_cycles`` cycles, far below
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
        self._head = head_bytes(self._shape)
        self._identity = pack_answer(_C["identity"].answer, identity)
        self._identity_len = len(self._identity) // 8
        self._buf_bytes = max(answer_bytes(_STATUS_FIELDS), answer_bytes(_CHANNEL_FIELDS),
                              answer_bytes(P.NACK_FIELDS))
        self._max_answer = max(self._identity_len, self._buf_bytes)
        # the pass starts at a period start, and may start between two targets: the whole group
        # (a read cycle and a target transfer per channel) and its commit strobe must fit before
        # the next period start, counted from the cycle STAGE_WAIT decides
        self._stage_cycles = self._channels * (1 + servo.target_cycles) + 2
        self._pass_cycles, self._core_latency = servo.pass_cycles, core.latency
        ls, cs, ss = link.signature.members, core.signature.members, servo.signature.members
        super().__init__({
            **{n: ls[n].flip() for n in ("request", "rd_addr", "rd_data", "counter_addr",
                                         "counter_data", "answer", "answer_data", "answer_index")},
            "ik_i": cs["i"].flip(), "ik_o": cs["o"].flip(),
            **{n: ss[n].flip() for n in ("write", "target", "commit", "read", "status",
                                         "keepalive", "busy", "period_start")},
        })
        self._servo_names = core.servos

    @property
    def shape(self) -> P.Shape:
        return self._shape

    @property
    def stage_cycles(self) -> int:
        """Cycles from the decision to stage a group of widths to its commit strobe, inclusive
        of a margin cycle: staging starts only with this many cycles left before a period start."""
        return self._stage_cycles

    def move_cycles(self, legs: int) -> int:
        """Most cycles from ``request.valid`` of a move of ``legs`` legs to its commit strobe:
        fetch and decode, each leg through the core (unselected legs a cycle each), a wait for
        the staging window (it may just have closed: the rest of the period and a pass), and
        the staging itself. A ``set_pulse`` is a move of no legs."""
        per_leg = 2 * self._coords + 3 + self._core_latency + self._servos
        return 5 + (self._legs - legs) + legs * per_leg + self._pass_cycles + 2 * self._stage_cycles

    def elaborate(self, platform):
        m = Module()
        r = _Regs(self)
        m.submodules.widths = mem = Memory(shape=self._w, depth=self._channels, init=[])
        wr, rd = falling_edge_write_port(m, mem), mem.read_port()
        self._always(m, r)
        m.d.comb += rd.addr.eq(r.ch)
        with m.FSM():
            self._receive_states(m, r)
            with m.State("DECODE"):
                self._decode(m, r, wr)
            self._move_states(m, r, wr)
            self._stage_states(m, r, rd)
            self._write_states(m, r)
            self._read_states(m, r)
            self._answer_states(m, r)
        return m

    # -- always on: counters, the answer payload, keepalive
    def _always(self, m, r):
        m.d.sync += r.since.eq(Mux(self.period_start, 0, Mux(r.since == self._period, r.since, r.since + 1)))
        _saturating_increment(m, r.uptime, self.period_start)
        m.d.comb += self.keepalive.eq(self.request.valid & self.request.ready)
        idx = self.answer_index
        m.d.comb += [self.answer_data.valid.eq(r.sending),
                     self.answer_data.payload.eq(Mux(r.ans_ident, self._identity.word_select(idx, 8),
                                                     r.buf.word_select(idx, 8)))]
        with m.If(self.answer_data.valid & self.answer_data.ready & (idx == r.ans_len - 1)):
            m.d.sync += r.sending.eq(0)

    def _receive_states(self, m, r):
        with m.State("IDLE"):
            with m.If(self.request.valid & ~r.sending):
                m.d.sync += [r.cmd.eq(self.request.payload.command), r.length.eq(self.request.payload.length),
                             r.ra.eq(0)]
                m.next = "FETCH"
        with m.State("FETCH"):
            # the leading bytes into args (a move's targets are read leg by leg later)
            moves = Cat(*(r.cmd == c.code for c in P.COMMANDS if has_targets(c))).any()
            n = Mux(moves, 1, r.length)
            m.d.comb += self.rd_addr.eq(r.ra)
            with m.If(r.ra != 0):
                m.d.sync += r.args.word_select((r.ra - 1)[:len(r.ra)], 8).eq(self.rd_data)
            with m.If(r.ra == n):
                m.next = "DECODE"
            with m.Else():
                m.d.sync += r.ra.eq(r.ra + 1)

    # -- answers
    def _ack(self, m, r):
        m.d.sync += [r.ans_code.eq(P.ANSWER_BIT | r.cmd), r.ans_len.eq(0), r.ans_ident.eq(0)]
        m.next = "ANSWER"

    def _nack(self, m, r, reason: str):
        self._answer_buffer(m, r, P.NACK, P.NACK_FIELDS, {"request": r.cmd, "reason": _REASON[reason]})

    def _answer_buffer(self, m, r, code, fields, values):
        bits = pack_answer(fields, values)
        m.d.sync += [r.buf.eq(bits), r.ans_code.eq(code), r.ans_len.eq(len(bits) // 8), r.ans_ident.eq(0)]
        m.next = "ANSWER"

    def _answer_states(self, m, r):
        with m.State("ANSWER"):
            m.d.comb += [self.answer.valid.eq(1), self.answer.payload.command.eq(r.ans_code),
                         self.answer.payload.length.eq(r.ans_len)]
            with m.If(self.answer.ready):
                m.d.sync += r.sending.eq(r.ans_len != 0)
                m.next = "IDLE"

    # -- checking a request and starting its execution
    def _decode(self, m, r, wr):
        code = {name: c.code for name, c in _C.items()}
        arg = lambda name, field: field_value(r.args, _C[name], field)  # noqa: E731
        top = (1 << self._w) - 1
        m.d.comb += self.request.ready.eq(1)
        with m.Switch(r.cmd):
            with m.Case(code["identity"]):
                m.d.sync += [r.ans_code.eq(P.answer_code(_C["identity"])), r.ans_len.eq(self._identity_len),
                             r.ans_ident.eq(1)]
                m.next = "ANSWER"
            with m.Case(code["status"]):
                m.d.sync += [r.ch.eq(0), r.cnt.eq(0)]
                m.next = "STATUS_COUNT"
            with m.Case(code["channel_status"]):
                self._channel_checked(m, r, arg("channel_status", "channel"), "CHANNEL_READ")
            with m.Case(code["move_leg"]):
                leg = arg("move_leg", "leg")
                self._move_start(m, r, leg < self._legs, Const(1, self._legs) << leg[:max(1, (self._legs - 1).bit_length())])
            with m.Case(code["move_legs"]):
                mask = arg("move_legs", "legs")
                self._move_start(m, r, (mask != 0) & (mask >> self._legs == 0), mask[:self._legs])
            with m.Case(code["set_pulse"]):
                ch, pulse = arg("set_pulse", "channel"), arg("set_pulse", "pulse")
                with m.If((ch >= self._channels) | (pulse > top)):
                    self._nack(m, r, "bad_value")
                with m.Else():
                    m.d.comb += [wr.en.eq(1), wr.addr.eq(ch), wr.data.eq(pulse)]
                    m.d.sync += [r.pending.eq(0), r.pending.bit_select(ch[:len(r.w_ch)], 1).eq(1)]
                    m.next = "STAGE_WAIT"
            with m.Case(code["set_move_time"]):
                m.d.sync += r.move_time.eq(arg("set_move_time", "periods"))
                self._ack(m, r)
            self._decode_writes(m, r, arg, code, top)

    def _decode_writes(self, m, r, arg, code, top):
        """The requests that become servo parameter writes."""
        fields = {"set_trim": ("trim", ChannelField.TRIM), "set_speed": ("speed", ChannelField.SPEED),
                  "set_accel": ("accel", ChannelField.ACCEL), "set_home": ("pulse", ChannelField.HOME),
                  "set_failsafe_action": ("action", ChannelField.FAILSAFE)}
        highest = {"set_trim": top, "set_failsafe_action": max(FailsafeAction)}
        for name, (field, cf) in fields.items():
            with m.Case(code[name]):
                v = arg(name, field)
                bad = (v > highest.get(name, top)) | (v < -(1 << self._w) if name == "set_trim" else 0)
                self._write_checked(m, r, arg(name, "channel"), bad, cf, v)
        with m.Case(code["set_limits"]):
            lo, hi = arg("set_limits", "min"), arg("set_limits", "max")
            self._write_checked(m, r, arg("set_limits", "channel"), (hi > top) | (lo > hi), ChannelField.MIN, lo,
                                then=hi)
        with m.Case(code["set_failsafe"]):
            v = arg("set_failsafe", "periods")
            self._write_checked(m, r, Const(0, 8), v > top, ChannelField.TIMEOUT, v)
        for name, level in (("enable", 1), ("relax", 0)):
            with m.Case(code[name]):
                mask = arg(name, "channels")
                with m.If(mask >> self._channels != 0):
                    self._nack(m, r, "bad_value")
                with m.Else():
                    m.d.sync += [r.mask.eq(mask[:self._channels]), r.level.eq(level), r.ch.eq(0)]
                    m.next = "MASK"
        with m.Default():       # the receiver passes request codes only: kept for a defined state
            self._nack(m, r, "unsupported")

    def _channel_checked(self, m, r, ch, state):
        with m.If(ch >= self._channels):
            self._nack(m, r, "bad_value")
        with m.Else():
            m.d.sync += r.w_ch.eq(ch)
            m.next = state

    def _write_checked(self, m, r, ch, bad, field, value, then=None):
        with m.If((ch >= self._channels) | bad):
            self._nack(m, r, "bad_value")
        with m.Else():
            m.d.sync += [r.w_ch.eq(ch), r.w_field.eq(field), r.w_value.eq(value), r.w_more.eq(then is not None)]
            if then is not None:
                m.d.sync += r.w_then.eq(then)
            m.next = "WRITE"

    # -- moves: each leg of the mask through the core into the width buffer
    def _move_start(self, m, r, ok, legs):
        with m.If(ok):
            m.d.comb += self.request.ready.eq(0)     # its targets are still to be read
            m.d.sync += [r.legs.eq(legs), r.leg.eq(0), r.pending.eq(0), r.ra.eq(1)]
            m.next = "LEG_NEXT"
        with m.Else():
            self._nack(m, r, "bad_value")

    def _clamped_target(self, tgt):
        """The target register saturated to the plan's input ranges, and whether it was outside."""
        values, outside = {}, []
        for k, inp in enumerate(self._plan.inputs):
            v = tgt[16 * k:16 * (k + 1)].as_signed()
            values[inp.name] = Mux(v < inp.lo, inp.lo, Mux(v > inp.hi, inp.hi, v))
            outside.append((v < inp.lo) | (v > inp.hi))
        return values, Cat(*outside).any()

    def _move_states(self, m, r, wr):
        nbytes = 2 * self._coords
        with m.State("LEG_NEXT"):
            with m.If(r.leg == self._legs):
                m.d.comb += self.request.ready.eq(1)
                m.next = "STAGE_WAIT"
            with m.Elif(r.legs.bit_select(r.leg, 1)):
                m.d.sync += r.j.eq(0), r.ch.eq(0)
                m.next = "LEG_FETCH"
            with m.Else():
                m.d.sync += r.leg.eq(r.leg + 1)
        with m.State("LEG_FETCH"):
            # r.ch counts the target's bytes; the payload memory answers a cycle later
            m.d.comb += self.rd_addr.eq(r.ra)
            with m.If(r.ch != 0):
                m.d.sync += r.tgt.word_select((r.ch - 1)[:len(r.ch)], 8).eq(self.rd_data)
            with m.If(r.ch == nbytes):
                m.next = "LEG_OFFER"
            with m.Else():
                m.d.sync += [r.ch.eq(r.ch + 1), r.ra.eq(r.ra + 1)]
        with m.State("LEG_OFFER"):
            values, outside = self._clamped_target(r.tgt)
            m.d.comb += [self.ik_i.valid.eq(1), self.ik_i.payload.leg.eq(r.leg)]
            m.d.comb += [self.ik_i.payload.target[n].eq(v) for n, v in values.items()]
            _saturating_increment(m, r.clamped, self.ik_i.ready & outside)
            with m.If(self.ik_i.ready):
                m.next = "LEG_STORE"
        with m.State("LEG_STORE"):
            channel = r.leg * self._servos + r.j
            with m.Switch(r.j):
                for j, name in enumerate(self._servo_names):
                    with m.Case(j):
                        m.d.comb += wr.data.eq(self.ik_o.payload.widths[name])
            m.d.comb += [wr.addr.eq(channel), wr.en.eq(self.ik_o.valid)]
            with m.If(self.ik_o.valid):
                m.d.sync += [r.pending.bit_select(channel, 1).eq(1), r.j.eq(r.j + 1)]
                with m.If(r.j == self._servos - 1):
                    m.d.comb += self.ik_o.ready.eq(1)
                    m.d.sync += r.leg.eq(r.leg + 1)
                    m.next = "LEG_NEXT"

    # -- staging the buffered widths, all in one window between passes
    def _stage_states(self, m, r, rd):
        with m.State("STAGE_WAIT"):
            with m.If(~self.busy & (r.since < self._period - self._stage_cycles)):
                m.d.sync += r.ch.eq(0)
                m.next = "STAGE_READ"
        with m.State("STAGE_READ"):
            m.next = "STAGE_SEND"
        with m.State("STAGE_SEND"):
            pend = r.pending.bit_select(r.ch, 1)
            m.d.comb += [self.target.valid.eq(pend), self.target.payload.channel.eq(r.ch),
                         self.target.payload.pulse.eq(rd.data), self.target.payload.time.eq(r.move_time)]
            with m.If(~pend | self.target.ready):
                m.d.sync += r.ch.eq(r.ch + 1)
                m.next = "STAGE_READ"
                with m.If(r.ch == self._channels - 1):
                    m.next = "COMMIT"
        with m.State("COMMIT"):
            m.d.comb += self.commit.eq(1)
            self._ack(m, r)

    # -- parameter writes
    def _write_states(self, m, r):
        with m.State("WRITE"):
            m.d.comb += [self.write.valid.eq(1), self.write.payload.channel.eq(r.w_ch),
                         self.write.payload.field.eq(r.w_field), self.write.payload.value.eq(r.w_value)]
            with m.If(self.write.ready):
                with m.If(r.w_more):
                    m.d.sync += [r.w_more.eq(0), r.w_field.eq(ChannelField.MAX), r.w_value.eq(r.w_then)]
                with m.Else():
                    self._ack(m, r)
        with m.State("MASK"):
            with m.If(r.ch == self._channels):
                self._ack(m, r)
            with m.Elif(r.mask.bit_select(r.ch, 1)):
                m.d.comb += [self.write.valid.eq(1), self.write.payload.channel.eq(r.ch),
                             self.write.payload.field.eq(ChannelField.ENABLE), self.write.payload.value.eq(r.level)]
                with m.If(self.write.ready):
                    m.d.sync += r.ch.eq(r.ch + 1)
            with m.Else():
                m.d.sync += r.ch.eq(r.ch + 1)

    # -- status reads
    def _read_states(self, m, r):
        st = self.status.payload
        with m.State("CHANNEL_READ"):
            m.d.comb += [self.read.valid.eq(1), self.read.payload.eq(r.w_ch)]
            with m.If(self.read.ready):
                m.next = "CHANNEL_WAIT"
        with m.State("CHANNEL_WAIT"):
            m.d.comb += self.status.ready.eq(1)
            with m.If(self.status.valid):
                self._answer_buffer(m, r, P.answer_code(_C["channel_status"]), _CHANNEL_FIELDS, {
                    "channel": r.w_ch, "commanded": st.target, "current": st.current,
                    "moving": st.moving, "enabled": st.enabled})
        # the link's counters, read one a cycle (a block RAM), go straight to their place in the
        # answer buffer: no second copy of them in registers
        first = _field_word(_STATUS_FIELDS, P.RECEIVER_COUNTERS[0])
        counted = {name: r.buf.word_select(first + i, P.COUNTER_BITS) for i, name in enumerate(P.RECEIVER_COUNTERS)}
        with m.State("STATUS_COUNT"):
            m.d.comb += self.counter_addr.eq(r.cnt)
            with m.If(r.cnt != 0):
                m.d.sync += r.buf.word_select((first - 1) + r.cnt, P.COUNTER_BITS).eq(self.counter_data)
            with m.If(r.cnt == len(P.RECEIVER_COUNTERS)):
                m.next = "STATUS_READ"
            with m.Else():
                m.d.sync += r.cnt.eq(r.cnt + 1)
        with m.State("STATUS_READ"):
            with m.If(r.ch == self._channels):
                self._answer_buffer(m, r, P.answer_code(_C["status"]), _STATUS_FIELDS, {
                    "uptime": r.uptime, **counted, "clamped": r.clamped,
                    "moving": r.moving, "enabled": r.enabled})
            with m.Else():
                m.d.comb += [self.read.valid.eq(1), self.read.payload.eq(r.ch)]
                with m.If(self.read.ready):
                    m.next = "STATUS_WAIT"
        with m.State("STATUS_WAIT"):
            m.d.comb += self.status.ready.eq(1)
            with m.If(self.status.valid):
                m.d.sync += [r.moving.bit_select(r.ch, 1).eq(st.moving), r.enabled.bit_select(r.ch, 1).eq(st.enabled),
                             r.ch.eq(r.ch + 1)]
                m.next = "STATUS_READ"
