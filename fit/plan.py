"""The evaluation plan: the single source of truth for the golden model and the RTL.

A plan is a list of integer operations in topological order (a dataflow graph).
Every node holds an integer; its real value is ``integer * 2**-frac``. Every node
carries the integer interval it can take for any in-range input, computed by
interval arithmetic, from which its bit width and signedness follow, so that no
in-range input can overflow any intermediate.

Operations
----------
``input const add mul clamp shr shl frac index mask lut``: their meaning (arity, intervals,
integer and ideal values, rounding bounds, JSON form, hardware kind) is the table
:data:`ikseries.fit.ops.OPS`. ``index`` and ``mask`` cut an exact value (an input port, offset)
into a cell number and the offset inside the cell: a piecewise plan looks its coefficients up
by cell with ``lut``.

Registered operations take one pipeline stage; wiring-only ones take none.
"""
from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field

from .ops import OPS, operation

__all__ = ["quantize", "extend_stages", "under", "Node", "PlanInput", "PlanOutput", "Plan", "PlanBuilder", "bits_for", "lut_groups",
           "signed_bits", "stored_field", "PLAN_FORMAT",
           "PLAN_VERSION", "READABLE_VERSIONS", "REGISTERED_OPS"]

PLAN_FORMAT = "ikseries.plan"
PLAN_VERSION = 2
#: plan versions :meth:`Plan.from_json` reads: 1 stored the pipeline depth as "latency", a
#: name that misled for any architecture but the fully pipelined one
READABLE_VERSIONS = (1, 2)
#: the registered operations with operands (from :data:`ikseries.fit.ops.OPS`)
REGISTERED_OPS = frozenset(name for name, op in OPS.items() if op.registered and op.arity)


def quantize(value: float, frac: int) -> int:
    """Nearest integer to ``value * 2**frac``: a constant with ``frac`` fractional bits."""
    return int(round(value * 2.0 ** frac))


def extend_stages(nodes: list["Node"], st: list[int]) -> list[int]:
    """Append to ``st`` (the stages of ``nodes[:len(st)]``) the stage of every later node
    (see :meth:`Plan.stages`); returns ``st``."""
    for n in nodes[len(st):]:   # an input is registered (stage 1), a constant is not (0)
        st.append(max([st[a] for a in n.args] + [0]) + OPS[n.op].registered)
    return st


def under(nodes: list["Node"], a: int, ops: tuple[str, ...]) -> int:
    """The node under node ``a``'s chain of single-operand ``ops`` (``a`` itself if it is none)."""
    while nodes[a].op in ops:
        a = nodes[a].args[0]
    return a


def lut_groups(plan: "Plan") -> dict[int, list[int]]:
    """The live (:meth:`Plan.live`) ``lut`` nodes by index node (in plan order): the tables
    one ROM holds side by side."""
    groups: dict[int, list[int]] = {}
    live = plan.live()
    for idx, n in enumerate(plan.nodes):
        if OPS[n.op].kind == "table" and idx in live:
            groups.setdefault(n.args[0], []).append(idx)
    return groups


def stored_field(plan: "Plan", li: int) -> tuple[int, int]:
    """``(bits, top)``: the low ``bits`` of lut ``li``'s entries (two's complement at its node
    width) are stored in its ROM; the rest, ``top``, is the same in every entry its index
    reaches, and is wiring (FloPoCo's constant sign bits not stored: a table of negative
    values, or one far from 0, keeps only the bits that vary). At least one bit is stored.
    Here beside :func:`lut_groups` because the fitter's cost model prices the ROMs the
    evaluators lay out (:mod:`ikseries.hdl.evaluator`)."""
    n = plan.nodes[li]
    ix, w = plan.nodes[n.args[0]], n.width
    words = {v & ((1 << w) - 1) for v in n.param[ix.lo:ix.hi + 1]}
    bits = w
    while bits > 1 and len({v >> (bits - 1) for v in words}) == 1:
        bits -= 1
    return bits, next(iter(words)) >> bits


def bits_for(lo: int, hi: int) -> tuple[int, bool]:
    """Smallest (width, signed) holding every integer in [lo, hi]."""
    if lo >= 0:
        return max(1, int(hi).bit_length()), False
    w = max((-lo - 1).bit_length(), max(hi, 0).bit_length()) + 1
    return w, True


