"""The operations of an evaluation plan: one table, :data:`OPS`, read by everything that
interprets a plan.

Every entry is an :class:`Op`: the operation's name, arity and hardware kind, and its meaning
in each arithmetic a plan is evaluated in. A plan node is ``Node(op, args, frac, lo, hi, param,
ideal)`` (:class:`ikseries.fit.plan.Node`); its integer stands for ``integer * 2**-frac``.

========  =====  ========  =====================================================================
name      arity  kind      integer value (``param``)
========  =====  ========  =====================================================================
input     0      port      the port field ``param`` (a name)
const     0      constant  ``param``; ``ideal`` the real value it was rounded from
add       2      logic     a + b (operands with the plan's ``frac``)
mul       2      product   a * b (``frac`` = frac(a) + frac(b))
clamp     1      logic     min(max(a, lo), hi) (``param`` = (lo, hi))
shr       1      wiring    floor(a / 2**s) (``param`` = s)
shl       1      wiring    a * 2**s
frac      1      wiring    a, another binary point
index     1      wiring    floor(a / 2**s), 0 fractional bits: a cell number
mask      1      wiring    a mod 2**s (the low s bits), the same ``frac``: the offset in the cell
lut       1      table     table[a] (``param`` the integers, ``ideal`` the real values)
========  =====  ========  =====================================================================

Kinds (:data:`KINDS`): ``port`` and ``logic``, ``product``, ``table`` nodes are registered (one
pipeline stage: the input register, an adder or clamp, a multiplier, a ROM read); ``constant``
and ``wiring`` nodes take none (a wiring node is a rewiring of its operand's bits).

Readers: :mod:`ikseries.fit.plan` (arity, intervals, stages, rounding bound, JSON),
:mod:`ikseries.sim.golden` (integer and ideal values), :mod:`ikseries.fit.certify` (interval
enclosures), :mod:`ikseries.hdl.evaluator` and :mod:`ikseries.hdl.modulo` (the combinational
expression, registered or not), :mod:`ikseries.hdl.schedule` (folded microcode: wiring ``view``
shifts, ``product`` on a multiplier unit, ``table`` on the coefficient ROM).

Adding an operation
-------------------
Write its functions here and add one :class:`Op` entry to :data:`OPS`; every reader above takes
it from the table. Only the folded machine has a fixed ALU: an op of kind ``logic`` (or a
``wiring`` op without a ``view``) also needs its ALU microprogram in
``hdl/schedule.py`` (``ALU_PROGRAMS``), else :func:`ikseries.hdl.schedule.compile_program`
refuses the plan naming the op. Tests: a tiny plan using the op, checked exhaustively
(``tests/helpers.py``: ``check_exhaustively``) and bit-exactly on every core, as in
``tests/test_ops.py``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from amaranth.hdl import Array, Const, Mux, signed, unsigned

from . import centred as cn
from . import cut
from . import interval as ia

__all__ = ["Codec", "KINDS", "Op", "OPS", "REGISTERED_KINDS", "SCALAR", "SEQUENCE", "node_shape", "operation"]

KINDS = ("port", "constant", "logic", "product", "table", "wiring")
#: kinds that take one pipeline stage
REGISTERED_KINDS = frozenset({"port", "logic", "product", "table"})


@dataclass(frozen=True)
class Codec:
    """JSON form of a node's ``param`` or ``ideal``: ``encode`` to JSON, ``decode`` back
    (``decode`` raises ValueError naming what it expected)."""
    encode: Callable
    decode: Callable


def _decode_scalar(v):
    if isinstance(v, (list, dict)):
        raise ValueError(f"must be a number or a name, not {v!r}")
    return v


def _decode_sequence(v):
    if not isinstance(v, list):
        raise ValueError(f"must be a list, not {v!r}")
    return tuple(v)


SCALAR = Codec(lambda v: v, _decode_scalar)
SEQUENCE = Codec(list, _decode_sequence)


def node_shape(n):
    """Amaranth shape of plan node ``n``'s integer (from its interval)."""
    return signed(n.width) if n.signed else unsigned(n.width)


