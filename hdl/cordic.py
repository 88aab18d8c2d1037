"""Fully pipelined CORDIC leg solver: the conventional baseline for the polynomial evaluator."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.cordic import SHIFT_ADD_DIGITS, CordicDesign, CordicPlan, OperatorOps, csd, datapath
from ..fit.plan import bits_for

__all__ = ["AmaranthOps", "CordicLegSolver", "cordic_input_layout", "cordic_output_layout"]


def _shape(lo: int, hi: int):
    w, s = bits_for(lo, hi)
    return signed(w) if s else unsigned(w)


def cordic_input_layout(cp: CordicPlan) -> data.StructLayout:
    """One field per input: the port integer (value * 2**frac); as ``PlanEvaluator``'s."""
    return data.StructLayout({i.name: signed(i.width) if i.signed else unsigned(i.width) for i in cp.inputs})


def cordic_output_layout(cp: CordicPlan) -> data.StructLayout:
    """One field per servo: pulse width in PWM clock ticks, shaped by the pulse limits."""
    return data.StructLayout({s: _shape(*cp.limits) for s in cp.servos})


class AmaranthOps(OperatorOps):
    """Datapath back end emitting Amaranth: combinational expressions (exact: Amaranth widens
    ``+``, ``-``, ``*`` and shifts), and one register per value at each ``stage`` with the width
    of its analysed range, loaded when ``en`` is high."""

    analysis = False

    def __init__(self, m: Module, en, payload, layout: list[dict]):
        self._m, self._en, self._payload, self._layout = m, en, payload, layout
        self._stage = 0
        self._keep: list = []        # keeps the registers alive so their ids stay unique
        self._reg_stage: dict = {}   # id(register) -> its stage number

    def port(self, name):
        return self._payload[name]

    def c(self, v):
        return Const(v)

    def mulc(self, a, c: int):
        """a * c: a shift-add over the CSD digits of c when it has few, else ``*``."""
        digits = csd(c)
        if not digits:
            return Const(0)
        if len(digits) > SHIFT_ADD_DIGITS:
            return a * Const(c)
        a = Value.cast(a)
        if not a.shape().signed:
            a = Cat(a, Const(0, 1)).as_signed()
        acc = None
        for sign, k in sorted(digits, key=lambda d: -d[0]):   # positive digits first
            term = a << k
            acc = (term if sign > 0 else -term) if acc is None else (acc + term if sign > 0 else acc - term)
        return acc

    def addsub(self, a, b, sub):
        """a - b if sub else a + b, as ONE adder: a + (b ^ -sub) + sub (a conditional
        inversion and a carry-in; Yosys maps it to a single carry chain)."""
        b = Value.cast(b)
        if not b.shape().signed:
            b = Cat(b, Const(0, 1)).as_signed()
        return a + Mux(sub, ~b, b) + sub

    def or_(self, a, b):
        return a | b

    def mux(self, c, a, b):
        return Mux(c, a, b)

    def clamp(self, a, lo=None, hi=None):
        if lo is not None:
            a = Mux(a < lo, lo, a)
        if hi is not None:
            a = Mux(a > hi, hi, a)
        return a

    def stage(self, name, vals, hints=None):
        bounds = self._layout[self._stage]
        self._stage += 1
        out = {}
        for k, v in vals.items():
            # a register may only read the previous stage's registers (stage 1: the ports);
            # reading an older one would skip a delay the golden model cannot see
            for sig in Value.cast(v)._rhs_signals():
                st = self._reg_stage.get(id(sig), self._stage - 1)
                if st != self._stage - 1:
                    raise AssertionError(f"stage {self._stage} ({name}.{k}) reads {sig.name} from stage {st}")
            reg = Signal(_shape(*bounds[k]), name=f"s{self._stage}_{name}_{k}".replace("__", "_"))
            with self._m.If(self._en):
                self._m.d.sync += reg.eq(v)
            self._reg_stage[id(reg)] = self._stage
            self._keep.append(reg)
            out[k] = reg
        return out


class CordicLegSolver(wiring.Component):
    """Inverse kinematics of a cylinder-leg robot by CORDIC, one target per clock.

    The datapath is :func:`ikseries.fit.cordic.datapath` (see that module for the algorithm);
    every ``stage`` of it is one register stage here, every register as wide as its analysed
    range, so no in-range input overflows (out-of-range port values are clamped to the
    workspace in the first stage). Constant multiplies (gain compensation, pulse scaling) are
    shift-adds when the constant has at most ``SHIFT_ADD_DIGITS`` canonical signed digits
    (480 ticks/degree: one subtraction), else ``*`` by a constant left to Yosys (a DSP block);
    CORDIC shifts are wiring; the square root is a restoring one with one result bit per stage.

    Parameters
    ----------
    robot : ikseries.robot.Robot
        A robot with a cylinder-leg geometry.
    design : CordicDesign
        Iterations and fixed-point formats (see ``ikseries.fit.cordic_sizing.size_cordic``).

    Attributes
    ----------
    i : In(stream.Signature(cordic_input_layout(plan)))
        Targets: one port integer per input (``r``, ``theta``, ``z``), the same fields and
        widths as the polynomial ``PlanEvaluator``.
    o : Out(stream.Signature(cordic_output_layout(plan)))
        Pulse widths in PWM clock ticks (``s1``, ``s2``, ``s3``), rounded and clamped to the
        pulse limits exactly as the polynomial core's outputs.

    Latency
    -------
    ``latency`` cycles (``plan.latency``: one per datapath stage) from an input transfer to its
    output transfer when ``o.ready`` is high.

    Throughput
    ----------
    One input per cycle. When ``o.valid`` is high and ``o.ready`` low, the whole pipeline
    stalls and ``i.ready`` is low (the same global-stall handshake as ``PlanEvaluator``).
    After reset the pipeline is empty (``o.valid`` low).
    """

    def __init__(self, robot, design: CordicDesign):
        self._plan = CordicPlan(robot, design)
        super().__init__({
            "i": In(stream.Signature(cordic_input_layout(self._plan))),
            "o": Out(stream.Signature(cordic_output_layout(self._plan))),
        })

    @property
    def plan(self) -> CordicPlan:
        return self._plan

    @property
    def design(self) -> CordicDesign:
        return self._plan.design

    @property
    def latency(self) -> int:
        return self._plan.latency

    def elaborate(self, platform):
        m = Module()
        lat = self.latency
        en = Signal()
        m.d.comb += [en.eq(~self.o.valid | self.o.ready), self.i.ready.eq(en)]
        ops = AmaranthOps(m, en, self.i.payload, self._plan.layout)
        out = datapath(ops, self._plan)
        valid = Signal(lat, name="valid")   # valid[k]: stage k + 1 holds a real input
        with m.If(en):
            m.d.sync += valid.eq(Cat(self.i.valid, valid[:lat - 1]))
        m.d.comb += self.o.valid.eq(valid[lat - 1])
        for s in self._plan.servos:
            m.d.comb += self.o.payload[s].eq(out[s])
        return m