def signed_bits(lo: int, hi: int) -> int:
    """Two's complement width holding every integer in [lo, hi] (a signed operand)."""
    w, signed = bits_for(lo, hi)
    return w if signed else w + 1


@dataclass(frozen=True)
class Node:
    op: str
    args: tuple[int, ...]
    frac: int
    lo: int
    hi: int
    param: object = None        # input name | const value | shift | (lo, hi) for clamp | lut table
    ideal: float | tuple | None = None  # const / lut only: real value(s) before rounding

    @property
    def width(self) -> int:
        return bits_for(self.lo, self.hi)[0]

    @property
    def signed(self) -> bool:
        return bits_for(self.lo, self.hi)[1]

    @property
    def signed_width(self) -> int:
        """Bits of the value as a signed operand (an unsigned value needs one more)."""
        return signed_bits(self.lo, self.hi)


@dataclass(frozen=True)
class PlanInput:
    name: str       # field name (port suffix)
    unit: str
    frac: int       # fractional bits of the port integer
    lo: int         # in-range integer bounds
    hi: int
    width: int      # port width
    signed: bool

    @property
    def port_range(self) -> tuple[int, int]:
        """Every integer the port can carry (in range or not)."""
        if self.signed:
            return -(1 << (self.width - 1)), (1 << (self.width - 1)) - 1
        return 0, (1 << self.width) - 1


@dataclass(frozen=True)
class PlanOutput:
    name: str        # servo name (port suffix)
    node: int        # node holding the final integer (PWM clock ticks)
    preround: int    # node holding the value before the final rounding
    unit: str        # "ticks"
    ticks_per_pu: float


@dataclass
class Plan:
    inputs: list[PlanInput]
    nodes: list[Node]
    outputs: list[PlanOutput]
    meta: dict = field(default_factory=dict)

    # -- pipeline ------------------------------------------------------------
    def stages(self) -> list[int]:
        """Pipeline stage of every node: the number of clock edges after an input transfer at
        which the node's value is valid (inputs are registered: 1; constants: 0)."""
        return extend_stages(self.nodes, [])

    @property
    def depth(self) -> int:
        """Pipeline depth of the dataflow: the stage of the latest output (all aligned). It is the
        latency of the fully pipelined evaluator only; every architecture states its own
        latency (:meth:`ikseries.hdl.architectures.Architecture.timing`)."""
        st = self.stages()
        return max([1] + [st[o.node] for o in self.outputs])  # inputs are registered: >= 1

    def count(self, op: str) -> int:
        """Nodes of operation ``op`` that hardware evaluates (:meth:`live`)."""
        return sum(1 for i in self.live() if self.nodes[i].op == op)

    def live(self) -> set[int]:
        """The nodes the outputs need: hardware evaluates these only. The rest are sums only
        the certifier reads, an output's accumulator before its rounding constant moved
        into it (:meth:`PlanBuilder.round`), and the table it summed before that constant
        joined the table's entries."""
        return set().union(*(self.cone(o.node) for o in self.outputs))

    def cone(self, node: int) -> set[int]:
        """Indices of the nodes that ``node`` depends on (itself included)."""
        seen, todo = set(), [node]
        while todo:
            i = todo.pop()
            if i not in seen:
                seen.add(i)
                todo.extend(self.nodes[i].args)
        return seen

    # -- certified quantization bound -----------------------------------------
    def rounding_bounds(self) -> list[float]:
        """Bound on |integer value - ideal real value| of every node, as a real number.

        The ideal value is the same dataflow evaluated in exact real arithmetic
        with unrounded constants and no truncating shifts (see
        :func:`ikseries.sim.golden.evaluate_ideal`), except that cells of a rounded
        value (a feature cut) are those of its integer value: the ideal index and mask are
        the integer argument's cell and the ideal argument's offset from it, as the
        certifier's case split takes them. The bound is rigorous for every in-range input:
        it follows the interval of each node.
        """
        err: list[float] = []
        for n in self.nodes:
            err.append(OPS[n.op].rounding(n, [self.nodes[a] for a in n.args], [err[a] for a in n.args]))
        return err

    # -- serialisation -----------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "format": PLAN_FORMAT, "version": PLAN_VERSION,
            "inputs": [vars(i) for i in self.inputs],
            "outputs": [vars(o) for o in self.outputs],
            "depth": self.depth,
            "nodes": [self._node_json(i, n) for i, n in enumerate(self.nodes)],
            "meta": self.meta,
        }

    @staticmethod
    def _node_json(i: int, n: Node) -> dict:
        d = {"id": i, "op": n.op, "args": list(n.args), "frac": n.frac, "lo": n.lo, "hi": n.hi,
             "width": n.width, "signed": n.signed}
        op = OPS[n.op]
        if n.param is not None:
            d["param"] = op.param.encode(n.param)
        if n.ideal is not None:
            d["ideal"] = op.ideal.encode(n.ideal)
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Plan":
        if d.get("format") != PLAN_FORMAT:
            raise ValueError(f"plan format must be {PLAN_FORMAT!r}, not {d.get('format')!r}")
        if d.get("version") not in READABLE_VERSIONS:
            raise ValueError(f"plan version must be one of {', '.join(map(str, READABLE_VERSIONS))}, "
                             f"not {d.get('version')!r}")
        b = PlanBuilder([PlanInput(**i) for i in d["inputs"]], with_inputs=False)
        for nd in d["nodes"]:
            op = operation(nd["op"], len(nd["args"]))
            param = _decode(nd, "param", op.param)
            ideal = _decode(nd, "ideal", op.ideal)
            b._append(nd["op"], tuple(nd["args"]), nd["frac"], param, ideal, share=False)
            n = b.nodes[-1]
            if (n.lo, n.hi) != (nd["lo"], nd["hi"]):
                raise ValueError(f"plan node {nd['id']}: stored interval [{nd['lo']}, {nd['hi']}] "
                                 f"does not match the recomputed [{n.lo}, {n.hi}]")
        plan = cls(b.inputs, b.nodes, [PlanOutput(**o) for o in d["outputs"]], d.get("meta", {}))
        key = "latency" if d["version"] == 1 else "depth"
        if plan.depth != d.get(key):
            raise ValueError(f"plan {key} {d.get(key)!r} does not match the recomputed {plan.depth}")
        return plan

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=1, sort_keys=True) + "\n"


