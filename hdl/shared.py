"""Robot core: one folded evaluator time-multiplexed over identical legs, a PWM bank for all servos."""
from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.channels import ChannelTable
from ..fit.plan import Plan, signed_bits
from .architectures import Timing
from .evaluator import input_layout, node_shape, output_layout
from .folded import FoldedEvaluator
from .pwm import servo_channels
from .pwmbank import ServoPWMBank

__all__ = ["RobotCore", "robot_input_layout", "robot_output_layout", "TABLE_LATENCY", "table_in_use"]

#: cycles the channel table's output register adds to the latency and the initiation interval
TABLE_LATENCY = 1


def table_in_use(plan: Plan, channels: ChannelTable | None) -> ChannelTable | None:
    """``channels`` checked against ``plan``; None when there is none or it changes nothing
    (:meth:`~ikseries.fit.channels.ChannelTable.is_identity`: the core then has no table stage,
    its Verilog that of a core without a table)."""
    if channels is None:
        return None
    channels.check(plan)
    return None if channels.is_identity(plan) else channels


def robot_input_layout(plan: Plan, legs: int) -> data.StructLayout:
    """A target for one leg: ``leg`` index and the plan's input fields under ``target``."""
    return data.StructLayout({"leg": range(legs), "target": input_layout(plan)})


def robot_output_layout(plan: Plan, legs: int) -> data.StructLayout:
    """Pulse widths (clock ticks) of one leg's servos: ``leg`` and ``widths.<servo>``."""
    return data.StructLayout({"leg": range(legs), "widths": output_layout(plan)})


