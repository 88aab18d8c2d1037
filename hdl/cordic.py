"""Fully pipelined CORDIC leg solver: the conventional baseline for the polynomial evaluator."""
from __future__ import annotations

import math

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.baselines.cordic import SHIFT_ADD_DIGITS, CordicDesign, CordicPlan, OperatorOps, csd, datapath, isqrt_stages
from ..fit.plan import bits_for

__all__ = ["AmaranthOps", "FoldedAmaranthOps", "CordicLegSolver", "cordic_input_layout", "cordic_output_layout"]


def _shape(lo: int, hi: int):
    w, s = bits_for(lo, hi)
    return signed(w) if s else unsigned(w)


def cordic_input_layout(cp: CordicPlan) -> data.StructLayout:
    """One field per input: the port integer (value * 2**frac); as ``PlanEvaluator``'s."""
    return data.StructLayout({i.name: signed(i.width) if i.signed else unsigned(i.width) for i in cp.inputs})


def cordic_output_layout(cp: CordicPlan) -> data.StructLayout:
    """One field per servo: pulse width in PWM clock ticks, shaped by the pulse limits."""
    return data.StructLayout({s: _shape(*cp.limits[s]) for s in cp.servos})


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


class FoldedAmaranthOps(AmaranthOps):
    """:class:`AmaranthOps` whose loops each run on ONE set of registers (an iterative CORDIC).

    A loop of ``n`` iterations after stage ``s`` runs iteration ``i`` in cycle ``s + i`` as in
    the pipeline, so the latency does not change, but its registers are busy for ``n`` cycles:
    a target may enter only every ``initiation_interval`` >= ``n`` cycles (``phase``, the cycle
    of the target being accepted mod ``initiation_interval``, is 0 when it is). The first
    iteration reads the stage before the loop (``load``), later ones the loop's own registers;
    the shift ``>> i`` becomes a barrel shifter and the angle table a lookup by ``i``. Each
    register is as wide as the widest of its stages in the pipelined layout. Values the loop
    only carries are held in one register each. The square root is the digit-by-digit one
    (two bits of the radicand per iteration, fixed shifts), which yields the same
    floor(sqrt(x)) as the pipelined restoring root in the same number of iterations.
    """

    def __init__(self, m: Module, en, payload, layout: list[dict], phase, initiation_interval: int):
        super().__init__(m, en, payload, layout)
        self._phase, self._ii = phase, initiation_interval

    def table(self, values, i):
        if isinstance(i, int):
            return Const(values[i])
        return Array(Const(v) for v in values)[i]

    def _iterations(self, tag: str, n: int):
        """(load, busy, i) of a loop of ``n`` iterations starting now: ``load`` in the cycle of
        iteration 0; ``busy`` in every iteration's cycle; ``i`` the iteration number."""
        if n > self._ii:
            raise ValueError(f"initiation_interval must be >= the {n} iterations of loop {tag!r}, not {self._ii!r}")
        m = self._m
        done = Signal(range(n + 1), init=n, name=f"{tag}_iter")  # iterations done; n: idle
        load = Signal(name=f"{tag}_load")
        m.d.comb += load.eq(self._phase == self._stage % self._ii)
        with m.If(self._en):
            with m.If(load):
                m.d.sync += done.eq(1)
            with m.Elif(done != n):
                m.d.sync += done.eq(done + 1)
        return load, load | (done != n), Mux(load, 0, done)

    def _hold(self, regs: dict, stages: int):
        for r in regs.values():
            self._reg_stage[id(r)] = self._stage + stages
            self._keep.append(r)

    def loop(self, tag, n, step, live, hints=None):
        s = self._stage
        load, busy, i = self._iterations(tag, n)
        bounds = self._layout[s:s + n]
        regs = {k: Signal(_shape(min(b[k][0] for b in bounds), max(b[k][1] for b in bounds)),
                          name=f"{tag}_{k}") for k in bounds[0]}
        new = step(self, {k: Mux(load, live[k], r) for k, r in regs.items()}, i)
        with self._m.If(self._en & busy):
            self._m.d.sync += [r.eq(new[k]) for k, r in regs.items()]
        self._hold(regs, n)
        self._stage = s + n
        return regs

    def isqrt(self, live, xname, rname, xhi, tag):
        nb = isqrt_stages(xhi)
        rw = max(1, math.isqrt(xhi).bit_length())
        s, m = self._stage, self._m
        load, busy, _ = self._iterations(tag, nb)
        # after the iteration for result bit b: root = floor(sqrt(x >> 2b)),
        # rem = (x >> 2b) - root**2 <= 2 root; rest = x << 2 (nb - b) (the bits still to come)
        root = Signal(rw, name=f"{tag}_root")
        rem = Signal(rw + 1, name=f"{tag}_rem")
        rest = Signal(2 * nb, name=f"{tag}_rest")
        keep = {k: Signal(_shape(*self._layout[s][k]), name=f"{tag}_{k}") for k in live if k != xname}
        r0, m0, x0 = Mux(load, 0, root), Mux(load, 0, rem), Mux(load, live[xname], rest)
        cur = Cat(x0[2 * nb - 2:2 * nb], m0)           # (rem << 2) | next two radicand bits
        trial = Cat(Const(1, 2), r0)                   # (root << 2) | 1
        take = cur >= trial
        with m.If(self._en & busy):
            m.d.sync += [rem.eq(Mux(take, cur - trial, cur)), root.eq(Cat(take, r0)), rest.eq(x0 << 2)]
            m.d.sync += [r.eq(Mux(load, live[k], r)) for k, r in keep.items()]
        self._hold({**keep, rname: root, "_rem": rem, "_rest": rest}, nb)
        self._stage = s + nb
        return {**keep, rname: root}


