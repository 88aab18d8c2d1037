"""Partly folded evaluator: the plan's dataflow pipelined, its multiplications shared by a
modulo schedule (one target every ``initiation_interval`` cycles on fewer multipliers)."""
from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.plan import Plan
from .evaluator import input_layout, output_layout

__all__ = ["ModuloEvaluator", "ModuloSchedule", "modulo_schedule", "MUL_LATENCY"]

#: cycles from reading a multiplication's operands to reading its product: operand registers at
#: the multiplier inputs, the product register, the capture into the node's own register
MUL_LATENCY = 3
_WIRING = ("shr", "shl", "frac", "index", "mask")


@dataclass(frozen=True)
class ModuloSchedule:
    """When every plan node is computed for one target, and on which multiplier.

    ``ready[n]``: first cycle (counted from the cycle the target is accepted) in which node
    ``n`` can be read; ``start[n]``: the cycle a registered operation reads its operands
    (None for inputs, constants and wiring); ``unit[n]``: the multiplier of a
    multiplication. A multiplier serves at most one multiplication per phase
    ``start mod initiation_interval``, so targets can enter every ``initiation_interval``
    cycles.
    """
    initiation_interval: int
    units: int
    ready: tuple
    start: tuple
    unit: tuple
    latency: int
    swap: tuple = ()      # per node: the multiplier takes the operands in the other order
    operand_widths: tuple = ()  # per multiplier: signed widths (a, b) of its operands

    def last_read(self, plan: Plan) -> list[int]:
        """Per node, the last cycle it is read: by a registered consumer (when that reads its
        operands), through a wiring consumer (as late as that is read) or as an output."""
        last = list(self.ready)
        for o in plan.outputs:
            last[o.node] = max(last[o.node], self.latency)
        readers = [[] for _ in plan.nodes]
        for i, n in enumerate(plan.nodes):
            for a in n.args:
                readers[a].append(i)
        for i in reversed(range(len(plan.nodes))):     # readers come after their operands
            for r in readers[i]:
                last[i] = max(last[i], last[r] if plan.nodes[r].op in _WIRING else self.start[r])
        return last


def _signed_width(node) -> int:
    return node.width + (not node.signed)


