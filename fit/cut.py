"""Enclosures of a piecewise plan's table cuts (``index``, ``mask``, ``lut``) over the
certifier's cells.

A cell of the certifier is treated as half-open, [lo, hi), along every input that an index or
mask node cuts (see :func:`cut_chain`), unless it is degenerate there (lo == hi: the point
lo). The certifier's cells partition the box in that sense: the initial grid of every cut
input is [e_0, e_1), ..., [e_m-1, box_hi), {box_hi} (a degenerate last slab, see
the certifier's initial cells) and bisection splits [lo, hi) into [lo, mid) and [mid, hi); so every
point of the box, the upper corner included, lies in the half-open version of some cell and
an enclosure over the half-open cell suffices. On such a cell the argument of an index node,
a non-decreasing function g of the cut input (additions of constants, clamps, binary point
moves), ranges over [g(lo), g(hi)), half-open again unless a clamp acts at the top (then
g(hi) itself is reached inside the cell and the range is closed). The index is therefore
floor(g(lo) 2**k) .. ceil(g(hi) 2**k) - 1 (k = frac(argument) - shift), or .. floor(g(hi) 2**k)
if closed; with the initial grid aligned to the table cells (g(x) 2**k integer at every
edge) it is a single value on every cell, and bisection keeps it so. There the lut is a
constant (zero derivatives) and the mask the exact affine function argument - index 2**-k,
whose derivatives are the argument's. Where the index takes several values (an argument of
another form, an edge that is not a float, or a caller's own cells) the lut is the hull of
the reachable entries and the mask [0, 2**-k], both with unbounded derivatives (gradient
[-inf, inf], Hessian NaN: no mean-value or Taylor form applies), which is sound and makes the
refinement split the cell.

A grid over two inputs (:class:`ikseries.fit.features.CutGrid`) has an index node on each and
looks its coefficients up at the address i * 2**bits + j (a binary point move, a shift and an
add of the two cell numbers). Each index node is a cut chain of its own input, so the initial
grid is aligned to both tables (edges and a degenerate last slab along each input) and every
certifier cell, before and after bisection, holds one cell number of each: the address
enclosure, an interval sum of two exact integers (outward rounding at most moves it by less
than one, which the lut's ceil / floor of the enclosure undoes), is then one value, and the
lut a constant. Where either index takes several values its enclosure carries unbounded
derivatives, and the address enclosure contains every address reachable from the two index
ranges; the lut is then the hull of the contiguous entries between the least and greatest
address, a superset of the reachable ones (the unused entries after a row copy a real entry),
with unbounded derivatives: sound again, and refined away.

A cut of a computed value (a feature, :func:`feature_cuts`) has no input to align cells to: its
edges are curves. The certifier encloses it case by case instead (``fit/certify.py``
``_ErrorFunction``): in each case the index is forced to one reachable cell number and the
mask is the exact offset from that cell (:func:`forced_cell`), so every case is smooth over the
whole certifier cell.
"""
from __future__ import annotations

import numpy as np

from . import centred as cn
from . import interval as ia

__all__ = ["add_exact", "cell_enclosure", "chain_range", "cut_chain", "dims", "feature_cuts", "forced_cell",
           "index_cell", "index_range",
           "lut_cell", "mask_cell", "unbounded_where"]


def dims(values) -> int:
    """Number of inputs the derivatives are taken along (0 without derivatives)."""
    v = next(iter(values.values()))
    if isinstance(v, cn.Centred):
        return v.h.shape[0]
    return 0 if v.d is None else v.d[0].shape[0]


