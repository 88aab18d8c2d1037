"""Folding an evaluation plan onto a few functional units: lowering, list scheduling,
slot allocation and horizontal microcode for :class:`ikseries.hdl.folded.FoldedEvaluator`.

The machine (see ``folded.py``) has one value memory (constants pre-loaded, intermediates
written back), two read ports, one write port, one ALU (add / max / min / pass / and), ``k``
multiplier units and, when the plan has ``lut`` nodes, one coefficient-table ROM. Every cycle
it executes one microcode word, which says what every stage does in that cycle; all timing
lives here, in the compiler.

Lowering
--------
Wiring nodes whose op is a pure shift (a ``view`` in :data:`ikseries.fit.ops.OPS`: ``shr``,
``shl``, ``frac`` and ``index``, which is a ``shr``) disappear into *views*: every operand of a
registered node (or of a ``mask``) is ``(base >> a) << b`` of a registered node, a ``mask``, an
input or a constant (a chain of shifts always reduces to that form, exactly, with floor
semantics). A result is transformed into its view on the way into the memory (one shifter on
the write port, none on the read ports). A base with several views stores ``base >> min(a)``
and derives the other views with ALU ``pass`` operations; constants are folded at compile time;
each input view is written from the input register by a ``load``; ``clamp(x, lo, hi)`` becomes
``min(max(x, lo), hi)`` (bounds narrowed to the operand's interval, which changes no result);
``mask(x, s)`` becomes the ALU ``and`` of ``x`` with the constant ``2**s - 1`` (two's
complement low bits: the exact non-negative remainder), these ALU microprograms are
``ALU_PROGRAMS``; every ``lut`` node becomes one ``lut`` operation that reads its index from
the memory and looks it up in its own table of the ROM.

Coefficient-table ROM
---------------------
One entry per (table, index value): the address is the table number (microcode field
``tab``) above the ``lut_index_bits`` low bits of the index read from the value memory, so
no adder sits in the address path. Table ``t`` holds ``table[j]`` for every index value ``j``
its index can take and 0 elsewhere (padding up to ``2**lut_index_bits`` entries per table);
luts that share an index are simply several tables (one lookup, one write each: the write
port takes one value per cycle anyway).

Timing (cycle = microcode step, step 0 is the cycle after the input transfer)
----------------------------------------------------------------------------
Every long path of the machine is cut by a register (memory read -> read register -> ALU
compare/add -> ALU select -> source select -> view shift -> memory write), so the timing is
stated in these constants: ``READ_DELAY`` = 2, ``ALU_LATENCY`` = 4, ``LUT_LATENCY`` = 3,
``WRITE_DELAY`` = 2.

- an operation *issued* at ``t`` presents its read addresses at ``t``; the memory's data
  is registered at ``t + 1`` and seen by the units at ``t + READ_DELAY``;
- ALU: sum and comparison at ``t + 2``, selection (field ``alu`` of the word at ``t + 3``)
  registered at ``t + 3``, result written at ``t + ALU_LATENCY``;
- lut: the ROM address (index from the read register at ``t + 2``, table ``tab`` of the
  word at ``t + 2``) is registered by the ROM, the entry is written at ``t + LUT_LATENCY``;
- multiplier: latches its operands at ``t + READ_DELAY`` (``go``), feeds ``n_limbs`` limb
  pairs to its DSP-sized product on the following cycles, result written at
  ``t + READ_DELAY + n_limbs + 3`` (``Program.mul_latency``); a unit accepts a new ``go``
  ``n_limbs`` cycles after the previous one;
- *written* at ``w`` means: source selected (field ``src`` of the word at ``w``) and
  registered; at ``w + 1`` the view shift, memory address and write enable, output capture
  (fields ``view``, ``we``, ``wa``, ``cap`` of the word at ``w + 1``) are registered; the
  memory write happens at ``w + WRITE_DELAY``, so the value can be read by an operation
  issued at ``w + WRITE_DELAY + 1`` or later, and its slot can be reused by a value whose
  memory write comes after the last read (see ``_allocate``);
- one issue per cycle (two read ports), one write per cycle;
- ``steps`` = last write + ``WRITE_DELAY`` + 1: the last value's capture is done in the
  last step.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..fit.ops import OPS
from ..fit.plan import Plan, signed_bits
from .limbmul import check_dsp, limb_split

__all__ = ["ALU_OPS", "MicroOp", "Program", "READ_DELAY", "WRITE_DELAY", "compile_program",
           "resolve_view"]

ALU_OPS = ("add", "max", "min", "pass", "and")
READ_DELAY = 2         # issue -> cycle the units see the (registered) read data
ALU_LATENCY = READ_DELAY + 2   # issue -> write: read, read register, ALU compare/add, ALU select
LUT_LATENCY = READ_DELAY + 1   # issue -> write: index read, read register, ROM read
WRITE_DELAY = 2        # written at w (source selected and registered), shifted into its view and
                       # registered at w + 1 (fields view/we/wa/cap), in the memory at w + 2


def resolve_view(plan: Plan, idx: int) -> tuple[int, int, int]:
    """``(base, a, b)`` with node ``idx`` == ``(base >> a) << b`` and ``base`` no node whose op
    has a ``view`` (a pure shift, :data:`ikseries.fit.ops.OPS`; ``mask`` has none: it is an
    ALU ``and``)."""
    chain = []
    nodes = plan.nodes
    while (view := OPS[nodes[idx].op].view) is not None:
        chain.append(view(nodes[idx]))
        idx = nodes[idx].args[0]
    a = b = 0
    for right, left in reversed(chain):    # ((x >> a) << b) >> right << left, floor exact
        if right <= b:
            b -= right
        else:
            a, b = a + right - b, 0
        b += left
    return idx, a, b


def _view_interval(lo: int, hi: int, view: tuple[int, int]) -> tuple[int, int]:
    a, b = view
    return (lo >> a) << b, (hi >> a) << b


@dataclass
class MicroOp:
    """One lowered operation: writes value ``out`` (view ``view`` of its raw result)."""
    kind: str                  # "load" | "alu" | "mul" | "lut"
    args: tuple[int, ...]      # value ids read (alu: 1-2, mul: 2 with the wider first, lut: index)
    out: int                   # value id written
    view: tuple[int, int]      # (a, b): stored = (raw >> a) << b
    alu: str | None = None     # add | max | min | pass | and
    input: str | None = None   # load: plan input name
    table: int = -1            # lut: table number in the ROM (Program.tables)
    raw: tuple[int, int] = (0, 0)  # interval of the raw result
    issue: int = -1            # scheduled cycle (load: write cycle)
    write: int = -1
    unit: int = -1             # multiplier unit


@dataclass
class Program:
    """A scheduled, allocated program and its microcode (see the module docstring)."""
    plan: Plan
    multipliers: int
    dsp: tuple[int, int] | None
    ops: list[MicroOp]
    values: list[tuple[int, int]]          # interval of every stored value
    const_value: dict[int, int]            # value id -> integer (constants only)
    outputs: dict[str, int]                # output name -> value id
    tables: list[tuple[int, ...]] = field(default_factory=list)   # lut tables, by index value
    slot: dict[int, int] = field(default_factory=dict)   # value id -> memory address
    views: list[tuple[int, int]] = field(default_factory=list)
    # widths
    store_width: int = 0                   # signed width of the value memory
    mul_widths: tuple[int, int] = (2, 2)   # signed widths of multiplier operands A, B
    limb_bits: tuple[int, int] = (1, 1)    # bits per low limb (A, B)
    limbs: tuple[int, int] = (1, 1)        # limbs per operand (A, B)
    acc_width: int = 1                     # signed width of the product accumulator
    wb_width: int = 1                      # signed width of the write-back path
    lut_width: int = 0                     # signed width of the table ROM (0: no ROM)
    lut_index_bits: int = 0                # index bits of a ROM address (below the table)
    steps: int = 0                         # microcode length (cycles per evaluation)
    depth: int = 0                         # value memory depth
    words: list[dict] = field(default_factory=list)

    @property
    def n_limbs(self) -> int:
        return self.limbs[0] * self.limbs[1]

    @property
    def mul_latency(self) -> int:
        """Issue -> write of a product: ``go`` at ``READ_DELAY``, then the unit's ``n_limbs + 3``."""
        return READ_DELAY + self.n_limbs + 3

    @property
    def n_consts(self) -> int:
        return len(self.const_value)

    def count(self, kind: str) -> int:
        return sum(1 for o in self.ops if o.kind == kind)

    @property
    def mul_busy_cycles(self) -> int:
        """Multiplier-cycles of work (limb products) per evaluation."""
        return self.count("mul") * self.n_limbs

    def lut_init(self) -> list[int]:
        """Table ROM contents: entry ``(t << lut_index_bits) | j`` is ``tables[t][j]`` (0 past its end)."""
        n = 1 << self.lut_index_bits
        return [tab[j] if j < len(tab) else 0 for tab in self.tables for j in range(n)]

    def memory_init(self) -> list[int]:
        init = [0] * self.depth
        for v, c in self.const_value.items():
            init[self.slot[v]] = c
        return init


