"""Pipelined fixed-point evaluator generated from an evaluation plan."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..fit.ops import OPS, node_shape
from ..fit.plan import Plan, lut_groups, stored_field   # both re-exported: the ROM layout's helpers

__all__ = ["PlanEvaluator", "input_layout", "lut_fields", "lut_groups", "lut_rom_init", "node_expression",
           "output_layout", "stored_field"]


def lut_rom_init(plan: Plan, index: int, luts: list[int]) -> tuple[list[int], int]:
    """``(init, width)`` of the ROM shared by the ``luts`` read at node ``index``.

    Entry ``j`` (0 <= j <= index.hi) is the concatenation, first lut in the low bits, of
    ``table[j]`` of every lut, each its stored field (:func:`stored_field`: the low bits of
    its two's complement at the node's width); entries the index never takes (j < index.lo)
    hold 0 (they may not fit the field).
    """
    lo, hi = plan.nodes[index].lo, plan.nodes[index].hi
    init = [0] * (hi + 1)
    off = 0
    for li in luts:
        bits = stored_field(plan, li)[0]
        for j in range(lo, hi + 1):
            init[j] |= (plan.nodes[li].param[j] & ((1 << bits) - 1)) << off
        off += bits
    return init, off


def lut_fields(plan: Plan, luts: list[int], data) -> dict:
    """Each lut's value in ``data``, a word of the ROM :func:`lut_rom_init` lays out for
    ``luts``: its stored field under its constant top bits, sign-restored for a signed node."""
    fields, off = {}, 0
    for li in luts:
        n = plan.nodes[li]
        bits, top = stored_field(plan, li)
        f = Cat(data[off:off + bits], Const(top, n.width - bits))
        fields[li] = f.as_signed() if n.signed else f
        off += bits
    return fields


def input_layout(plan: Plan) -> data.StructLayout:
    """One field per plan input: the port integer (value * 2**frac)."""
    return data.StructLayout({i.name: signed(i.width) if i.signed else unsigned(i.width) for i in plan.inputs})


def output_layout(plan: Plan) -> data.StructLayout:
    """One field per output: pulse width in PWM clock ticks."""
    return data.StructLayout({o.name: node_shape(plan.nodes[o.node]) for o in plan.outputs})


def node_expression(n, ops):
    """The value of plan node ``n`` as an Amaranth expression of its operands' values ``ops``
    (its op's ``rtl`` in :data:`ikseries.fit.ops.OPS`); the caller registers it or not."""
    rtl = OPS[n.op].rtl
    if rtl is None:
        raise ValueError(f"plan node operation {n.op!r} has no expression here")
    return rtl(n, ops)


class PlanEvaluator(wiring.Component):
    """Evaluates every output of ``plan`` for a stream of inputs.

    Each registered plan operation (add, mul, clamp, lut) is one pipeline stage;
    shifts, binary-point changes, ``index`` (a shift) and ``mask`` (the low bits)
    are wiring. The ``lut`` nodes that share an index node are one ROM
    (``Memory`` with ``init``, a block RAM where the FPGA has one; see
    :func:`lut_rom_init`): one word per index value, the tables side by side,
    read by one synchronous port addressed by the index and enabled with the
    pipeline, so the ROM read is that stage's register. Operands computed early are
    delayed to meet their consumers; every width comes from the plan's interval
    analysis, so no in-range input overflows (out-of-range inputs are clamped
    to the workspace by the plan's first stage).

    Parameters
    ----------
    plan : Plan

    Attributes
    ----------
    i : In(stream.Signature(input_layout(plan)))
    o : Out(stream.Signature(output_layout(plan)))

    Latency
    -------
    ``latency`` cycles (``plan.depth``) from an input transfer to its output
    transfer when ``o.ready`` is high.

    Throughput
    ----------
    One input per cycle. When ``o.valid`` is high and ``o.ready`` low, the whole
    pipeline stalls (lut ROM read ports included: their ``en`` is the pipeline
    enable) and ``i.ready`` is low.
    """

    def __init__(self, plan: Plan):
        if not isinstance(plan, Plan):
            raise TypeError(f"plan must be a Plan, not {plan!r}")
        if not plan.outputs:
            raise ValueError("plan must have at least one output")
        self._plan = plan
        super().__init__({
            "i": In(stream.Signature(input_layout(plan))),
            "o": Out(stream.Signature(output_layout(plan))),
        })

    @property
    def plan(self) -> Plan:
        return self._plan

    @property
    def latency(self) -> int:
        return self._plan.depth

    @property
    def initiation_interval(self) -> int:
        """Cycles between accepted inputs when never stalled: 1 (fully pipelined)."""
        return 1

    def elaborate(self, platform):
        m = Module()
        plan = self._plan
        stages = plan.stages()
        lat = plan.depth
        en = Signal()
        m.d.comb += [en.eq(~self.o.valid | self.o.ready), self.i.ready.eq(en)]

        vals: list = []
        delayed: dict = {}
        groups = lut_groups(plan)
        lut_field: dict = {}      # lut node -> its field of its ROM's read data

        def at(idx, stage):
            """Value of node ``idx`` delayed so that it is valid at ``stage``."""
            have = stages[idx]
            if OPS[plan.nodes[idx].op].kind == "constant" or have >= stage:
                return vals[idx]
            key = (idx, stage)
            if key not in delayed:
                prev = at(idx, stage - 1)
                reg = Signal(node_shape(plan.nodes[idx]), name=f"n{idx}_d{stage}")
                with m.If(en):
                    m.d.sync += reg.eq(prev)
                delayed[key] = reg
            return delayed[key]

        live = plan.live()
        for idx, n in enumerate(plan.nodes):
            op = OPS[n.op]
            if idx not in live and op.kind != "port":    # a sum only the certifier reads
                vals.append(None)
                continue
            if op.kind == "constant":
                vals.append(node_expression(n, []))
                continue
            sig = Signal(node_shape(n), name=f"n{idx}_{n.op}")
            if op.kind == "port":
                with m.If(en):
                    m.d.sync += sig.eq(self.i.payload[n.param])
                vals.append(sig)
                continue
            s = stages[idx]
            ops = [at(a, s - 1 if op.registered else s) for a in n.args]
            if op.kind == "table":
                if idx not in lut_field:
                    lut_field.update(self._lut_rom(m, en, n.args[0], groups[n.args[0]], ops[0]))
                expr = lut_field[idx]
            else:
                expr = node_expression(n, ops)
            if op.registered and op.kind != "table":   # a table: the ROM port registers
                with m.If(en):
                    m.d.sync += sig.eq(expr)
            else:
                m.d.comb += sig.eq(expr)
            vals.append(sig)

        valid = Signal(lat, name="valid")   # valid[k]: stage k + 1 holds a real input
        with m.If(en):
            m.d.sync += valid.eq(Cat(self.i.valid, valid[:lat - 1]))
        m.d.comb += self.o.valid.eq(valid[lat - 1])
        for o in plan.outputs:
            m.d.comb += self.o.payload[o.name].eq(at(o.node, lat))
        return m

    def _lut_rom(self, m, en, index, luts, addr) -> dict:
        """ROM of the ``luts`` read at node ``index`` (address ``addr``, valid the stage
        before them), one field per lut node, sign-restored for signed nodes."""
        plan = self._plan
        init, width = lut_rom_init(plan, index, luts)
        rom = Memory(shape=unsigned(width), depth=len(init), init=init)
        m.submodules[f"lut{index}"] = rom
        port = rom.read_port(domain="sync")
        m.d.comb += [port.addr.eq(addr), port.en.eq(en)]
        return lut_fields(plan, luts, port.data)