class CordicLegSolver(wiring.Component):
    """Inverse kinematics of a cylinder-leg robot by CORDIC: pipelined (one target per clock)
    or iterative (each CORDIC and the square root on one set of registers).

    The datapath is :func:`ikseries.fit.baselines.cordic.datapath` (see that module for the algorithm).
    With ``initiation_interval`` 1 every ``stage`` of it is one register stage, every register
    as wide as its analysed range, so no in-range input overflows (out-of-range port values are
    clamped to the workspace in the first stage). Constant multiplies (gain compensation, pulse
    scaling) are shift-adds when the constant has at most ``SHIFT_ADD_DIGITS`` canonical signed
    digits (480 ticks/degree: one subtraction), else ``*`` by a constant left to Yosys (a DSP
    block); CORDIC shifts are wiring; the square root is a restoring one with one result bit per
    stage. With ``initiation_interval`` >= :attr:`longest_loop` each loop (micro-rotations,
    square-root steps) runs on one set of registers, an iteration per cycle
    (:class:`FoldedAmaranthOps`): the same values at the same latency, a fraction of the
    registers and adders, barrel shifters instead of wiring.

    Parameters
    ----------
    robot : ikseries.robot.Robot
        A robot with a cylinder-leg geometry.
    design : CordicDesign
        Iterations and fixed-point formats (see ``ikseries.fit.baselines.cordic_sizing.size_cordic``).
    initiation_interval : int
        1 (default): pipelined; or at least :attr:`longest_loop`: iterative.

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
    ``latency`` cycles (``plan.latency``: one per datapath stage or loop iteration) from an
    input transfer to its output transfer when ``o.ready`` is high, either way.

    Throughput
    ----------
    One input every ``initiation_interval`` cycles: pipelined, every cycle; iterative,
    ``i.ready`` is high one cycle in ``initiation_interval`` (a phase counter at 0). When
    ``o.valid`` is high and ``o.ready`` low, everything (the phase counter included) stalls and
    ``i.ready`` is low (the global-stall handshake of ``PlanEvaluator``). After reset the
    pipeline is empty (``o.valid`` low).
    """

    def __init__(self, robot, design: CordicDesign, initiation_interval: int = 1):
        self._plan = CordicPlan(robot, design)
        longest = self.longest_loop
        if isinstance(initiation_interval, bool) or not isinstance(initiation_interval, int) \
                or not (initiation_interval == 1 or initiation_interval >= longest):
            raise ValueError(f"initiation_interval must be 1 (pipelined) or an integer >= {longest} "
                             f"(the longest loop of this design), not {initiation_interval!r}")
        self._ii = initiation_interval
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

    @property
    def initiation_interval(self) -> int:
        return self._ii

    @property
    def longest_loop(self) -> int:
        """Iterations of the design's longest loop: the smallest interval of the iterative form."""
        return self._plan.longest_loop

    def elaborate(self, platform):
        m = Module()
        lat, ii = self.latency, self._ii
        en = Signal()
        m.d.comb += en.eq(~self.o.valid | self.o.ready)
        if ii == 1:
            m.d.comb += self.i.ready.eq(en)
            ops = AmaranthOps(m, en, self.i.payload, self._plan.layout)
        else:
            phase = Signal(range(ii), name="phase")
            with m.If(en):
                m.d.sync += phase.eq(Mux(phase == ii - 1, 0, phase + 1))
            m.d.comb += self.i.ready.eq(en & (phase == 0))
            ops = FoldedAmaranthOps(m, en, self.i.payload, self._plan.layout, phase, ii)
        out = datapath(ops, self._plan)
        accepted = self.i.valid if ii == 1 else self.i.valid & self.i.ready   # ready = en if ii == 1
        valid = Signal(lat, name="valid")   # valid[k]: stage k + 1 holds a real input
        with m.If(en):
            m.d.sync += valid.eq(Cat(accepted, valid[:lat - 1]))
        m.d.comb += self.o.valid.eq(valid[lat - 1])
        for s in self._plan.servos:
            m.d.comb += self.o.payload[s].eq(out[s])
        return m