def _check_params(multipliers, dsp):
    if not isinstance(multipliers, int) or isinstance(multipliers, bool) or multipliers < 1:
        raise ValueError(f"multipliers must be a positive integer, not {multipliers!r}")
    check_dsp(dsp)


class _Lowering:
    """The values and micro-operations of a plan being lowered (see :func:`_lower`)."""

    def __init__(self):
        self.values: list[tuple[int, int]] = []
        self.const_value: dict[int, int] = {}
        self.const_by_int: dict[int, int] = {}
        self.ops: list[MicroOp] = []
        self.tables: list[tuple[int, ...]] = []

    def new_value(self, lo, hi) -> int:
        self.values.append((lo, hi))
        return len(self.values) - 1

    def const(self, c) -> int:
        """The value id of the integer constant ``c`` (one per integer, pre-loaded)."""
        c = int(c)
        if c not in self.const_by_int:
            v = self.new_value(c, c)
            self.const_by_int[c] = v
            self.const_value[v] = c
        return self.const_by_int[c]


def _alu_add(lw: _Lowering, n, args, out, prim):
    lw.ops.append(MicroOp("alu", tuple(args), out, prim, alu="add", raw=(n.lo, n.hi)))


def _alu_mask(lw: _Lowering, n, args, out, prim):
    """Two's complement low bits of x: x & (2**s - 1)."""
    lw.ops.append(MicroOp("alu", (args[0], lw.const((1 << n.param) - 1)), out, prim, alu="and",
                          raw=(n.lo, n.hi)))