@dataclass(frozen=True)
class Op:
    """One plan operation (see the module docstring).

    Parameters
    ----------
    name : str
    arity : int
        Number of operands.
    kind : str
        One of :data:`KINDS`.
    bounds : callable
        ``(a, frac, param, ideal, inputs) -> (lo, hi)``: the node's integer interval from its
        operand nodes ``a`` (the plan's :class:`~ikseries.fit.plan.PlanInput` list ``inputs``);
        raises ValueError for bad operands or parameters.
    integer : callable
        ``(n, x, ports) -> values``: the integer value (numpy, vectorised) from the operand
        values ``x`` and the port integers by name ``ports``.
    real : callable
        ``(n, a, x, ports) -> values``: the ideal value in float64 (unrounded constants, exact
        shifts) from the operand nodes ``a`` and their ideal values ``x``.
    rounding : callable
        ``(n, a, e) -> float``: bound on |integer value * 2**-frac - ideal value| from the
        operand nodes ``a`` and their bounds ``e``, for every in-range input.
    enclose : callable
        ``(n, nodes, x, inputs) -> Interval``: enclosure of the ideal value over the
        certifier's cells from the operand enclosures ``x`` and the input enclosures by name.
    rtl : callable or None
        ``(n, x) -> Value``: the combinational Amaranth expression from the operand values
        (None: no expression, the input port).
    view : callable or None
        ``n -> (a, b)`` when the op is the pure shift ``(x >> a) << b`` of its operand.
    cuts : bool
        The op cuts its argument into table cells (the certifier aligns its cells to them).
    param, ideal : Codec
        JSON forms of ``param`` and ``ideal``.
    """
    name: str
    arity: int
    kind: str
    bounds: Callable
    integer: Callable
    real: Callable
    rounding: Callable
    enclose: Callable
    rtl: Callable | None = None
    view: Callable | None = None
    cuts: bool = False
    param: Codec = SCALAR
    ideal: Codec = SCALAR

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"op {self.name}: kind must be one of {', '.join(KINDS)}, not {self.kind!r}")

    @property
    def registered(self) -> bool:
        """Takes one pipeline stage."""
        return self.kind in REGISTERED_KINDS

    @property
    def wiring(self) -> bool:
        """Takes no hardware: a rewiring of its operand's bits."""
        return self.kind == "wiring"

    @property
    def product(self) -> bool:
        """A multiplication: runs on a multiplier."""
        return self.kind == "product"


def _scale(n) -> float:
    return 2.0 ** -n.frac


def _same(n, a, e):
    """Rounding rule of an exact op (or a clamp: the ideal value is clamped too, and a clamp
    never increases a distance, it is 1-Lipschitz)."""
    return e[0]


def _first(n, nodes, x, inputs):
    return x[0]


# -- input, const -------------------------------------------------------------------------------
def _input_bounds(a, frac, param, ideal, inputs):
    for i in inputs:
        if i.name == param:
            return i.port_range
    raise ValueError(f"input node must name one of the plan inputs {[i.name for i in inputs]}, not {param!r}")


def _const_real(n, a, x, ports):
    return n.ideal if n.ideal is not None else n.param * _scale(n)


def _const_rounding(n, a, e):
    return abs(n.param * _scale(n) - n.ideal) if n.ideal is not None else 0.0


def _const_enclose(n, nodes, x, inputs):
    return ia.point(n.ideal if n.ideal is not None else np.ldexp(float(n.param), -n.frac))


# -- add, mul -------------------------------------------------------------------------------------
def _add_bounds(a, frac, param, ideal, inputs):
    if a[0].frac != a[1].frac or frac != a[0].frac:
        raise ValueError("add operands must have equal fractional bits")
    return a[0].lo + a[1].lo, a[0].hi + a[1].hi


def _mul_bounds(a, frac, param, ideal, inputs):
    if frac != a[0].frac + a[1].frac:
        raise ValueError("mul result must have frac(a) + frac(b) fractional bits")
    p = [x * y for x in (a[0].lo, a[0].hi) for y in (a[1].lo, a[1].hi)]
    lo, hi = min(p), max(p)
    if a[0] is a[1]:  # one node twice (the same object): a square is never negative
        lo = 0 if a[0].lo <= 0 <= a[0].hi else min(a[0].lo ** 2, a[0].hi ** 2)
    return lo, hi


def _mul_rounding(n, a, e):
    ma = max(abs(a[0].lo), abs(a[0].hi)) * 2.0 ** -a[0].frac
    mb = max(abs(a[1].lo), abs(a[1].hi)) * 2.0 ** -a[1].frac
    return ma * e[1] + mb * e[0] + e[0] * e[1]


def _mul_enclose(n, nodes, x, inputs):
    return x[0].sqr() if n.args[0] == n.args[1] else x[0] * x[1]


