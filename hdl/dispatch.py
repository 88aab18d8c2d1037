"""The controller's command dispatcher: a request from the link in, its effect on the IK core
and the servo controller, its answer back to the link."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.memory import Memory

from . import protocol as P
from .answers import answer_byte_map, answer_bytes, answer_constant, has_targets, scalar_offsets
from .bram import falling_edge_write_port
from .servo_fields import ChannelField, FailsafeAction

__all__ = ["Dispatcher"]

_C = {c.name: c for c in P.COMMANDS}
_INDEX = {c.name: i for i, c in enumerate(P.COMMANDS)}
_REASON = {name: i + 1 for i, (name, _) in enumerate(P.NACK_REASONS)}
#: the request field a parameter write carries as its value, and its servo field
_WRITES = {"set_trim": ("trim", ChannelField.TRIM), "set_limits": ("max", ChannelField.MIN),
           "set_speed": ("speed", ChannelField.SPEED), "set_accel": ("accel", ChannelField.ACCEL),
           "set_home": ("pulse", ChannelField.HOME), "set_failsafe": ("periods", ChannelField.TIMEOUT),
           "set_failsafe_action": ("action", ChannelField.FAILSAFE)}
#: request fields that are pulse widths or periods of the servo controller (``width_bits`` wide)
_WIDE = {"set_pulse": ("pulse",), "set_trim": ("trim",), "set_limits": ("min", "max"), "set_speed": ("speed",),
         "set_accel": ("accel",), "set_home": ("pulse",), "set_failsafe": ("periods",)}
#: answers the dispatcher builds in its scratch memory, in the order of their kind code
_BUILT = (_C["status"].answer, _C["channel_status"].answer, P.NACK_FIELDS)
_STATUS, _CHANNEL, _NACK = range(len(_BUILT))
#: cycles to read one request field: the payload memory's latency, then a byte a cycle into
#: the 32-bit field register (every field is at most a u32)
_LOAD_CYCLES = 5
#: cycles per coordinate: its load, then the two bound comparisons and the saturated store
_COORD_CYCLES = _LOAD_CYCLES + 3


class _Regs:
    """The dispatcher's registers, shared by its groups of states."""

    def __init__(self, d):
        self.cmd = Signal(8)
        self.ci = Signal(range(len(P.COMMANDS) + 1))      # the command's index (len: none)
        self.ra = Signal(range(d._max_request + 1))         # next payload byte to read
        self.bcnt = Signal(range(_LOAD_CYCLES))             # cycle of the field load
        self.step = Signal(range(4))                        # fields of the request loaded
        self.val = Signal(32)                               # the field, extended to 32 bits
        self.lim = Signal(signed(d._w + 1))                 # value of a parameter write
        self.w_ch = Signal(range(d._channels))
        self.w_more = Signal()                              # set_limits: MAX follows MIN
        self.legs = Signal(d._legs)                         # legs of a move
        self.leg = Signal(range(d._legs + 1))
        self.j = Signal(range(d._servos))
        self.k = Signal(range(d._coords))
        self.ch = Signal(range(d._channels + 1))
        self.tgt = [Signal(signed(16)) for _ in range(d._coords)]   # one leg's target, saturated
        self.below, self.above, self.outside = Signal(), Signal(), Signal()
        self.legs_phase = Signal()                          # the fields being read are coordinates
        self.move_time = Signal(d._time_bits)
        self.kind = Signal(range(len(_BUILT)))              # the answer being built
        self.b = Signal(range(d._region))                   # its byte
        self.settle = Signal()                              # a counter read is under way
        self.unsupported = Signal()                         # NACK reason
        self.nack, self.ident = Signal(), Signal()
        self.ans_len = Signal(range(d._region + 1))
        self.sending = Signal()                             # answer payload still being pulled
        self.rd_idx = Signal(range(d._region))              # answer byte the memory now shows
        self.moving, self.enabled = Signal(d._channels), Signal(d._channels)
        self.uptime = Signal(32)
        self.since = Signal(range(d._period + 1))           # cycles since the last period start
        self.clamped = Signal(P.COUNTER_BITS)
        # the states' side of the ``write`` and ``target`` register slices
        self.write = stream.Signature(d.write.payload.shape()).create(path=("w_in",))
        self.target = stream.Signature(d.target.payload.shape()).create(path=("t_in",))