def _alu_clamp(lw: _Lowering, n, args, out, prim):
    """clamp -> min(max(x, lo'), hi'), the bounds narrowed to the operand's interval."""
    xlo, xhi = lw.values[args[0]]
    clo, chi = n.param
    lo_b = max(clo, xlo)
    t = lw.new_value(max(xlo, lo_b), max(xhi, lo_b))
    lw.ops.append(MicroOp("alu", (args[0], lw.const(lo_b)), t, (0, 0), alu="max", raw=lw.values[t]))
    hi_b = min(chi, lw.values[t][1])
    lw.ops.append(MicroOp("alu", (t, lw.const(hi_b)), out, prim, alu="min", raw=(n.lo, n.hi)))


#: the ALU microprograms of the plan operations the machine computes on its ALU (every op of
#: :data:`ikseries.fit.ops.OPS` but ports, constants, products, tables and views)
ALU_PROGRAMS = {"add": _alu_add, "mask": _alu_mask, "clamp": _alu_clamp}


def _lower_node(lw: _Lowering, n, args, out, prim):
    """Micro-operations computing plan node ``n`` (not a port, constant or view) into ``out``."""
    kind = OPS[n.op].kind
    if kind == "product":
        w = [signed_bits(*lw.values[x]) for x in args]
        if w[1] > w[0]:
            args.reverse()
        lw.ops.append(MicroOp("mul", tuple(args), out, prim, raw=(n.lo, n.hi)))
    elif kind == "table":    # entries the index never takes are 0 (they may not fit)
        ilo, ihi = lw.values[args[0]]
        lw.tables.append(tuple(n.param[j] if j >= ilo else 0 for j in range(ihi + 1)))
        lw.ops.append(MicroOp("lut", tuple(args), out, prim, table=len(lw.tables) - 1, raw=(n.lo, n.hi)))
    elif n.op in ALU_PROGRAMS:
        ALU_PROGRAMS[n.op](lw, n, args, out, prim)
    else:
        raise ValueError(f"plan operation must be one the folded machine can compute (ports, constants, "
                         f"products, tables, shift views or {', '.join(ALU_PROGRAMS)}), not {n.op!r}")


