"""The evaluation plan: the single source of truth for the golden model and the RTL.

A plan is a list of integer operations in topological order (a dataflow graph).
Every node holds an integer; its real value is ``integer * 2**-frac``. Every node
carries the integer interval it can take for any in-range input, computed by
interval arithmetic, from which its bit width and signedness follow, so that no
in-range input can overflow any intermediate.

Operations
----------
``input``  a port field (already clamped to its range by a ``clamp`` node after it)
``const``  an integer constant; ``ideal`` keeps the real value it was rounded from
``add``    a + b (operands have equal ``frac``)            registered
``mul``    a * b (``frac`` = frac(a) + frac(b))            registered
``clamp``  min(max(a, lo), hi)                             registered
``shr``    floor(a / 2**s) (arithmetic shift right)        wiring only
``shl``    a * 2**s                                        wiring only
``frac``   same integer, new binary point (``reinterpret``)  wiring only
``index``  floor(a / 2**s), 0 fractional bits: a table index  wiring only
``mask``   a mod 2**s (the low s bits), same ``frac``          wiring only
``lut``    table[a]: a constant per index (``param`` the integers,
           ``ideal`` the real values they were rounded from)  registered

``index`` and ``mask`` cut an exact value (an input port, offset) into a cell number and the
offset inside the cell: a piecewise plan looks its coefficients up by cell with ``lut``. Their
ideal (real) value is the same floor / remainder of the ideal argument, so within one cell the
offset is an exact affine function of the input.

Registered operations take one pipeline stage; wiring-only ones take none.
"""
from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field

__all__ = ["quantize", "extend_stages", "Node", "PlanInput", "PlanOutput", "Plan", "PlanBuilder", "bits_for",
           "signed_bits", "PLAN_FORMAT",
           "PLAN_VERSION", "REGISTERED_OPS"]

PLAN_FORMAT = "ikseries.plan"
PLAN_VERSION = 1
REGISTERED_OPS = frozenset({"add", "mul", "clamp", "lut"})
_OPS = {"input": 0, "const": 0, "add": 2, "mul": 2, "clamp": 1, "shr": 1, "shl": 1, "frac": 1,
        "index": 1, "mask": 1, "lut": 1}


def quantize(value: float, frac: int) -> int:
    """Nearest integer to ``value * 2**frac``: a constant with ``frac`` fractional bits."""
    return int(round(value * 2.0 ** frac))