class RobotCore(wiring.Component):
    """Inverse kinematics and servo signals for ``legs`` legs that share one plan.

    One :class:`FoldedEvaluator` serves every leg in turn: each input carries a leg index
    and that leg's tip target; the widths it yields are written to that leg's servo
    channels of a :class:`ServoPWMBank` (one period counter for all channels), which
    applies a leg's new widths together at the next PWM period start.

    With a channel table (:class:`~ikseries.fit.channels.ChannelTable`) a mirrored leg's
    ``mirror_input`` is negated on the way in (combinationally, into the evaluator's input
    register; the one port value whose negation does not fit saturates) and each width
    becomes ``min(max(offset + sign * width, lo), hi)`` with its channel's constants, picked
    by the leg, in an output register; a table with gains multiplies first, ``min(max((offset
    + sign * gain * width) >> gain_bits, lo), hi)`` (one constant-operand product per servo,
    a DSP-sized one). Interval analysis over every leg's constants and every
    width the plan can yield sizes the adder (no overflow for any input); the limits lie in
    the plan's output range, so the widths keep its shape.

    Parameters
    ----------
    plan : Plan
        The plan of one leg; its outputs are pulse widths in clock ticks (never negative).
    legs : int
        Number of legs.
    period : int
        PWM period in clock cycles.
    clock_hz : float
        Clock frequency the core will run at; only used for ``refresh_hz``.
    multipliers, dsp, dsp_registers
        As for :class:`FoldedEvaluator` (``dsp_registers``: the units' limb products on that
        family's DSP primitive; :meth:`simulation_model` is then the twin with fabric
        registers the Amaranth simulator runs).
    reset_widths : dict, optional
        Pulse width per servo name (the same for every leg) until its leg's first target.
    channels : ChannelTable, optional
        The per-leg mirror and per-channel constants (:func:`table_in_use`: none, or one that
        changes nothing, gives the core without a table stage).
    held_input : bool
        The sender holds ``i.payload`` (leg and target) from the input transfer until the
        widths transfer on ``o``: the evaluator has no input register
        (:class:`~ikseries.hdl.folded.FoldedEvaluator`). Default False.
    rotate_outputs : bool
        Adds ``rotate`` for a reader that takes the widths one at a time from the first servo's
        (:class:`~ikseries.hdl.folded.FoldedEvaluator`'s ``rotate_outputs``; with a channel
        table its output register moves instead). The PWM bank is then not loaded: its pins
        keep the reset widths (the reader drives pins of its own). Default False.

    Attributes
    ----------
    i : In(stream.Signature(robot_input_layout(plan, legs)))
    o : Out(stream.Signature(robot_output_layout(plan, legs)))
        The widths of each evaluation with its leg; every transfer on ``o`` also loads
        them into the PWM bank (tie ``o.ready`` high if nothing listens).
    pwm : Out(legs * len(plan.outputs))
        Servo signals; bit ``leg * len(plan.outputs) + j`` drives servo ``j`` of ``leg``.
    period_start : Out(1)
        High for one cycle when a PWM period starts (widths take effect).
    rotate : In(1)
        With ``rotate_outputs``: a strobe while ``o.valid`` moves ``o.payload.widths`` one servo
        towards the first (the first takes the last's place); exactly once per servo per
        transfer (or never).

    Reset: the evaluator idle, the table's output register empty (``o.valid`` low), the PWM
    bank's reset widths.

    Latency
    -------
    ``latency`` cycles from a target transfer on ``i`` to its widths on ``o``: the
    evaluator's, plus :data:`TABLE_LATENCY` with a channel table; the widths reach the servo signals at the next period start (the one
    after, for widths that arrive in a period's last cycle; see :class:`~ikseries.hdl.pwmbank.ServoPWMBank`).

    Throughput
    ----------
    One target every ``initiation_interval`` (= ``latency``) cycles while ``o.ready`` is high:
    one evaluation in flight, ``i.ready`` low from an input transfer until its output
    transfers (the folded stream rule); every leg
    gets new widths ``refresh_hz`` times a second when targets are offered round-robin.
    """

    def __init__(self, plan: Plan, legs: int, period: int, clock_hz: float, *, multipliers: int = 1,
                 dsp: tuple[int, int] | None = None, reset_widths: dict | None = None,
                 channels: ChannelTable | None = None, dsp_registers: str | None = None,
                 held_input: bool = False, rotate_outputs: bool = False):
        self._args = ((plan, legs, period, clock_hz), dict(multipliers=multipliers, dsp=dsp,
                                                           reset_widths=reset_widths, channels=channels,
                                                           held_input=held_input, rotate_outputs=rotate_outputs))
        if not isinstance(legs, int) or isinstance(legs, bool) or legs < 1:
            raise ValueError(f"legs must be a positive integer, not {legs!r}")
        if isinstance(clock_hz, bool) or not isinstance(clock_hz, (int, float)) or not clock_hz > 0:
            raise ValueError(f"clock_hz must be a positive number, not {clock_hz!r}")
        if channels is not None and channels.legs != legs:
            raise ValueError(f"channels must be a table of {legs} legs, not {channels.legs}")
        self._table = table_in_use(plan, channels)
        self._rotate = bool(rotate_outputs)
        # with a table stage its output register is the one that rotates
        self._evaluator = FoldedEvaluator(plan, multipliers, dsp, dsp_registers, held_input,
                                          self._rotate and self._table is None)
        self._servos, reset_widths = servo_channels(plan, reset_widths)
        width_bits = max(plan.nodes[o.node].width for o in plan.outputs)
        self._bank = ServoPWMBank(period, width_bits, legs, len(self._servos),
                                  [reset_widths.get(s, 0) for s in self._servos] * legs)
        self._plan, self._legs, self._clock_hz = plan, legs, clock_hz
        super().__init__({
            "i": In(stream.Signature(robot_input_layout(plan, legs))),
            "o": Out(stream.Signature(robot_output_layout(plan, legs))),
            "pwm": Out(legs * len(self._servos)),
            "period_start": Out(1),
            **({"rotate": In(1)} if self._rotate else {}),
        })

    @property
    def evaluator(self) -> FoldedEvaluator:
        return self._evaluator

    @property
    def legs(self) -> int:
        return self._legs

    @property
    def dsp_registers(self) -> str | None:
        """The family ("ice40", "ecp5") when the products run on its DSP primitives, else None."""
        return self._evaluator.dsp_registers

    def simulation_model(self) -> "RobotCore":
        """A core the Amaranth simulator can run with the same ports, timing and values: this
        one, or with ``dsp_registers`` a twin whose DSP registers are fabric flip-flops."""
        if self.dsp_registers is None:
            return self
        args, kw = self._args
        return RobotCore(*args, **kw)

    def registered(self) -> "RobotCore":
        """This core with an input register of its own and whole outputs (``held_input`` and
        ``rotate_outputs`` False): the plain core a board without a controller has, which
        :mod:`bench.controller_cells` measures against."""
        args, kw = self._args
        plain = {**kw, "held_input": False, "rotate_outputs": False}
        return self if plain == kw else RobotCore(*args, **plain)

    @property
    def servos(self) -> list[str]:
        return list(self._servos)

    @property
    def period(self) -> int:
        return self._bank.period

    @property
    def clock_hz(self) -> float:
        return self._clock_hz

    @property
    def channels(self) -> ChannelTable | None:
        """The channel table in use (None: no table stage)."""
        return self._table

    @property
    def latency(self) -> int:
        return self._evaluator.latency + (TABLE_LATENCY if self._table is not None else 0)

    @property
    def initiation_interval(self) -> int:
        return self._evaluator.initiation_interval + (TABLE_LATENCY if self._table is not None else 0)

    @property
    def timing(self) -> Timing:
        """The evaluator's latency and initiation interval, shared by the legs."""
        return Timing(self.latency, self.initiation_interval, "folded", self._legs)

    @property
    def refresh_hz(self) -> float:
        """Whole-robot IK refresh rate: every leg re-evaluated this many times per second."""
        return self.timing.refresh_hz(self._clock_hz)

    def elaborate(self, platform):
        m = Module()
        m.submodules.evaluator = ev = self._evaluator
        m.submodules.pwm_bank = bank = self._bank
        # the evaluator holds one evaluation at a time (its i.ready stays low until its
        # output transfers), so the leg of the evaluation in flight is one register
        leg = Signal(range(self._legs))
        if self._table is not None:
            self._table_stage(m, ev, bank, leg)
            m.d.comb += [self.pwm.eq(bank.pwm), self.period_start.eq(bank.period_start)]
            return m
        m.d.comb += [ev.i.valid.eq(self.i.valid), ev.i.payload.eq(self.i.payload.target),
                     self.i.ready.eq(ev.i.ready)]
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += leg.eq(self.i.payload.leg)
        m.d.comb += [self.o.valid.eq(ev.o.valid), ev.o.ready.eq(self.o.ready),
                     self.o.payload.leg.eq(leg), self.o.payload.widths.eq(ev.o.payload)]
        if self._rotate:
            m.d.comb += ev.rotate.eq(self.rotate)
        else:
            m.d.comb += [bank.i.valid.eq(ev.o.valid & self.o.ready), bank.i.payload.group.eq(leg)]
        for j, s in enumerate(self._servos):
            m.d.comb += bank.i.payload.widths[j].eq(ev.o.payload[s])
        m.d.comb += [self.pwm.eq(bank.pwm), self.period_start.eq(bank.period_start)]
        return m

    def _table_stage(self, m, ev, bank, leg):
        """The evaluator between the input mirror and the table's output register; one
        evaluation in flight through both (``gate``: the evaluator's output is not moving to
        the register, and the register is empty or transfers now)."""
        full = Signal()
        gate = Signal()
        m.d.comb += [gate.eq(~ev.o.valid & (~full | self.o.ready)),
                     ev.i.valid.eq(self.i.valid & gate), self.i.ready.eq(ev.i.ready & gate)]
        self._mirror_inputs(m, ev)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += leg.eq(self.i.payload.leg)
        out_leg = Signal(range(self._legs))
        out = Signal(output_layout(self._plan))
        load = ev.o.valid & ~full
        m.d.comb += ev.o.ready.eq(~full)
        for j, s in enumerate(self._servos):
            w = self._calibrated(m, j, ev.o.payload[s], leg)
            with m.If(load):
                m.d.sync += out[s].eq(w)
        if self._rotate:        # the register is full (no load) while a reader rotates it
            names = self._servos
            with m.If(self.rotate):
                m.d.sync += [out[s].eq(out[names[(j + 1) % len(names)]]) for j, s in enumerate(names)]
        with m.If(load):
            m.d.sync += [full.eq(1), out_leg.eq(leg)]
        with m.Elif(self.o.valid & self.o.ready):
            m.d.sync += full.eq(0)
        # a rotating register does not load the bank
        loads = [] if self._rotate else [bank.i.valid.eq(full & self.o.ready)]
        m.d.comb += [self.o.valid.eq(full), self.o.payload.leg.eq(out_leg), self.o.payload.widths.eq(out),
                     *loads, bank.i.payload.group.eq(out_leg)]
        for j, s in enumerate(self._servos):
            m.d.comb += bank.i.payload.widths[j].eq(out[s])

    def _mirror_inputs(self, m, ev):
        """The target into the evaluator; a mirrored leg's ``mirror_input`` negated, at one
        bit more, saturated to the port's top (only the port's most negative value needs it)."""
        t, tgt = self._table, self.i.payload.target
        for inp in self._plan.inputs:
            if inp.name != t.mirror_input:
                m.d.comb += ev.i.payload[inp.name].eq(tgt[inp.name])
                continue
            flip = Signal(name=f"mirror_{inp.name}")
            with m.Switch(self.i.payload.leg):
                for k, mirrored in enumerate(t.mirrored):
                    with m.Case(k):
                        m.d.comb += flip.eq(int(mirrored))
            neg = Signal(signed(inp.width + 1), name=f"neg_{inp.name}")
            top = inp.port_range[1]
            m.d.comb += [neg.eq(-tgt[inp.name]),
                         ev.i.payload[inp.name].eq(Mux(flip, Mux(neg > top, top, neg), tgt[inp.name]))]

    def _calibrated(self, m, j, width, leg):
        """``min(max((offset + sign * gain * width) >> gain_bits, lo), hi)`` of servo ``j``
        with the constants of ``leg``'s channel (a table without gains: no product, no shift);
        the sum at the width its interval over all legs needs."""
        t, plan = self._table, self._plan
        s = self._servos[j]
        shape = node_shape(plan.nodes[plan.outputs[j].node])
        total = signed(signed_bits(*t.sum_range(plan, j)))
        off, neg = Signal(total, name=f"offset_{s}"), Signal(name=f"mirror_{s}")
        lo, hi = Signal(shape, name=f"lo_{s}"), Signal(shape, name=f"hi_{s}")
        gain = Signal(range(t.gain_range(j) + 1), name=f"gain_{s}") if t.gain_bits else None
        with m.Switch(leg):
            for k in range(self._legs):
                c = t.channel(k, s)
                with m.Case(k):
                    m.d.comb += [off.eq(c.offset), neg.eq(int(c.sign == -1)), lo.eq(c.lo), hi.eq(c.hi)]
                    if gain is not None:
                        m.d.comb += gain.eq(c.gain)
        v = Signal(total, name=f"sum_{s}")
        sat = Signal(shape, name=f"channel_{s}")
        term = width if gain is None else width * gain
        m.d.comb += v.eq(Mux(neg, off - term, off + term))
        if gain is not None:
            q = Signal(signed(total.width - t.gain_bits), name=f"scaled_{s}")
            m.d.comb += q.eq(v >> t.gain_bits)      # arithmetic: the floor, as the golden model's
            v = q
        m.d.comb += sat.eq(Mux(v < lo, lo, Mux(v > hi, hi, v)))
        return sat