def _lower(plan: Plan):
    nodes = plan.nodes
    views: dict[int, list] = {}

    def need(idx):
        base, a, b = resolve_view(plan, idx)
        lst = views.setdefault(base, [])
        if (a, b) not in lst:
            lst.append((a, b))
        return base, (a, b)

    operand = {}
    live = plan.live()
    for i, n in enumerate(nodes):
        if i in live and OPS[n.op].view is None:
            operand[i] = [need(x) for x in n.args]
    out_ref = {o.name: need(o.node) for o in plan.outputs}

    lw = _Lowering()
    value_of: dict = {}
    for base in sorted(views):
        n, vs = nodes[base], views[base]
        kind = OPS[n.op].kind
        if kind == "constant":
            for v in vs:
                value_of[(base, v)] = lw.const(_view_interval(n.param, n.param, v)[0])
            continue
        if kind == "port":
            for v in vs:
                out = lw.new_value(*_view_interval(n.lo, n.hi, v))
                lw.ops.append(MicroOp("load", (), out, v, input=n.param, raw=(n.lo, n.hi)))
                value_of[(base, v)] = out
            continue
        prim = vs[0] if len(vs) == 1 else (min(a for a, _ in vs), 0)
        out = lw.new_value(*_view_interval(n.lo, n.hi, prim))
        _lower_node(lw, n, [value_of[r] for r in operand[base]], out, prim)
        value_of[(base, prim)] = out
        for v in vs:
            if v != prim:
                dv = lw.new_value(*_view_interval(n.lo, n.hi, v))
                lw.ops.append(MicroOp("alu", (out,), dv, (v[0] - prim[0], v[1]), alu="pass",
                                      raw=lw.values[out]))
                value_of[(base, v)] = dv
    outputs = {name: value_of[r] for name, r in out_ref.items()}
    return lw.ops, lw.values, lw.const_value, outputs, lw.tables


def _schedule(ops, n_values, multipliers, mul_latency, n_limbs):
    producer = {o.out: k for k, o in enumerate(ops)}
    consumers: dict[int, list[int]] = {k: [] for k in range(len(ops))}
    for k, o in enumerate(ops):
        for a in o.args:
            if a in producer:
                consumers[producer[a]].append(k)
    lat = [{"load": 0, "alu": ALU_LATENCY, "lut": LUT_LATENCY}.get(o.kind, mul_latency) for o in ops]
    height = [0] * len(ops)
    for k in reversed(range(len(ops))):       # ops are in dependency order
        height[k] = lat[k] + max([height[c] + 1 + WRITE_DELAY for c in consumers[k]] + [0])
    ready_at = {}                             # value id -> first cycle it can be read
    wport: set[int] = set()
    unit_free = [0] * multipliers             # first cycle a unit may take a new go
    loads = sorted((k for k, o in enumerate(ops) if o.kind == "load"), key=lambda k: -height[k])
    waiting = [k for k, o in enumerate(ops) if o.kind != "load"]
    t = 0
    while loads or waiting:
        if loads and t not in wport:
            k = loads.pop(0)
            ops[k].issue = ops[k].write = t
            wport.add(t)
            ready_at[ops[k].out] = t + 1 + WRITE_DELAY
        cands = [k for k in waiting
                 if all(a not in producer or ready_at.get(a, 1 << 30) <= t for a in ops[k].args)]
        cands.sort(key=lambda k: (-height[k], k))
        for k in cands:
            o = ops[k]
            w = t + lat[k]
            if w in wport:
                continue
            if o.kind == "mul":
                free = [u for u in range(multipliers) if unit_free[u] <= t + READ_DELAY]
                if not free:
                    continue
                o.unit = free[0]
                unit_free[o.unit] = t + READ_DELAY + n_limbs
            o.issue, o.write = t, w
            wport.add(w)
            ready_at[o.out] = w + 1 + WRITE_DELAY
            waiting.remove(k)
            break
        t += 1
        if t > 100 * (len(ops) + 10) * (n_limbs + 4):
            raise RuntimeError("scheduler made no progress (internal error)")