# -- clamp ------------------------------------------------------------------------------------------
def _clamp_bounds(a, frac, param, ideal, inputs):
    clo, chi = param
    return min(max(a[0].lo, clo), chi), max(min(a[0].hi, chi), clo)


def _clamp_real(n, a, x, ports):
    return np.clip(x[0], n.param[0] * _scale(n), n.param[1] * _scale(n))


def _clamp_enclose(n, nodes, x, inputs):
    return cn.clamp(x[0], np.ldexp(float(n.param[0]), -n.frac), np.ldexp(float(n.param[1]), -n.frac))


def _clamp_rtl(n, x):
    lo, hi = n.param
    return Mux(x[0] < lo, lo, Mux(x[0] > hi, hi, x[0]))


# -- shr, shl, frac -------------------------------------------------------------------------------
def _shr_bounds(a, frac, param, ideal, inputs):
    return a[0].lo >> param, a[0].hi >> param


def _shr_rounding(n, a, e):
    return e[0] + (1 - 2.0 ** -n.param) * _scale(n)


def _shl_bounds(a, frac, param, ideal, inputs):
    return a[0].lo << param, a[0].hi << param


def _frac_real(n, a, x, ports):
    return x[0] * 2.0 ** (a[0].frac - n.frac)


def _frac_rounding(n, a, e):  # same integer, real value scaled by 2**(frac(a) - frac)
    return e[0] * 2.0 ** (a[0].frac - n.frac)


def _frac_enclose(n, nodes, x, inputs):
    return cn.ldexp(x[0], nodes[n.args[0]].frac - n.frac)


# -- index, mask, lut: a cell number, the offset in the cell, a table per cell ------------------------
def _index_bounds(a, frac, param, ideal, inputs):
    if frac != 0:
        raise ValueError(f"index must have 0 fractional bits, not {frac}")
    return a[0].lo >> param, a[0].hi >> param


def _mask_bounds(a, frac, param, ideal, inputs):
    if frac != a[0].frac:
        raise ValueError("mask keeps the fractional bits of its operand")
    m = (1 << param) - 1
    return (a[0].lo & m, a[0].hi & m) if a[0].lo >> param == a[0].hi >> param else (0, m)


def _cell(n, a, x):
    """Cell number (float) of the ideal argument ``x``: cells of 2**s integers of it."""
    return np.floor(x * 2.0 ** (a.frac - n.param))


def _index_real(n, a, x, ports):
    return _cell(n, a[0], x[0]).astype(np.int64)


def _mask_real(n, a, x, ports):
    return x[0] - _cell(n, a[0], x[0]) * 2.0 ** (n.param - a[0].frac)


# A cut of a rounded value (a feature cut) may put the integer argument in another cell than the
# ideal one near an edge: there the ideal index and mask are those of the integer argument's
# cell (the certifier encloses every cell the rounded argument can reach, fit/certify.py
# _ErrorFunction), so the index is exact and the mask off by the argument's rounding only.
def _index_rounding(n, a, e):
    return 0.0


def _mask_rounding(n, a, e):
    return e[0]


def _lut_bounds(a, frac, param, ideal, inputs):
    table = param
    if not (isinstance(table, tuple) and table and all(isinstance(v, int) for v in table)):
        raise ValueError(f"lut table must be a non-empty tuple of integers, not {table!r}")
    if ideal is not None and len(ideal) != len(table):
        raise ValueError(f"lut ideal values must be one per entry ({len(table)}), not {len(ideal)}")
    if a[0].frac != 0 or a[0].lo < 0 or a[0].hi >= len(table):
        raise ValueError(f"lut index must be an integer in [0, {len(table) - 1}], "
                         f"not [{a[0].lo}, {a[0].hi}] with {a[0].frac} fractional bits")
    reach = table[a[0].lo:a[0].hi + 1]
    return min(reach), max(reach)


def _lut_real(n, a, x, ports):
    # the index is an exact integer, but a sum of cell numbers (a grid's address) is a float
    index = np.asarray(x[0])
    index = index if index.dtype.kind in "iu" else np.floor(index).astype(np.int64)
    return np.asarray(n.ideal if n.ideal is not None else n.param, dtype=np.float64)[index] * (
        1.0 if n.ideal is not None else _scale(n))


def _lut_rounding(n, a, e):
    if n.ideal is None:
        return 0.0
    sc = _scale(n)
    return max(abs(n.param[i] * sc - n.ideal[i]) for i in range(a[0].lo, a[0].hi + 1))