def _decode(nd: dict, key: str, codec):
    """Field ``key`` of a plan node's JSON through its op's ``codec`` (None if absent)."""
    if nd.get(key) is None:
        return None
    try:
        return codec.decode(nd[key])
    except ValueError as e:
        raise ValueError(f"plan node {nd['id']}: the {key} of a {nd['op']} node {e}") from None


class PlanBuilder:
    """Appends nodes with their intervals; structurally identical nodes are shared.

    With ``operand_bits = (p, q)`` every multiplication's operands fit one ``p`` x ``q`` signed
    DSP multiplier (the wider operand gets the wider port): :meth:`mul` first drops the low
    bits of an operand that is too wide (a ``shr``; a constant or table is rounded again from
    its ideal values instead; a clamp to multiples of the dropped bits clamps the narrowed value,
    the same integers on fewer bits), so the plan never needs a product split into limbs. The
    extra rounding is part of the plan, so the certified bound includes it.
    """

    def __init__(self, inputs: list[PlanInput], with_inputs: bool = True,
                 operand_bits: tuple[int, int] | None = None):
        if operand_bits is not None and not (
                isinstance(operand_bits, tuple) and len(operand_bits) == 2
                and all(isinstance(w, int) and not isinstance(w, bool) and w >= 2 for w in operand_bits)):
            raise ValueError(f"operand_bits must be None or a pair of signed widths >= 2 such as (18, 18), "
                             f"not {operand_bits!r}")
        self.operand_bits = operand_bits
        self.inputs = list(inputs)
        self.nodes: list[Node] = []
        self._memo: dict[tuple, int] = {}
        self._stages: list[int] = []       # of nodes[:len(_stages)], extended on demand
        self.input_nodes = {}
        for i in self.inputs if with_inputs else ():
            raw = self._append("input", (), i.frac, i.name)
            self.input_nodes[i.name] = self.clamp(raw, i.lo, i.hi) if self._needs_clamp(i) else raw

    @staticmethod
    def _needs_clamp(i: PlanInput) -> bool:
        return i.port_range != (i.lo, i.hi)

    def op(self, op: str, args: tuple[int, ...], frac: int, param=None, ideal=None) -> int:
        """Append (or share) a node of any operation of :data:`ikseries.fit.ops.OPS`."""
        return self._append(op, tuple(args), frac, param, ideal)

    def _append(self, op, args, frac, param=None, ideal=None, share=True) -> int:
        spec = operation(op, len(args))
        key = (op, args, frac, param, ideal)
        if share and key in self._memo:
            return self._memo[key]
        lo, hi = spec.bounds([self.nodes[i] for i in args], frac, param, ideal, self.inputs)
        if max(abs(lo), abs(hi)) >= 1 << 62:
            raise OverflowError(f"plan node {op} needs more than 63 bits (interval [{lo}, {hi}])")
        self.nodes.append(Node(op, tuple(args), frac, lo, hi, param, ideal))
        self._memo[key] = len(self.nodes) - 1
        return len(self.nodes) - 1

    @contextlib.contextmanager
    def trial(self):
        """A scratch evaluation: nodes appended inside the ``with`` block are discarded on exit
        (as is their structural sharing), so alternative lowerings can be built and measured."""
        n, memo = len(self.nodes), dict(self._memo)
        try:
            yield self
        finally:
            del self.nodes[n:]
            del self._stages[n:]
            self._memo = memo

    def stages(self) -> list[int]:
        """Pipeline stage of every node so far (see :meth:`Plan.stages`)."""
        return list(extend_stages(self.nodes, self._stages))

    def stage(self, a: int) -> int:
        """Pipeline stage of node ``a`` (see :meth:`Plan.stages`)."""
        return extend_stages(self.nodes, self._stages)[a]

    # -- helpers ---------------------------------------------------------------
    def const(self, value: float, frac: int) -> int:
        """Constant rounded to ``frac`` fractional bits (ideal value kept for the error bound)."""
        q = quantize(value, frac)
        ideal = None if q == value * 2.0 ** frac else float(value)
        return self._append("const", (), frac, q, ideal)

    def frac(self, a: int) -> int:
        return self.nodes[a].frac

    def is_zero(self, a: int) -> bool:
        n = self.nodes[a]
        return n.op == "const" and n.param == 0

    def reinterpret(self, a: int, frac: int) -> int:
        """Same integer, real value scaled by 2**(frac(a) - frac)."""
        return a if frac == self.frac(a) else self._append("frac", (a,), frac)

    def align(self, a: int, frac: int) -> int:
        """Change the binary point to ``frac`` bits (exact when widening, floor when narrowing)."""
        f = self.frac(a)
        if f == frac:
            return a
        if frac > f:
            n = self.nodes[a]
            if n.op == "const":     # exact: the same constant with more fractional bits
                return self._append("const", (), frac, n.param << (frac - f), n.ideal)
            return self._append("shl", (a,), frac, frac - f)
        return self._append("shr", (a,), frac, f - frac)

    def add(self, a: int, b: int) -> int:
        if self.is_zero(a):
            return b
        if self.is_zero(b):
            return a
        f = max(self.frac(a), self.frac(b))
        a, b = self.align(a, f), self.align(b, f)
        for rule in (self._into_table, self._fold_constants, self._latest_last,
                     self._before_shift):   # either operand may be the sum
            for x, y in ((a, b), (b, a)):
                if (folded := rule(x, y)) is not None:
                    return folded
        return self._append("add", (a, b), f)

    def _latest_last(self, a: int, b: int) -> int | None:
        """``(x + y) + b`` as ``(x + b) + y`` when ``y`` is ready last (a product, say): the
        earlier terms are summed while it is computed, one stage sooner; the same integers,
        adders and rounding bound (additions are exact)."""
        n = self.nodes[a]
        if n.op != "add":
            return None
        for x, y in (n.args, n.args[::-1]):
            if self._later(y, x, self.nodes[b].op == "const") and self.stage(y) > self.stage(b):
                return self.add(self.add(x, b), y)
        return None

    def _later(self, y: int, x: int, ties: bool) -> bool:
        """Node ``y`` is ready after ``x``: a later stage, or with ``ties`` the same stage and
        a product where ``x`` is not (a multiplier takes longer than an adder in every
        architecture; a constant added to ``x`` there never costs a stage)."""
        sy, sx = self.stage(y), self.stage(x)
        return sy > sx or (ties and sy == sx and self._product(y) and not self._product(x))

    def _product(self, a: int) -> bool:
        """Node ``a`` is a product under shifts and binary point moves."""
        return self.nodes[under(self.nodes, a, ("frac", "shr", "shl"))].op == "mul"

    def _into_table(self, a: int, b: int) -> int | None:
        """A constant ``c`` (a rounding half, say) added to a sum that holds a table read
        ``lut(i)`` (through additions on the sum's binary point) is stored in the table:
        ``lut'(i) = lut(i) + c``, FloPoCo's trick. Its adder and any stage it would cost are
        gone; the same integers, the ideal values summed. The sum's additions above the table
        are rebuilt over ``lut'``."""
        c = self.nodes[b]
        if c.op != "const" or (path := self._table_path(a, c.frac)) is None:
            return None
        t = self.nodes[path[-1]]
        q = tuple(v + c.param for v in t.param)
        ideal = None
        if t.ideal is not None or c.ideal is not None:
            scale = 2.0 ** -c.frac
            cv = c.ideal if c.ideal is not None else c.param * scale
            ideal = tuple((v * scale if t.ideal is None else t.ideal[k]) + cv for k, v in enumerate(t.param))
            ideal = None if all(x == v * scale for x, v in zip(ideal, q)) else ideal
        new = self._append("lut", t.args, t.frac, q, ideal)
        for node, child in zip(reversed(path[:-1]), reversed(path[1:])):
            args = list(self.nodes[node].args)
            args[args.index(child)] = new            # one operand only: x + x holds c once
            new = self._append("add", tuple(args), self.frac(node))
        return new

    def _table_path(self, a: int, frac: int) -> list[int] | None:
        """Nodes from ``a`` down to a table read on binary point ``frac`` through additions on
        it (first operands first), or None."""
        n = self.nodes[a]
        if n.frac != frac:
            return None
        if n.op == "lut":
            return [a]
        if n.op == "add":
            for x in n.args:
                if (path := self._table_path(x, frac)) is not None:
                    return [a, *path]
        return None

    def _fold_constants(self, a: int, b: int) -> int | None:
        """``(x + c1) + c2`` as ``x + (c1 + c2)``: one adder (and one pipeline stage) fewer, the
        same integers; the constants' rounding errors add up at most (ideal values summed)."""
        n, c2 = self.nodes[a], self.nodes[b]
        if c2.op != "const" or n.op != "add":
            return None
        consts = [k for k in (1, 0) if self.nodes[n.args[k]].op == "const"]
        if not consts:
            return None
        x, c1 = n.args[1 - consts[0]], self.nodes[n.args[consts[0]]]
        if c1.frac != c2.frac:
            return None
        scale = 2.0 ** -c2.frac
        param = c1.param + c2.param
        ideal = None
        if c1.ideal is not None or c2.ideal is not None:
            ideal = sum(c.ideal if c.ideal is not None else c.param * scale for c in (c1, c2))
            ideal = None if ideal == param * scale else ideal
        return self.add(x, self._append("const", (), c2.frac, param, ideal))

    def _before_shift(self, a: int, b: int) -> int | None:
        """A constant added after a binary point move or a floor shift of a sum is added to the
        sum: ``frac(y) + c`` is ``frac(y + c)`` (the same integers) and ``(y >> s) + c`` is
        ``(y + c * 2**s) >> s`` (floor((y + c 2**s) / 2**s) = floor(y / 2**s) + c), so the
        constant joins the sum's own (one adder and pipeline stage fewer, same integers)."""
        n, c, base = self.nodes[a], self.nodes[b], under(self.nodes, a, ("frac", "shr"))
        if c.op != "const" or base == a or self.nodes[base].op != "add":
            return None
        y = n.args[0]
        fy = self.frac(y)
        if n.op == "shr":      # the same real constant, on the sum's finer binary point
            k = self._append("const", (), fy, c.param << n.param, c.ideal)
            return self.align(self.add(y, k), c.frac)
        scale = 2.0 ** (c.frac - fy)    # frac: the same integer, the real value rescaled
        k = self._append("const", (), fy, c.param, None if c.ideal is None else c.ideal * scale)
        return self.reinterpret(self.add(y, k), c.frac)

    def mul(self, a: int, b: int, frac: int | None = None) -> int:
        """Product, truncated (floor) to ``frac`` fractional bits if given (operands first
        narrowed to ``operand_bits``, if set)."""
        if self.operand_bits is not None:
            a, b = self._fit_operands(a, b)
        p = self._append("mul", (a, b), self.frac(a) + self.frac(b))
        return p if frac is None else self.align(p, frac)

    def signed_width(self, a: int) -> int:
        """Bits of node ``a`` as a signed operand (:attr:`Node.signed_width`)."""
        return self.nodes[a].signed_width

    def _fit_operands(self, a: int, b: int) -> tuple[int, int]:
        wide, narrow = max(self.operand_bits), min(self.operand_bits)
        if a == b:                       # a square: narrow once, keep the operands equal
            a = self._narrow(a, narrow)
            return a, a
        if self.signed_width(a) >= self.signed_width(b):
            return self._narrow(a, wide), self._narrow(b, narrow)
        return self._narrow(a, narrow), self._narrow(b, wide)

    def _narrow(self, a: int, bits: int) -> int:
        """``a`` with low bits dropped until it is at most ``bits`` signed bits wide."""
        while (w := self.signed_width(a)) > bits:
            n, f = self.nodes[a], self.frac(a) - (w - bits)
            if n.op == "const":
                a = self.const(n.ideal if n.ideal is not None else n.param * 2.0 ** -n.frac, f)
            elif n.op == "lut":
                ideal = n.ideal if n.ideal is not None else tuple(v * 2.0 ** -n.frac for v in n.param)
                a = self.lut(n.args[0], ideal, f)
            elif n.op == "clamp" and all(v % (1 << (w - bits)) == 0 for v in n.param):
                # floor commutes with a clamp to multiples of 2**s: clamp the narrow value
                sh = w - bits
                a = self.clamp(self.align(n.args[0], f), n.param[0] >> sh, n.param[1] >> sh)
            else:
                a = self.align(a, f)
        return a

    def clamp(self, a: int, lo: int, hi: int) -> int:
        n = self.nodes[a]
        if n.lo >= lo and n.hi <= hi:
            return a
        return self._append("clamp", (a,), n.frac, (int(lo), int(hi)))

    def cell(self, a: int, shift: int) -> tuple[int, int]:
        """(cell number, offset inside the cell) of the exact value ``a`` cut every 2**shift integers."""
        return self._append("index", (a,), 0, shift), self._append("mask", (a,), self.frac(a), shift)

    def lut(self, index: int, values, frac: int) -> int:
        """Per index, ``values[index]`` rounded to ``frac`` fractional bits (ideal values kept)."""
        q = tuple(quantize(v, frac) for v in values)
        exact = all(qi == v * 2.0 ** frac for qi, v in zip(q, values))
        return self._append("lut", (index,), frac, q, None if exact else tuple(float(v) for v in values))

    def round(self, a: int, frac: int) -> int:
        """Round half up to ``frac`` fractional bits. The half joins the sum ``a`` where it
        waits for no product (:meth:`add`'s rules), so ``a`` itself may be left to the
        certifier alone (:func:`ikseries.fit.certify.output_rounding`): hardware evaluates
        the outputs' cones only."""
        f = self.frac(a)
        if frac >= f:
            return self.align(a, frac)
        half = self._append("const", (), f, 1 << (f - frac - 1))
        return self.align(self.add(a, half), frac)

    def build(self, outputs: list[PlanOutput], meta: dict | None = None) -> Plan:
        """Keep only the nodes the outputs need and renumber them."""
        keep = set()
        plan = Plan(self.inputs, self.nodes, outputs, {})
        for o in outputs:
            keep |= plan.cone(o.node) | plan.cone(o.preround)
        # inputs always stay (they are ports)
        keep |= {i for i, n in enumerate(self.nodes) if n.op == "input"}
        order = sorted(keep)
        remap = {old: new for new, old in enumerate(order)}
        nodes = [Node(n.op, tuple(remap[a] for a in n.args), n.frac, n.lo, n.hi, n.param, n.ideal)
                 for n in (self.nodes[i] for i in order)]
        outs = [PlanOutput(o.name, remap[o.node], remap[o.preround], o.unit, o.ticks_per_pu) for o in outputs]
        return Plan(self.inputs, nodes, outs, dict(meta or {}))

