"""Pipelined fixed-point evaluator generated from an evaluation plan."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fit.plan import REGISTERED_OPS, Plan

__all__ = ["PlanEvaluator", "input_layout", "output_layout"]


def _shape(node):
    return signed(node.width) if node.signed else unsigned(node.width)


def input_layout(plan: Plan) -> data.StructLayout:
    """One field per plan input: the port integer (value * 2**frac)."""
    return data.StructLayout({i.name: signed(i.width) if i.signed else unsigned(i.width) for i in plan.inputs})


def output_layout(plan: Plan) -> data.StructLayout:
    """One field per output: pulse width in PWM clock ticks."""
    return data.StructLayout({o.name: _shape(plan.nodes[o.node]) for o in plan.outputs})


class PlanEvaluator(wiring.Component):
    """Evaluates every output of ``plan`` for a stream of inputs.

    Each registered plan operation (add, mul, clamp) is one pipeline stage;
    shifts and binary-point changes are wiring. Operands computed early are
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
    ``latency`` cycles (``plan.latency``) from an input transfer to its output
    transfer when ``o.ready`` is high.

    Throughput
    ----------
    One input per cycle. When ``o.valid`` is high and ``o.ready`` low, the whole
    pipeline stalls and ``i.ready`` is low.
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
        return self._plan.latency

    @property
    def initiation_interval(self) -> int:
        """Cycles between accepted inputs when never stalled: 1 (fully pipelined)."""
        return 1

    def elaborate(self, platform):
        m = Module()
        plan = self._plan
        stages = plan.stages()
        lat = plan.latency
        en = Signal()
        m.d.comb += [en.eq(~self.o.valid | self.o.ready), self.i.ready.eq(en)]

        vals: list = []
        delayed: dict = {}

        def at(idx, stage):
            """Value of node ``idx`` delayed so that it is valid at ``stage``."""
            have = stages[idx]
            if plan.nodes[idx].op == "const" or have >= stage:
                return vals[idx]
            key = (idx, stage)
            if key not in delayed:
                prev = at(idx, stage - 1)
                reg = Signal(_shape(plan.nodes[idx]), name=f"n{idx}_d{stage}")
                with m.If(en):
                    m.d.sync += reg.eq(prev)
                delayed[key] = reg
            return delayed[key]

        for idx, n in enumerate(plan.nodes):
            shape = _shape(n)
            if n.op == "const":
                vals.append(Const(n.param, shape))
                continue
            sig = Signal(shape, name=f"n{idx}_{n.op}")
            if n.op == "input":
                with m.If(en):
                    m.d.sync += sig.eq(self.i.payload[n.param])
                vals.append(sig)
                continue
            s = stages[idx]
            ops = [at(a, s - 1 if n.op in REGISTERED_OPS else s) for a in n.args]
            if n.op == "add":
                expr = ops[0] + ops[1]
            elif n.op == "mul":
                expr = ops[0] * ops[1]
            elif n.op == "clamp":
                lo, hi = n.param
                expr = Mux(ops[0] < lo, lo, Mux(ops[0] > hi, hi, ops[0]))
            elif n.op == "shr":
                expr = ops[0] >> n.param
            elif n.op == "shl":
                expr = ops[0] << n.param
            else:  # frac: same integer
                expr = ops[0]
            if n.op in REGISTERED_OPS:
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