def _cell_enclose(rule):
    return lambda n, nodes, x, inputs: cut.cell_enclosure(rule, n, nodes, x[0], inputs)


def _shift_right(n, x):
    return x[0] >> n.param


#: the operations, by name, in the order of the module docstring
OPS: dict[str, Op] = {op.name: op for op in (
    Op("input", 0, "port", _input_bounds,
       integer=lambda n, x, ports: ports[n.param],
       real=lambda n, a, x, ports: ports[n.param] * _scale(n),
       rounding=lambda n, a, e: 0.0,
       enclose=lambda n, nodes, x, inputs: inputs[n.param]),
    Op("const", 0, "constant", lambda a, frac, param, ideal, inputs: (int(param), int(param)),
       integer=lambda n, x, ports: np.int64(n.param), real=_const_real, rounding=_const_rounding,
       enclose=_const_enclose, rtl=lambda n, x: Const(n.param, node_shape(n))),
    Op("add", 2, "logic", _add_bounds,
       integer=lambda n, x, ports: x[0] + x[1], real=lambda n, a, x, ports: x[0] + x[1],
       rounding=lambda n, a, e: e[0] + e[1], enclose=lambda n, nodes, x, inputs: x[0] + x[1],
       rtl=lambda n, x: x[0] + x[1]),
    Op("mul", 2, "product", _mul_bounds,
       integer=lambda n, x, ports: x[0] * x[1], real=lambda n, a, x, ports: x[0] * x[1],
       rounding=_mul_rounding, enclose=_mul_enclose, rtl=lambda n, x: x[0] * x[1]),
    Op("clamp", 1, "logic", _clamp_bounds,
       integer=lambda n, x, ports: np.clip(x[0], n.param[0], n.param[1]), real=_clamp_real,
       rounding=_same, enclose=_clamp_enclose, rtl=_clamp_rtl, param=SEQUENCE),
    Op("shr", 1, "wiring", _shr_bounds,
       integer=lambda n, x, ports: x[0] >> n.param, real=lambda n, a, x, ports: x[0],
       rounding=_shr_rounding, enclose=_first, rtl=_shift_right, view=lambda n: (n.param, 0)),
    Op("shl", 1, "wiring", _shl_bounds,
       integer=lambda n, x, ports: x[0] << n.param, real=lambda n, a, x, ports: x[0],
       rounding=_same, enclose=_first, rtl=lambda n, x: x[0] << n.param, view=lambda n: (0, n.param)),
    Op("frac", 1, "wiring", lambda a, frac, param, ideal, inputs: (a[0].lo, a[0].hi),
       integer=lambda n, x, ports: x[0], real=_frac_real, rounding=_frac_rounding,
       enclose=_frac_enclose, rtl=lambda n, x: x[0], view=lambda n: (0, 0)),
    Op("index", 1, "wiring", _index_bounds,
       integer=lambda n, x, ports: x[0] >> n.param, real=_index_real, rounding=_index_rounding,
       enclose=_cell_enclose(cut.index_cell), rtl=_shift_right, view=lambda n: (n.param, 0), cuts=True),
    # two's complement low bits: non-negative, zero-extended
    Op("mask", 1, "wiring", _mask_bounds,
       integer=lambda n, x, ports: x[0] & ((1 << n.param) - 1), real=_mask_real, rounding=_mask_rounding,
       enclose=_cell_enclose(cut.mask_cell), rtl=lambda n, x: x[0] & Const((1 << n.param) - 1, unsigned(n.param)),
       cuts=True),
    Op("lut", 1, "table", _lut_bounds,
       integer=lambda n, x, ports: np.asarray(n.param, dtype=np.int64)[x[0]], real=_lut_real,
       rounding=_lut_rounding, enclose=_cell_enclose(cut.lut_cell),
       rtl=lambda n, x: Array(Const(v, node_shape(n)) for v in n.param)[x[0]], param=SEQUENCE, ideal=SEQUENCE),
)}


def operation(name: str, n_args: int) -> Op:
    """The entry of :data:`OPS` for an operation ``name`` with ``n_args`` operands.

    Raises
    ------
    ValueError
        If ``name`` is no plan operation or takes another number of operands.
    """
    if name not in OPS or n_args != OPS[name].arity:
        raise ValueError(f"bad plan operation {name!r} with {n_args} operands")
    return OPS[name]