def cut_chain(nodes, i):
    """``(input name, steps)`` if node ``i`` is an input through additions of constants, clamps,
    binary point moves and (exact in the ideal arithmetic) shifts, else None. The steps, first
    applied first, are ``("add", c)``, ``("clamp", lo, hi)`` and ``("scale", k)`` (times 2**k):
    all non-decreasing, so the value is a non-decreasing function of the input."""
    steps = []
    while nodes[i].op != "input":
        n = nodes[i]
        if n.op == "clamp":
            steps.append(("clamp", np.ldexp(float(n.param[0]), -n.frac), np.ldexp(float(n.param[1]), -n.frac)))
        elif n.op == "frac":
            steps.append(("scale", nodes[n.args[0]].frac - n.frac))
        elif n.op == "add" and [nodes[a].op for a in n.args].count("const") == 1:
            c, i = (n.args[0], n.args[1]) if nodes[n.args[0]].op == "const" else (n.args[1], n.args[0])
            c = nodes[c]
            steps.append(("add", c.ideal if c.ideal is not None else np.ldexp(float(c.param), -c.frac)))
            continue
        elif n.op not in ("shl", "shr"):
            return None
        i = n.args[0]
    return nodes[i].param, steps[::-1]


def add_exact(x, c, side):
    """x + c rounded towards ``side`` (-inf or inf): exact when the float sum is (TwoSum)."""
    s = x + c
    t = s - x
    err = (x - (s - t)) + (c - t)              # x + c == s + err exactly
    return np.where(err > 0 if side > 0 else err < 0, np.nextafter(s, side), s)


def chain_range(steps, lo, hi):
    """Range of a cut chain's value for its input in [lo, hi) (the point lo where lo == hi):
    ``(lo, hi, open)``, ``open`` where the top ``hi`` itself is excluded."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    top_open = lo < hi
    for step in steps:
        if step[0] == "add":
            lo, hi = add_exact(lo, step[1], -np.inf), add_exact(hi, step[1], np.inf)
        elif step[0] == "scale":
            lo, hi = np.ldexp(lo, step[1]), np.ldexp(hi, step[1])   # exact barring underflow
        else:   # a clamp reaches its top limit inside the cell unless the top stays within
            top_open = top_open & (hi > step[1]) & (hi <= step[2])
            lo, hi = np.clip(lo, step[1], step[2]), np.clip(hi, step[1], step[2])
    return lo, hi, top_open


def index_range(n, nodes, a: ia.Interval, inputs: dict):
    """Least and greatest value of index / mask node ``n``'s cell number over the cells."""
    k = nodes[n.args[0]].frac - n.param
    chain = cut_chain(nodes, n.args[0])
    if chain is None:                            # the argument's enclosure, closed
        lo, hi, top_open = a.lo, a.hi, False
    else:
        x = inputs[chain[0]]
        lo, hi, top_open = chain_range(chain[1], x.lo, x.hi)
    ilo = np.floor(np.ldexp(lo, k))
    ihi = np.where(top_open, np.ceil(np.ldexp(hi, k)) - 1.0, np.floor(np.ldexp(hi, k)))
    return ilo, np.maximum(ilo, ihi)