def _tiles(wa: int, wb: int, dsp: tuple[int, int]) -> int:
    """DSP blocks of a wa x wb signed product (either orientation), 0 for no product."""
    if not wa or not wb:
        return 0
    return min(-(-wa // dsp[0]) * -(-wb // dsp[1]), -(-wa // dsp[1]) * -(-wb // dsp[0]))


def modulo_schedule(plan: Plan, initiation_interval: int, units: int | None = None,
                    dsp: tuple[int, int] = (18, 18)) -> ModuloSchedule:
    """List-schedule ``plan`` with its multiplications on ``units`` multipliers (default the
    fewest: ceil(multiplications / initiation_interval)), each free once per phase.

    Every cycle the ready multiplications take the free multipliers of that phase, the one
    with the longest path to an output first; additions, clamps and table reads have their
    own hardware and run as soon as their operands are ready. Of the free multipliers a
    multiplication takes the one (and the operand order) that its widths grow least, counted
    in ``dsp``-sized blocks, so wide and narrow products gather on different multipliers.
    """
    ii = initiation_interval
    muls = [i for i, n in enumerate(plan.nodes) if n.op == "mul"]
    units = max(1, -(-len(muls) // ii)) if units is None else units
    if units * ii < len(muls):
        raise ValueError(f"units must be at least {-(-len(muls) // ii)} for {len(muls)} multiplications "
                         f"at initiation interval {ii}, not {units}")
    nodes = plan.nodes
    # height: cycles from reading a node's operands to the outputs (priority)
    users = [[] for _ in nodes]
    for i, n in enumerate(nodes):
        for a in n.args:
            users[a].append(i)
    height = [0] * len(nodes)
    for i in reversed(range(len(nodes))):
        own = MUL_LATENCY if nodes[i].op == "mul" else (0 if nodes[i].op in _WIRING else 1)
        height[i] = own + max((height[u] for u in users[i]), default=0)
    ready: list = [None] * len(nodes)
    start: list = [None] * len(nodes)
    unit: list = [None] * len(nodes)
    busy = [[False] * ii for _ in range(units)]
    widths = [(0, 0)] * units
    swap: list = [False] * len(nodes)
    pending = set(muls)

    def place(i, free):
        wa, wb = (_signed_width(nodes[a]) for a in nodes[i].args)
        best = None
        for u in free:
            ua, ub = widths[u]
            for sw, (x, y) in ((False, (wa, wb)), (True, (wb, wa))):
                grown = (max(ua, x), max(ub, y))
                key = (_tiles(*grown, dsp) - _tiles(ua, ub, dsp), grown[0] * grown[1] - ua * ub, u, sw)
                if best is None or key < best[0]:
                    best = (key, u, sw, grown)
        _, u, sw, grown = best
        widths[u], swap[i] = grown, sw
        return u

    def settle():
        """Give every non-multiplication whose operands are scheduled its time."""
        for i, n in enumerate(nodes):
            if ready[i] is not None or n.op == "mul":
                continue
            if n.op == "const":
                ready[i] = 0
            elif n.op == "input":
                ready[i] = 1
            elif all(ready[a] is not None for a in n.args):
                t = max(ready[a] for a in n.args)
                if n.op in _WIRING:
                    ready[i] = t
                else:
                    start[i], ready[i] = t, t + 1

    settle()
    cycle = 0
    while pending:
        cands = sorted((i for i in pending if all(ready[a] is not None and ready[a] <= cycle
                                                  for a in nodes[i].args)),
                       key=lambda i: (-height[i], i))
        for i in cands:
            free = [u for u in range(units) if not busy[u][cycle % ii]]
            if not free:
                break
            u = place(i, free)
            busy[u][cycle % ii] = True
            start[i], ready[i], unit[i] = cycle, cycle + MUL_LATENCY, u
            pending.discard(i)
        settle()
        cycle += 1
    settle()
    latency = max([1] + [ready[o.node] for o in plan.outputs])
    return ModuloSchedule(ii, units, tuple(ready), tuple(start), tuple(unit), latency, tuple(swap),
                          tuple(widths))




def _shape(node):
    return signed(node.width) if node.signed else unsigned(node.width)


class ModuloEvaluator(wiring.Component):
    """Evaluates every output of ``plan``, one target every ``initiation_interval`` cycles.

    Between the fully pipelined :class:`~ikseries.hdl.evaluator.PlanEvaluator` (one target
    per cycle, one multiplier per multiplication) and the
    :class:`~ikseries.hdl.folded.FoldedEvaluator` (everything on a few units, one target per
    evaluation): the dataflow keeps its own adders, clamps and table reads, while the
    multiplications share ``units`` multipliers in a modulo schedule
    (:func:`modulo_schedule`). A phase counter selects each multiplier's operands; each
    multiplier has registered operands and a registered product (DSP-friendly), which the
    node's own register captures. A value read more than ``initiation_interval`` cycles
    after it was computed is kept in a chain of registers that advance once per target.
    Every width comes from the plan's interval analysis, so the outputs equal
    :func:`ikseries.sim.golden.evaluate` bit for bit.

    Parameters
    ----------
    plan : Plan
    initiation_interval : int
        Cycles between accepted targets (>= 1).
    units : int, optional
        Multipliers; default the fewest that fit: ceil(multiplications / initiation_interval).
    dsp : (int, int)
        Signed operand widths of the device's DSP multiplier (default ECP5 MULT18X18D 18x18):
        the schedule gathers products by their size in those blocks.

    Attributes
    ----------
    i : In(stream.Signature(input_layout(plan)))
    o : Out(stream.Signature(output_layout(plan)))

    Latency
    -------
    ``latency`` cycles from an input transfer to its output transfer while ``o.ready`` is
    high (the schedule's length; a multiplication takes ``MUL_LATENCY`` cycles).

    Throughput
    ----------
    One input every ``initiation_interval`` cycles: ``i.ready`` is high one cycle in
    ``initiation_interval`` (when the phase counter is 0). When ``o.valid`` is high and
    ``o.ready`` low, everything, the phase counter included, stalls.
    """

    def __init__(self, plan: Plan, initiation_interval: int, units: int | None = None,
                 dsp: tuple[int, int] = (18, 18)):
        if not isinstance(plan, Plan):
            raise TypeError(f"plan must be a Plan, not {plan!r}")
        if isinstance(initiation_interval, bool) or not isinstance(initiation_interval, int) \
                or initiation_interval < 1:
            raise ValueError(f"initiation_interval must be an integer >= 1, not {initiation_interval!r}")
        if units is not None and (isinstance(units, bool) or not isinstance(units, int) or units < 1):
            raise ValueError(f"units must be None or an integer >= 1, not {units!r}")
        self._plan = plan
        self._schedule = modulo_schedule(plan, initiation_interval, units, dsp)
        super().__init__({
            "i": In(stream.Signature(input_layout(plan))),
            "o": Out(stream.Signature(output_layout(plan))),
        })

    @property
    def plan(self) -> Plan:
        return self._plan

    @property
    def schedule(self) -> ModuloSchedule:
        return self._schedule

    @property
    def latency(self) -> int:
        return self._schedule.latency

    @property
    def initiation_interval(self) -> int:
        return self._schedule.initiation_interval

    @property
    def multipliers(self) -> int:
        return self._schedule.units

    def elaborate(self, platform):
        m = Module()
        plan, sch = self._plan, self._schedule
        ii, lat, nodes = sch.initiation_interval, sch.latency, plan.nodes
        en = Signal()
        m.d.comb += en.eq(~self.o.valid | self.o.ready)
        phase = Signal(range(ii), name="phase")
        with m.If(en):
            m.d.sync += phase.eq(Mux(phase == ii - 1, 0, phase + 1))
        m.d.comb += self.i.ready.eq(en & (phase == 0))

        last = sch.last_read(plan)
        chains: dict = {}
        wires: dict = {}

        def at_phase(c):
            return en & (phase == c % ii)

        def read(i, c):
            """Value of node ``i`` of the target being evaluated, during its cycle ``c``."""
            n = nodes[i]
            if n.op == "const":
                return Const(n.param, _shape(n))
            if n.op in _WIRING:
                if (i, c) in wires:
                    return wires[i, c]
                a = read(n.args[0], c)
                if n.op == "shr":
                    v = a >> n.param
                elif n.op == "shl":
                    v = a << n.param
                elif n.op == "index":
                    v = a >> n.param
                elif n.op == "mask":
                    v = a.as_unsigned()[:n.param]
                else:
                    v = a
                w = wires[i, c] = Signal(_shape(n), name=f"n{i}_{n.op}_c{c}")
                m.d.comb += w.eq(v)
                return w
            if c < sch.ready[i] or c > last[i]:
                raise AssertionError(f"node {i} read at cycle {c} outside [{sch.ready[i]}, {last[i]}]")
            return chains[i][(c - sch.ready[i]) // ii]

        # registers of every registered node: reg[0] written at the end of cycle ready - 1,
        # reg[j] takes reg[j - 1] at the same phase
        for i, n in enumerate(nodes):
            if n.op in _WIRING or n.op == "const":
                continue
            depth = (last[i] - sch.ready[i]) // ii + 1
            chains[i] = [Signal(_shape(n), name=f"n{i}_{n.op}" + (f"_r{j}" if j else ""))
                         for j in range(depth)]
            with m.If(at_phase(sch.ready[i] - 1)):
                m.d.sync += [chains[i][j].eq(chains[i][j - 1]) for j in range(1, depth)]

        for i, n in enumerate(nodes):
            if n.op in _WIRING or n.op in ("const", "mul"):
                continue
            reg = chains[i][0]
            if n.op == "input":
                with m.If(self.i.ready):
                    m.d.sync += reg.eq(self.i.payload[n.param])
                continue
            s = sch.start[i]
            ops = [read(a, s) for a in n.args]
            if n.op == "add":
                v = ops[0] + ops[1]
            elif n.op == "clamp":
                lo, hi = n.param
                v = Mux(ops[0] < lo, lo, Mux(ops[0] > hi, hi, ops[0]))
            elif n.op == "lut":
                v = Array(Const(x, _shape(n)) for x in n.param)[ops[0]]
            else:
                raise ValueError(f"plan node operation {n.op!r} is not supported")
            with m.If(at_phase(s)):
                m.d.sync += reg.eq(v)

        # shared multipliers: operands selected by phase, registered; product registered;
        # each multiplication's node register captures the product at its phase
        for u in range(sch.units):
            mine = [i for i in range(len(nodes)) if sch.unit[i] == u]
            if not mine:
                continue
            wa, wb = sch.operand_widths[u]
            a, b = Signal(signed(wa), name=f"mul{u}_a"), Signal(signed(wb), name=f"mul{u}_b")
            p = Signal(signed(wa + wb), name=f"mul{u}_p")
            with m.If(en):
                m.d.sync += p.eq(a * b)
                with m.Switch(phase):
                    for i in mine:
                        s = sch.start[i]
                        x, y = nodes[i].args[::-1] if sch.swap[i] else nodes[i].args
                        with m.Case(s % ii):
                            m.d.sync += [a.eq(read(x, s)), b.eq(read(y, s))]
            for i in mine:
                with m.If(at_phase(sch.start[i] + MUL_LATENCY - 1)):
                    m.d.sync += chains[i][0].eq(p)

        valid = Signal(lat, name="valid")    # valid[k]: a target accepted k + 1 cycles ago
        with m.If(en):
            m.d.sync += valid.eq(Cat(self.i.valid & self.i.ready, valid[:lat - 1]))
        m.d.comb += self.o.valid.eq(valid[lat - 1])
        for o in plan.outputs:
            m.d.comb += self.o.payload[o.name].eq(read(o.node, lat))
        return m