def _register_slice(m, inner, outer):
    """A stream register from ``inner`` (the states offer) to ``outer`` (the port): payload
    and valid registered, so no path runs combinationally from the states into the servo
    controller; a transfer a cycle (``inner.ready`` while the register is empty or being taken)."""
    take = ~outer.valid | outer.ready
    m.d.comb += inner.ready.eq(take)
    with m.If(take):
        m.d.sync += [outer.valid.eq(inner.valid), outer.payload.eq(inner.payload)]


def _saturating_increment(m, counter, event):
    # the increment's carry out says the counter is full: no separate all-ones detector
    nxt = Signal(len(counter) + 1)
    m.d.comb += nxt.eq(counter + 1)
    with m.If(event & ~nxt[-1]):
        m.d.sync += counter.eq(nxt[:-1])


class Dispatcher(wiring.Component):
    """Executes the link's requests (``docs/protocol.md``) on an IK core and a servo controller.

    A request is read from the link's payload memory a field at a time (each into one 32-bit
    register, zero- or sign-extended), checked, executed, then answered: an acknowledgement,
    an answer, or NACK ``bad_value`` for a field out of range for this robot (a channel, a
    leg, a leg or channel mask, a pulse, trim, speed, acceleration, home or failsafe timeout
    that does not fit ``width_bits``, limits with min > max, an unknown failsafe action). A
    NACKed request changes nothing. Every request taken pulses ``keepalive`` (the cycle
    after). ``write``, ``target`` (a register slice on each stream), ``commit`` and
    ``keepalive`` are registered, so no path runs combinationally from the dispatcher's states
    into the servo controller; an answer header waits until the servo controller has taken
    the writes, targets and commit. Requests arrive
    at the line rate, thousands of cycles apart, so everything is byte-serial: one field
    register, checked by the rule a table picks for the command and field, a comparator per
    target bound (against its constant), answers built a byte a cycle in block RAM.

    Moves: each leg of a ``move_leg``/``move_legs`` target goes through the IK core, one leg at
    a time; a coordinate is saturated to the plan input's ``[lo, hi]`` first (``status`` counts
    the leg targets that were outside in ``clamped``), so a port never sees a value it cannot
    carry. The widths are buffered (one word per channel), then all staged on the servo
    controller's ``target`` stream with the current move time and committed by one strobe,
    in a part of the PWM period where the engine's pass cannot start before the commit: the
    channels of one request always change together, at one period start. Leg ``l`` servo ``j``
    is channel ``l * servos + j``. ``set_pulse`` takes the same path for one channel, so a
    move time applies to it as well.

    One block RAM holds the width buffer, the answer being built (status, channel_status,
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
    request, rd_addr, rd_data, counter_addr, counter_data, answer, answer_data, answer_index
        To the link's ports of the same names.
    ik_i, ik_o
        To the core's ``i`` and ``o``.
    write, target, commit, read, status, keepalive, busy, period_start
        To the servo controller's ports of the same names.

    Reset state: idle, no answer pending, move time 0, counters (``uptime``, ``clamped``) 0.

    Latency
    -------
    Cycles from ``request.valid`` to the answer header, with ``F`` the request's scalar fields
    read (``_LOAD_CYCLES + 1`` = 6 cycles each): identity 2, set_move_time ``2 + 6 F``;
    parameter writes ``4 + 6 F`` (set_limits one more), enable/relax ``3 + 6 F`` plus a cycle
    per channel, each plus any wait for the engine's pass (``pass_cycles`` at most);
    channel_status ``2 + 6 F`` and the servo controller's read, then 2 cycles per answer byte;
    status: for each channel a read of the servo controller, then 2 cycles per answer byte
    (the link's counters read as they are then); a NACK ``2 + 6 F + 4``. Moves:
    :meth:`move_cycles` to the commit strobe (per selected leg ``C`` coordinates of
    ``_COORD_CYCLES`` = 8 cycles, the core's latency and ``servos`` cycles; a wait of at most
    ``stage_cycles + pass_cycles`` for the staging window and ``stage_cycles`` to stage and
    commit, ``stage_cycles = channels * (1 + target_cycles) + 3``), the header 1 cycle later.
    The widths reach the pins at the second period start after the commit at the latest (the
    servo controller's latency). An answer byte is on ``answer_data`` the cycle after
    ``answer_index`` names it. A request waits in the link while the previous answer's payload
    is still being sent.

    Throughput
    ----------
    One request at a time. A full ``move_legs`` takes at most ``move_cycles(legs)``, about
    ``legs * (8 C + latency + servos + 2) + pass_cycles + 2 * stage_cycles`` cycles, far below
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
        self._identity = answer_constant(_C["identity"].answer, identity)
        # three regions of one size in the memory: widths, the answer being built, identity;
        # an address is the region above the offset, so no adder
        biggest = max([self._channels, len(self._identity)] + [answer_bytes(f) for f in _BUILT])
        self._region = 1 << (biggest - 1).bit_length()
        # the pass starts at a period start, and may start between two targets: the whole group
        # (a read cycle and a target transfer per channel) and its commit strobe must fit before
        # the next period start, counted from the cycle STAGE_WAIT decides; the last cycle is
        # the commit register's (the port strobes the cycle after the COMMIT state)
        self._stage_cycles = self._channels * (1 + servo.target_cycles) + 3
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
        the command and the leg field, each leg through the core (unselected legs a cycle
        each), a wait for the staging window (it may just have closed: the rest of the period
        and a pass), and the staging itself. A ``set_pulse`` is a move of no legs."""
        fetch = 2 + 2 * (_LOAD_CYCLES + 1)          # set_pulse's two fields, more than a leg mask
        per_leg = 2 + self._coords * _COORD_CYCLES + self._core_latency + self._servos
        return fetch + (self._legs - legs) + legs * per_leg + self._pass_cycles + 2 * self._stage_cycles

    def elaborate(self, platform):
        m = Module()
        r = _Regs(self)
        m.submodules.mem = mem = Memory(shape=self._w, depth=3 * self._region,
                                        init=[0] * (2 * self._region) + list(self._identity))
        wr, rd = falling_edge_write_port(m, mem), mem.read_port()
        self._always(m, r, rd)
        for inner, outer in ((r.write, self.write), (r.target, self.target)):
            _register_slice(m, inner, outer)
        m.d.sync += self.commit.eq(0)
        with m.FSM():
            self._receive_states(m, r)
            with m.State("CHECK"):
                self._check(m, r, wr)
            self._move_states(m, r, wr)
            self._stage_states(m, r)
            self._write_states(m, r)
            self._read_states(m, r)
            with m.State("BUILD"):
                self._build(m, r, wr)
            with m.State("ANSWER"):
                # only once the servo controller has taken every write, target and commit
                done = ~self.write.valid & ~self.target.valid & ~self.commit
                m.d.comb += [self.answer.valid.eq(done), self.answer.payload.length.eq(r.ans_len),
                             self.answer.payload.command.eq(Mux(r.nack, P.NACK, r.cmd | P.ANSWER_BIT))]
                with m.If(done & self.answer.ready):
                    m.d.sync += r.sending.eq(r.ans_len != 0)
                    m.next = "IDLE"
        m.d.comb += r.target.payload.pulse.eq(rd.data)
        return m

    def _region_addr(self, region: int, offset):
        return Cat(offset[:(self._region - 1).bit_length()], Const(region, 2))

    # -- always on: counters, the answer payload, keepalive
    def _always(self, m, r, rd):
        m.d.sync += r.since.eq(Mux(self.period_start, 0, Mux(r.since == self._period, r.since, r.since + 1)))
        _saturating_increment(m, r.uptime, self.period_start)
        # registered too: the request's acceptance depends on the field checks
        m.d.sync += self.keepalive.eq(self.request.valid & self.request.ready)
        idx = self.answer_index
        # the read port serves the answer being sent or else the staging of widths; a byte is
        # valid once the memory shows the one the link names (the index just moved: not yet)
        shown = Signal()
        m.d.sync += [r.rd_idx.eq(idx), shown.eq(r.sending)]
        m.d.comb += [rd.addr.eq(Mux(r.sending, Mux(r.ident, self._region_addr(2, idx), self._region_addr(1, idx)),
                                    r.ch)),
                     self.answer_data.valid.eq(r.sending & shown & (r.rd_idx == idx)),
                     self.answer_data.payload.eq(rd.data[:8])]
        with m.If(self.answer_data.valid & self.answer_data.ready & (idx == r.ans_len - 1)):
            m.d.sync += r.sending.eq(0)

    def _receive_states(self, m, r):
        with m.State("IDLE"):
            with m.If(self.request.valid & ~r.sending):
                with m.Switch(self.request.payload.command):
                    for i, c in enumerate(P.COMMANDS):
                        with m.Case(c.code):
                            m.d.sync += r.ci.eq(i)
                    with m.Default():
                        m.d.sync += r.ci.eq(len(P.COMMANDS))
                m.d.sync += [r.cmd.eq(self.request.payload.command), r.ra.eq(0), r.w_ch.eq(0), r.nack.eq(0),
                             r.ident.eq(0), r.unsupported.eq(0), r.bcnt.eq(0), r.legs_phase.eq(0)]
                m.next = "DECODE"
        with m.State("DECODE"):
            with m.Switch(r.ci):
                with m.Case(_INDEX["identity"]):
                    m.d.comb += self.request.ready.eq(1)
                    m.d.sync += [r.ident.eq(1), r.ans_len.eq(len(self._identity))]
                    m.next = "ANSWER"
                with m.Case(_INDEX["status"]):
                    m.d.comb += self.request.ready.eq(1)
                    m.d.sync += r.ch.eq(0)
                    m.next = "STATUS_READ"
                with m.Case(*[i for i, c in enumerate(P.COMMANDS) if scalar_offsets(c)]):
                    m.d.sync += r.step.eq(0)
                    m.next = "LOAD"
                with m.Default():   # the receiver passes request codes only: kept for a defined state
                    m.d.sync += r.unsupported.eq(1)
                    self._nack(m, r)
        with m.State("LOAD"):
            # a byte a cycle, the payload memory a cycle behind the address; the bytes past the
            # field's end are its extension, so every check sees one 32-bit integer
            nb, sgn = self._field_kind(m, r)
            m.d.comb += self.rd_addr.eq(r.ra)
            with m.If(r.bcnt < nb):
                m.d.sync += r.ra.eq(r.ra + 1)
            fill = Mux(sgn & r.val[-1], 0xFF, 0)
            with m.If(r.bcnt != 0):
                m.d.sync += r.val.eq(Cat(r.val[8:], Mux(r.bcnt <= nb, self.rd_data, fill)))
            m.d.sync += r.bcnt.eq(r.bcnt + 1)
            with m.If(r.bcnt == _LOAD_CYCLES - 1):
                m.d.sync += r.bcnt.eq(0)
                with m.If(r.legs_phase):
                    m.next = "CLAMP_LO"
                with m.Else():
                    m.next = "CHECK"

    def _nack(self, m, r):
        """Refuse the request (still offered by the link): build the NACK answer."""
        m.d.comb += self.request.ready.eq(1)
        m.d.sync += r.nack.eq(1)
        self._start_build(m, r, _NACK)

    def _start_build(self, m, r, kind: int):
        m.d.sync += [r.kind.eq(kind), r.b.eq(0), r.settle.eq(0)]
        m.next = "BUILD"

    def _ack(self, m, r):
        m.d.sync += r.ans_len.eq(0)
        m.next = "ANSWER"

    # -- checking each field as it is read, then executing the request
    def _field_kind(self, m, r):
        """Bytes and signedness of the field being loaded: a coordinate's, or the scalar
        field ``step`` of the command's (a table on the command index and ``step``)."""
        coord = next(f for f in _C["move_legs"].request if f.count == "coords")
        nb, sgn = Signal(range(5)), Signal()
        with m.Switch(Cat(r.step, r.ci)):
            for ci, c in enumerate(P.COMMANDS):
                for i, (_, nbytes, signed_) in enumerate(scalar_offsets(c).values()):
                    with m.Case(ci << len(r.step) | i):
                        m.d.comb += [nb.eq(nbytes), sgn.eq(signed_)]
        with m.If(r.legs_phase):
            m.d.comb += [nb.eq(P.KINDS[coord.kind][0]), sgn.eq(P.KINDS[coord.kind][1])]
        return nb, sgn

    def _checks(self, m, r):
        """Each range check, once, on the field register (a field's kind and rule pick one)."""
        v, top = r.val, self._w
        return {"none": Const(1), "channel": v < self._channels, "leg": v < self._legs,
                "leg_mask": (v != 0) & (v >> self._legs == 0), "channel_mask": v >> self._channels == 0,
                "failsafe_action": v <= max(FailsafeAction),
                # a signed width is in [-2**top, 2**top): its bits from top up are its sign
                "signed_width": (v[top:] == 0) | (v[top:] == (1 << (32 - top)) - 1),
                "width": v >> top == 0, "max": (v >> top == 0) & (r.lim.as_unsigned() <= v[:top + 1])}

    @staticmethod
    def _rule(cmd, name: str) -> str:
        """The check of request field ``name`` of ``cmd``: a key of :meth:`_checks`."""
        field = next(f for f in cmd.request if f.name == name)
        if field.values is not None:
            return field.values
        if name not in _WIDE.get(cmd.name, ()):
            return "none"
        if cmd.name == "set_limits" and name == "max":
            return "max"
        return "signed_width" if P.KINDS[field.kind][1] else "width"

    def _check(self, m, r, wr):
        # one multiplexer picks the field's check; every failure takes the one NACK path
        checks = self._checks(m, r)
        ok, last = Signal(), Signal()
        with m.Switch(Cat(r.step, r.ci)):
            for ci, c in enumerate(P.COMMANDS):
                names = list(scalar_offsets(c))
                for i, name in enumerate(names):
                    with m.Case(ci << len(r.step) | i):
                        m.d.comb += [ok.eq(checks[self._rule(c, name)]), last.eq(i + 1 == len(names))]
        with m.If(~ok):
            self._nack(m, r)
        with m.Elif(~last):
            m.d.sync += r.step.eq(r.step + 1)
            m.next = "LOAD"
        with m.Switch(Cat(r.step, r.ci)):
            for ci, c in enumerate(P.COMMANDS):
                names = list(scalar_offsets(c))
                for i, name in enumerate(names):
                    with m.Case(ci << len(r.step) | i):
                        with m.If(ok):
                            self._keep(m, r, c, name)
                            if i + 1 == len(names):
                                self._execute(m, r, c, wr)

    def _keep(self, m, r, cmd, name: str):
        """A checked field that later states read from its own register."""
        if name == "channel":
            m.d.sync += r.w_ch.eq(r.val[:len(r.w_ch)])
        elif cmd.name == "set_limits" and name == "min":
            m.d.sync += r.lim.eq(r.val[:len(r.lim)])

    def _execute(self, m, r, cmd, wr):
        name = cmd.name
        if has_targets(cmd):        # its targets are still to be read: the request stays offered
            legs = Const(1, self._legs) << r.val[:max(1, (self._legs - 1).bit_length())] if name == "move_leg" \
                else r.val[:self._legs]
            m.d.sync += [r.legs.eq(legs), r.leg.eq(0), r.ch.eq(0)]
            m.next = "LEG_NEXT"
            return
        m.d.comb += self.request.ready.eq(1)
        if name == "channel_status":
            m.next = "CHANNEL_READ"
        elif name == "set_pulse":
            m.d.comb += [wr.en.eq(1), wr.addr.eq(r.w_ch), wr.data.eq(r.val)]
            m.next = "STAGE_WAIT"
        elif name == "set_move_time":
            m.d.sync += r.move_time.eq(r.val)
            self._ack(m, r)
        elif name in ("enable", "relax"):
            m.d.sync += [r.lim.eq(name == "enable"), r.ch.eq(0)]
            m.next = "MASK"
        else:
            assert name in _WRITES, name
            if name == "set_limits":
                m.d.sync += r.w_more.eq(1)      # lim holds MIN, val MAX
            else:
                m.d.sync += [r.lim.eq(r.val[:len(r.lim)]), r.w_more.eq(0)]
            m.next = "WRITE"

    # -- moves: each coordinate saturated, each leg of the mask through the core into the buffer
    def _bound(self, m, r, high):
        """The plan input bound of coordinate ``k``: its ``hi`` if ``high`` else its ``lo``."""
        bnd = Signal(signed(17))
        with m.Switch(r.k):
            for k, inp in enumerate(self._plan.inputs):
                with m.Case(k):
                    m.d.comb += bnd.eq(Mux(high, inp.hi, inp.lo))
        return bnd

    def _outside(self, m, r, v, high: bool):
        """Whether ``v`` is above coordinate ``k``'s ``hi`` if ``high``, else below its ``lo``."""
        out = Signal()
        with m.Switch(r.k):
            for k, inp in enumerate(self._plan.inputs):
                with m.Case(k):
                    m.d.comb += out.eq(v > inp.hi if high else v < inp.lo)
        return out

    def _move_states(self, m, r, wr):
        with m.State("LEG_NEXT"):
            with m.If(r.leg == self._legs):
                m.d.comb += self.request.ready.eq(1)
                m.next = "STAGE_WAIT"
            with m.Elif(r.legs.bit_select(r.leg, 1)):
                m.d.sync += [r.k.eq(0), r.j.eq(0), r.outside.eq(0), r.legs_phase.eq(1)]
                m.next = "LOAD"
            with m.Else():
                m.d.sync += [r.leg.eq(r.leg + 1), r.ch.eq(r.ch + self._servos)]
        # a comparator per bound of each coordinate, against its constant: a carry chain and
        # no look-up table on iCE40 (a subtractor against a selected bound needs both)
        v = r.val[:17].as_signed()
        with m.State("CLAMP_LO"):
            m.d.sync += r.below.eq(self._outside(m, r, v, high=False))
            m.next = "CLAMP_HI"
        with m.State("CLAMP_HI"):
            m.d.sync += r.above.eq(self._outside(m, r, v, high=True))
            m.next = "CLAMP_SET"
        with m.State("CLAMP_SET"):
            bnd = self._bound(m, r, r.above)
            saturated = Mux(r.below | r.above, bnd, v)
            for k, t in enumerate(r.tgt):
                with m.If(r.k == k):
                    m.d.sync += t.eq(saturated)
            m.d.sync += [r.outside.eq(r.outside | r.below | r.above), r.k.eq(r.k + 1)]
            m.next = "LOAD"
            with m.If(r.k == self._coords - 1):
                m.next = "LEG_OFFER"
        with m.State("LEG_OFFER"):
            m.d.comb += [self.ik_i.valid.eq(1), self.ik_i.payload.leg.eq(r.leg)]
            m.d.comb += [self.ik_i.payload.target[inp.name].eq(t) for inp, t in zip(self._plan.inputs, r.tgt)]
            _saturating_increment(m, r.clamped, self.ik_i.ready & r.outside)
            with m.If(self.ik_i.ready):
                m.d.sync += r.legs_phase.eq(0)
                m.next = "LEG_STORE"
        with m.State("LEG_STORE"):
            with m.Switch(r.j):
                for j, name in enumerate(self._servo_names):
                    with m.Case(j):
                        m.d.comb += wr.data.eq(self.ik_o.payload.widths[name])
            m.d.comb += [wr.addr.eq(r.ch), wr.en.eq(self.ik_o.valid)]
            with m.If(self.ik_o.valid):
                m.d.sync += [r.ch.eq(r.ch + 1), r.j.eq(r.j + 1)]
                with m.If(r.j == self._servos - 1):
                    m.d.comb += self.ik_o.ready.eq(1)
                    m.d.sync += r.leg.eq(r.leg + 1)
                    m.next = "LEG_NEXT"

    # -- staging the buffered widths, all in one window between passes
    def _stage_states(self, m, r):
        with m.State("STAGE_WAIT"):
            with m.If(~self.busy & (r.since < self._period - self._stage_cycles)):
                m.d.sync += [r.ch.eq(0), r.j.eq(0), r.leg.eq(0)]
                m.next = "STAGE_READ"
        with m.State("STAGE_READ"):
            m.next = "STAGE_SEND"
        with m.State("STAGE_SEND"):
            # a move stages the channels of its legs, set_pulse its one channel
            pend = Mux(r.ci == _INDEX["set_pulse"], r.ch == r.w_ch, r.legs.bit_select(r.leg, 1))
            m.d.comb += [r.target.valid.eq(pend), r.target.payload.channel.eq(r.ch),
                         r.target.payload.time.eq(r.move_time)]
            with m.If(~pend | r.target.ready):
                m.d.sync += [r.ch.eq(r.ch + 1), r.j.eq(r.j + 1)]
                with m.If(r.j == self._servos - 1):
                    m.d.sync += [r.j.eq(0), r.leg.eq(r.leg + 1)]
                m.next = "STAGE_READ"
                with m.If(r.ch == self._channels - 1):
                    m.next = "COMMIT"
        with m.State("COMMIT"):
            m.d.sync += self.commit.eq(1)       # registered: on the port the next cycle
            self._ack(m, r)

    # -- parameter writes
    def _write_states(self, m, r):
        with m.State("WRITE"):
            field = Signal(4)
            with m.Switch(r.ci):
                for name, (_, cf) in _WRITES.items():
                    with m.Case(_INDEX[name]):
                        m.d.comb += field.eq(Mux(r.w_more, cf, ChannelField.MAX) if name == "set_limits" else cf)
            m.d.comb += [r.write.valid.eq(1), r.write.payload.channel.eq(r.w_ch),
                         r.write.payload.field.eq(field), r.write.payload.value.eq(r.lim)]
            with m.If(r.write.ready):
                with m.If(r.w_more):
                    m.d.sync += [r.w_more.eq(0), r.lim.eq(r.val[:len(r.lim)])]
                with m.Else():
                    self._ack(m, r)
        with m.State("MASK"):
            with m.If(r.ch == self._channels):
                self._ack(m, r)
            with m.Elif(r.val.bit_select(r.ch, 1)):
                m.d.comb += [r.write.valid.eq(1), r.write.payload.channel.eq(r.ch),
                             r.write.payload.field.eq(ChannelField.ENABLE), r.write.payload.value.eq(r.lim)]
                with m.If(r.write.ready):
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
            # the status stays offered while its answer is built from it
            with m.If(self.status.valid):
                self._start_build(m, r, _CHANNEL)
        with m.State("STATUS_READ"):
            with m.If(r.ch == self._channels):
                self._start_build(m, r, _STATUS)
            with m.Else():
                m.d.comb += [self.read.valid.eq(1), self.read.payload.eq(r.ch)]
                with m.If(self.read.ready):
                    m.next = "STATUS_WAIT"
        with m.State("STATUS_WAIT"):
            # shifted in from the top: after the last channel, channel c is bit c
            m.d.comb += self.status.ready.eq(1)
            with m.If(self.status.valid):
                m.d.sync += [r.moving.eq(Cat(r.moving[1:], st.moving)), r.enabled.eq(Cat(r.enabled[1:], st.enabled)),
                             r.ch.eq(r.ch + 1)]
                m.next = "STATUS_READ"

    # -- answers built a byte at a time in the memory's answer region
    def _sources(self, r):
        """Per answer kind, the signal each answer field's bytes come from."""
        st = self.status.payload
        reason = Mux(r.unsupported, _REASON["unsupported"], _REASON["bad_value"])
        return {_STATUS: {"uptime": r.uptime, **{n: self.counter_data for n in P.RECEIVER_COUNTERS},
                          "clamped": r.clamped, "moving": r.moving, "enabled": r.enabled},
                _CHANNEL: {"channel": r.w_ch, "commanded": st.target, "current": st.current,
                           "moving": st.moving, "enabled": st.enabled},
                _NACK: {"request": r.cmd, "reason": reason}}

    def _build(self, m, r, wr):
        byte, answer_end, length = Signal(8), Signal(), Signal.like(r.ans_len)
        sources = self._sources(r)
        b_bits = len(r.b)
        # the answers' bytes by where they come from, selected by the answer kind and the byte
        # index: one multiplexer input per distinct source byte (the six receiver counters' bytes
        # are one, counter_data's), bytes past a field's signal zero
        cases, addr = {}, {}
        for kind, fields in enumerate(_BUILT):
            at = 0
            for f in fields:
                n, sig = f.group_bytes(None), sources[kind][f.name]
                assert len(answer_byte_map((f,))) == n and len(sig) <= 8 * n, f.name
                for k in range(n):
                    key = kind << b_bits | at
                    if f.name in P.RECEIVER_COUNTERS:
                        addr.setdefault(P.RECEIVER_COUNTERS.index(f.name), []).append(key)
                    if 8 * k < len(sig):
                        cases.setdefault((id(sig), k), (sig, k, []))[2].append(key)
                    at += 1
            with m.If((r.kind == kind) & (r.b == at - 1)):
                m.d.comb += [answer_end.eq(1), length.eq(at)]
        # two switches: a byte of a counter selects both its address and its byte (a switch
        # takes only its first matching case)
        with m.Switch(Cat(r.b, r.kind)):
            for a, at in addr.items():
                with m.Case(*at):
                    m.d.comb += self.counter_addr.eq(a)
        with m.Switch(Cat(r.b, r.kind)):
            for sig, k, at in cases.values():
                with m.Case(*at):
                    m.d.comb += byte.eq(sig[8 * k:8 * k + 8])
        # each byte is written a cycle after it is selected: the counters are a memory
        with m.If(~r.settle):
            m.d.sync += r.settle.eq(1)
        with m.Else():
            m.d.comb += [wr.en.eq(1), wr.addr.eq(self._region_addr(1, r.b)), wr.data.eq(byte)]
            m.d.sync += [r.settle.eq(0), r.b.eq(r.b + 1)]
            with m.If(answer_end):
                m.d.comb += self.status.ready.eq(r.kind == _CHANNEL)
                m.d.sync += r.ans_len.eq(length)
                m.next = "ANSWER"