def unbounded_where(x: ia.Interval, jump, dims: int) -> ia.Interval:
    """``x`` with no derivative bound (gradient [-inf, inf], Hessian NaN) in the cells ``jump``."""
    if x.order == 0 or not np.any(jump):
        return x
    size = jump.size
    zero = np.zeros((dims, size))
    dlo, dhi = (zero, zero) if x.d is None else (np.broadcast_to(x.d[0], zero.shape),
                                                 np.broadcast_to(x.d[1], zero.shape))
    d = (np.where(jump, -np.inf, dlo), np.where(jump, np.inf, dhi))
    h = None
    if x.order >= 2:
        zero = np.zeros((dims * (dims + 1) // 2, size))
        hlo, hhi = (zero, zero) if x.h is None else x.h
        h = (np.where(jump, np.nan, hlo), np.where(jump, np.nan, hhi))
    return ia.Interval(np.broadcast_to(x.lo, (size,)), np.broadcast_to(x.hi, (size,)), d, h, x.order)


def lut_cell(n, nodes, a: ia.Interval, inputs: dict, dims: int) -> ia.Interval:
    """Enclosure of lut node ``n`` (index enclosure ``a``) over the cells: its entry where the
    index is one value, else the hull of the reachable entries with unbounded derivatives."""
    table = np.asarray(n.ideal, dtype=np.float64) if n.ideal is not None else np.ldexp(
        np.asarray(n.param, dtype=np.float64), -n.frac)
    # the argument is a cell number within the table (the plan's interval analysis); an
    # enclosure reaching past an end only by widening is clipped back
    ilo = np.clip(np.ceil(np.atleast_1d(a.lo)), 0, len(table) - 1).astype(np.int64)
    ihi = np.maximum(ilo, np.clip(np.floor(np.atleast_1d(a.hi)), 0, len(table) - 1).astype(np.int64))
    lo, hi = table[ilo], table[ihi]
    jump = ilo != ihi
    for i, j in set(zip(ilo[jump].tolist(), ihi[jump].tolist())):   # hull of the reachable
        at = jump & (ilo == i) & (ihi == j)
        lo[at], hi[at] = table[i:j + 1].min(), table[i:j + 1].max()
    return unbounded_where(ia.Interval(lo, hi, order=a.order), jump, dims)


def index_cell(n, nodes, a: ia.Interval, inputs: dict, dims: int) -> ia.Interval:
    """Enclosure of index node ``n`` (argument enclosure ``a``) over the cells: the cell number."""
    ilo, ihi = index_range(n, nodes, a, inputs)
    jump = np.atleast_1d(ilo != ihi)
    return unbounded_where(ia.Interval(ilo, ihi, order=a.order), jump, dims)


def mask_cell(n, nodes, a: ia.Interval, inputs: dict, dims: int) -> ia.Interval:
    """Enclosure of mask node ``n`` (argument enclosure ``a``) over the cells: the offset in the
    cell, exact and affine where the cell number is one value."""
    ilo, ihi = index_range(n, nodes, a, inputs)
    jump = np.atleast_1d(ilo != ihi)
    width = np.ldexp(1.0, n.param - nodes[n.args[0]].frac)
    off = a - ilo * width                        # exact affine in one table cell
    off = ia.Interval(np.where(jump, 0.0, off.lo), np.where(jump, width, off.hi), off.d, off.h, off.order)
    return unbounded_where(off, jump, dims)


def cell_enclosure(rule, n, nodes, a, inputs: dict):
    """``rule`` (:func:`lut_cell`, :func:`index_cell`, :func:`mask_cell`) applied to node ``n``
    with argument enclosure ``a`` and input enclosures ``inputs`` (Intervals or centred forms:
    the centre point and the whole cell are then each enclosed on their own)."""
    if isinstance(a, cn.Centred):
        return cn.Centred(*(rule(n, nodes, getattr(a, p), {k: getattr(v, p) for k, v in inputs.items()},
                                 a.h.shape[0]) for p in ("c", "x")), a.h, tighten=False)
    return rule(n, nodes, a, inputs, dims(inputs))


def feature_cuts(nodes, cone, rounding=None) -> tuple:
    """``(argument node, shift)`` of every index or mask node of ``cone`` whose argument is no
    :func:`cut_chain` of an input: cells of a computed value (a feature), whose edges are
    curves across the certifier's cells, not planes it can be aligned to; and, given the
    plan's ``rounding`` bounds, every one whose argument is rounded (a chain through a floor
    shift too: the hardware's cell may be the ideal one's neighbour, so it needs the cases)."""
    keys = {(nodes[i].args[0], nodes[i].param) for i in cone
            if nodes[i].op in ("index", "mask") and (cut_chain(nodes, nodes[i].args[0]) is None
                                                    or (rounding is not None and rounding[nodes[i].args[0]] > 0))}
    return tuple(sorted(keys))


def forced_cell(n, nodes, a, k):
    """Enclosure of index or mask node ``n`` (argument enclosure ``a``, an Interval or a
    centred form) with its cell number taken to be ``k`` (one per certifier cell): the constant
    ``k``, or the exact affine offset ``a - k 2**shift`` from that cell, which lies outside
    [0, 2**shift) wherever the argument does not lie in cell ``k`` (a caller forcing every cell
    number the argument can reach encloses the node's value over the whole cell, case by case)."""
    k = np.asarray(k, dtype=np.float64)
    if n.op == "mask":
        return a - k * np.ldexp(1.0, n.param - nodes[n.args[0]].frac)
    if isinstance(a, cn.Centred):
        return cn.Centred(ia.Interval(k, k, order=a.c.order), ia.Interval(k, k, order=a.x.order), a.h, tighten=False)
    return ia.Interval(k, k, order=a.order)