def _allocate(prog: Program):
    """Memory addresses: constants first (pre-loaded), then intermediates, reusing a slot
    once the last read of its value has been issued (strictly before the cycle the next
    value enters the memory, ``write + WRITE_DELAY``)."""
    last_read: dict[int, int] = {}
    for o in prog.ops:
        for a in o.args:
            last_read[a] = max(last_read.get(a, -1), o.issue)
    for v in sorted(prog.const_value):
        prog.slot[v] = len(prog.slot)
    base = len(prog.slot)
    free_after: list[int] = []                 # per intermediate slot: last read cycle
    for o in sorted(prog.ops, key=lambda o: o.write):
        if o.out not in last_read:             # only captured as an output: not stored
            continue
        for s, f in enumerate(free_after):
            if f < o.write + WRITE_DELAY:    # last read before the memory write
                free_after[s] = last_read[o.out]
                prog.slot[o.out] = base + s
                break
        else:
            free_after.append(last_read[o.out])
            prog.slot[o.out] = base + len(free_after) - 1
    prog.depth = max(1, base + len(free_after))


def compile_program(plan: Plan, multipliers: int = 1, dsp: tuple[int, int] | None = None) -> Program:
    """Lower, schedule and allocate ``plan`` for ``multipliers`` units of DSP size ``dsp``
    (signed operand bits, e.g. ``(16, 16)``; None: one full-width product per multiplier)."""
    if not isinstance(plan, Plan):
        raise TypeError(f"plan must be a Plan, not {plan!r}")
    if not plan.outputs:
        raise ValueError("plan must have at least one output")
    _check_params(multipliers, dsp)
    ops, values, const_value, outputs, tables = _lower(plan)
    prog = Program(plan, multipliers, dsp, ops, values, const_value, outputs, tables)

    muls = [o for o in ops if o.kind == "mul"]
    wa = max([signed_bits(*values[o.args[0]]) for o in muls] + [2])
    wb = max([signed_bits(*values[o.args[1]]) for o in muls] + [2])
    prog.mul_widths = (wa, wb)
    prog.limb_bits, prog.limbs, _ = limb_split(wa, wb, dsp)
    prog.acc_width = max([signed_bits(*o.raw) for o in muls] + [2])
    prog.store_width = max(signed_bits(lo, hi) for lo, hi in values)
    in_w = max(signed_bits(*i.port_range) for i in plan.inputs) if plan.inputs else 1
    if tables:
        prog.lut_width = max(signed_bits(min(t), max(t)) for t in tables)
        prog.lut_index_bits = max(1, max(len(t) - 1 for t in tables).bit_length())
    prog.wb_width = max(prog.store_width + 1, prog.acc_width, in_w, prog.lut_width)

    _schedule(ops, len(values), multipliers, prog.mul_latency, prog.n_limbs)
    _allocate(prog)
    prog.views = sorted({o.view for o in ops})
    writes = [o.write for o in ops]
    prog.steps = max(writes) + 1 + WRITE_DELAY if writes else 1
    _assemble(prog)
    return prog


def _assemble(prog: Program):
    """One dict of microcode fields per step (see ``folded.microcode_layout``)."""
    k = prog.multipliers
    inputs = [i.name for i in prog.plan.inputs]
    outs = list(prog.outputs)
    word = {"rx": 0, "ry": 0, "alu": 0, "go": 0, "we": 0, "wa": 0, "src": 0, "view": 0, "cap": 0}
    if prog.tables:
        word["tab"] = 0
    words = [dict(word) for _ in range(prog.steps)]
    vidx = {v: i for i, v in enumerate(prog.views)}
    written = set()
    for o in prog.ops:
        if o.kind != "load":
            w = words[o.issue]
            w["rx"] = prog.slot[o.args[0]]
            w["ry"] = prog.slot[o.args[-1]]
            if o.kind == "alu":
                words[o.issue + READ_DELAY + 1]["alu"] = ALU_OPS.index(o.alu)
            elif o.kind == "lut":
                words[o.issue + READ_DELAY]["tab"] = o.table
            else:
                words[o.issue + READ_DELAY]["go"] |= 1 << o.unit
        if o.write in written:
            raise RuntimeError(f"write port conflict at step {o.write} (internal error)")
        written.add(o.write)
        words[o.write]["src"] = (0 if o.kind == "alu" else 1 + o.unit if o.kind == "mul"
                                 else 1 + k + len(inputs) if o.kind == "lut"
                                 else 1 + k + inputs.index(o.input))
        w = words[o.write + 1]                 # after the source register
        w["view"] = vidx[o.view]
        if o.out in prog.slot:
            w["we"], w["wa"] = 1, prog.slot[o.out]
        for j, name in enumerate(outs):
            if prog.outputs[name] == o.out:
                w["cap"] |= 1 << j
    prog.words = words