def extend_stages(nodes: list["Node"], st: list[int]) -> list[int]:
    """Append to ``st`` (the stages of ``nodes[:len(st)]``) the stage of every later node
    (see :meth:`Plan.stages`); returns ``st``."""
    for n in nodes[len(st):]:
        if n.op == "const":
            st.append(0)
        elif n.op == "input":
            st.append(1)
        else:
            s = max([st[a] for a in n.args] + [0])
            st.append(s + 1 if n.op in REGISTERED_OPS else s)
    return st


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
    def latency(self) -> int:
        """Clock cycles from an input transfer to the transfer of its outputs (all aligned)."""
        st = self.stages()
        return max([1] + [st[o.node] for o in self.outputs])  # inputs are registered: >= 1

    def count(self, op: str) -> int:
        return sum(1 for n in self.nodes if n.op == op)

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
        :func:`ikseries.sim.golden.evaluate_ideal`). The bound is rigorous for
        every in-range input: it follows the interval of each node.
        """
        err: list[float] = []
        for n in self.nodes:
            sc = 2.0 ** -n.frac
            if n.op == "input":
                e = 0.0
            elif n.op == "const":
                e = abs(n.param * sc - n.ideal) if n.ideal is not None else 0.0
            elif n.op == "add":
                e = err[n.args[0]] + err[n.args[1]]
            elif n.op == "mul":
                a, b = (self.nodes[i] for i in n.args)
                ea, eb = err[n.args[0]], err[n.args[1]]
                ma = max(abs(a.lo), abs(a.hi)) * 2.0 ** -a.frac
                mb = max(abs(b.lo), abs(b.hi)) * 2.0 ** -b.frac
                e = ma * eb + mb * ea + ea * eb
            elif n.op == "shr":
                e = err[n.args[0]] + (1 - 2.0 ** -n.param) * sc
            elif n.op == "frac":  # same integer, real value scaled by 2**(frac(a) - frac)
                e = err[n.args[0]] * 2.0 ** (self.nodes[n.args[0]].frac - n.frac)
            elif n.op in ("index", "mask"):  # a cell of an exact value only: a rounded one
                e = 0.0 if err[n.args[0]] == 0.0 else float("inf")  # could pick another cell
            elif n.op == "lut":
                a = self.nodes[n.args[0]]
                e = 0.0 if n.ideal is None else max(
                    abs(n.param[i] * sc - n.ideal[i]) for i in range(a.lo, a.hi + 1))
            else:  # shl: exact; clamp: the ideal value is clamped too, and a clamp
                e = err[n.args[0]]  # never increases a distance (it is 1-Lipschitz)
            err.append(e)
        return err

    # -- serialisation -----------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "format": PLAN_FORMAT, "version": PLAN_VERSION,
            "inputs": [vars(i) for i in self.inputs],
            "outputs": [vars(o) for o in self.outputs],
            "latency": self.latency,
            "nodes": [self._node_json(i, n) for i, n in enumerate(self.nodes)],
            "meta": self.meta,
        }

    @staticmethod
    def _node_json(i: int, n: Node) -> dict:
        d = {"id": i, "op": n.op, "args": list(n.args), "frac": n.frac, "lo": n.lo, "hi": n.hi,
             "width": n.width, "signed": n.signed}
        if n.param is not None:
            d["param"] = list(n.param) if isinstance(n.param, tuple) else n.param
        if n.ideal is not None:
            d["ideal"] = list(n.ideal) if isinstance(n.ideal, tuple) else n.ideal
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Plan":
        if d.get("format") != PLAN_FORMAT:
            raise ValueError(f"plan format must be {PLAN_FORMAT!r}, not {d.get('format')!r}")
        if d.get("version") != PLAN_VERSION:
            raise ValueError(f"plan version must be {PLAN_VERSION}, not {d.get('version')!r}")
        b = PlanBuilder([PlanInput(**i) for i in d["inputs"]], with_inputs=False)
        for nd in d["nodes"]:
            param = nd.get("param")
            if isinstance(param, list):
                param = tuple(param)
            ideal = nd.get("ideal")
            if isinstance(ideal, list):
                ideal = tuple(ideal)
            b._append(nd["op"], tuple(nd["args"]), nd["frac"], param, ideal, share=False)
            n = b.nodes[-1]
            if (n.lo, n.hi) != (nd["lo"], nd["hi"]):
                raise ValueError(f"plan node {nd['id']}: stored interval [{nd['lo']}, {nd['hi']}] "
                                 f"does not match the recomputed [{n.lo}, {n.hi}]")
        plan = cls(b.inputs, b.nodes, [PlanOutput(**o) for o in d["outputs"]], d.get("meta", {}))
        if plan.latency != d.get("latency"):
            raise ValueError(f"plan latency {d.get('latency')!r} does not match the recomputed {plan.latency}")
        return plan

    def dumps(self) -> str:
        return json.dumps(self.to_json(), indent=1, sort_keys=True) + "\n"


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
        self.input_nodes = {}
        for i in self.inputs if with_inputs else ():
            raw = self._append("input", (), i.frac, i.name)
            self.input_nodes[i.name] = self.clamp(raw, i.lo, i.hi) if self._needs_clamp(i) else raw

    @staticmethod
    def _needs_clamp(i: PlanInput) -> bool:
        return i.port_range != (i.lo, i.hi)

    def _append(self, op, args, frac, param=None, ideal=None, share=True) -> int:
        if op not in _OPS or len(args) != _OPS[op]:
            raise ValueError(f"bad plan operation {op!r} with {len(args)} operands")
        key = (op, args, frac, param, ideal)
        if share and key in self._memo:
            return self._memo[key]
        a = [self.nodes[i] for i in args]
        if op == "input":
            lo, hi = next(i for i in self.inputs if i.name == param).port_range
        elif op == "const":
            lo = hi = int(param)
        elif op == "add":
            if a[0].frac != a[1].frac or frac != a[0].frac:
                raise ValueError("add operands must have equal fractional bits")
            lo, hi = a[0].lo + a[1].lo, a[0].hi + a[1].hi
        elif op == "mul":
            if frac != a[0].frac + a[1].frac:
                raise ValueError("mul result must have frac(a) + frac(b) fractional bits")
            p = [x * y for x in (a[0].lo, a[0].hi) for y in (a[1].lo, a[1].hi)]
            lo, hi = min(p), max(p)
            if args[0] == args[1]:  # a square is never negative
                lo = 0 if a[0].lo <= 0 <= a[0].hi else min(a[0].lo ** 2, a[0].hi ** 2)
        elif op == "clamp":
            clo, chi = param
            lo, hi = min(max(a[0].lo, clo), chi), max(min(a[0].hi, chi), clo)
        elif op == "shr":
            lo, hi = a[0].lo >> param, a[0].hi >> param
        elif op == "shl":
            lo, hi = a[0].lo << param, a[0].hi << param
        elif op == "index":
            if frac != 0:
                raise ValueError(f"index must have 0 fractional bits, not {frac}")
            lo, hi = a[0].lo >> param, a[0].hi >> param
        elif op == "mask":
            if frac != a[0].frac:
                raise ValueError("mask keeps the fractional bits of its operand")
            m = (1 << param) - 1
            lo, hi = (a[0].lo & m, a[0].hi & m) if a[0].lo >> param == a[0].hi >> param else (0, m)
        elif op == "lut":
            table = param
            if not (isinstance(table, tuple) and table and all(isinstance(v, int) for v in table)):
                raise ValueError(f"lut table must be a non-empty tuple of integers, not {table!r}")
            if ideal is not None and len(ideal) != len(table):
                raise ValueError(f"lut ideal values must be one per entry ({len(table)}), not {len(ideal)}")
            if a[0].frac != 0 or a[0].lo < 0 or a[0].hi >= len(table):
                raise ValueError(f"lut index must be an integer in [0, {len(table) - 1}], "
                                 f"not [{a[0].lo}, {a[0].hi}] with {a[0].frac} fractional bits")
            reach = table[a[0].lo:a[0].hi + 1]
            lo, hi = min(reach), max(reach)
        else:  # frac
            lo, hi = a[0].lo, a[0].hi
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
            self._memo = memo

    def stages(self) -> list[int]:
        """Pipeline stage of every node so far (see :meth:`Plan.stages`)."""
        return extend_stages(self.nodes, [])

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
            return self._append("shl", (a,), frac, frac - f)
        return self._append("shr", (a,), frac, f - frac)

    def add(self, a: int, b: int) -> int:
        if self.is_zero(a):
            return b
        if self.is_zero(b):
            return a
        f = max(self.frac(a), self.frac(b))
        return self._append("add", (self.align(a, f), self.align(b, f)), f)

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
        """Round half up to ``frac`` fractional bits."""
        f = self.frac(a)
        if frac >= f:
            return self.align(a, frac)
        half = self._append("const", (), f, 1 << (f - frac - 1))
        return self.align(self._append("add", (a, half), f), frac)

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

