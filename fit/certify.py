"""Certified bound of a plan's error over the continuous workspace box.

Per servo, the approximation error ``e(x) = P(x) - f(x)`` (PWM ticks) is bounded over the
whole real input box, not only at sample points:

- ``P`` is the plan's ideal function (:func:`ikseries.sim.golden.evaluate_ideal`: unrounded
  constants, exact shifts), ``f`` the reference pulse width,
  ``calibration(geometry.angles(xp, *inputs)) * ticks_per_pu`` (a closed form evaluated on
  intervals; a chain's numeric IK enclosed per cell by a Krawczyk step,
  :mod:`ikseries.chain.enclose`);
- the box is covered by cells; on a cell with centre ``c`` and half-widths ``h`` the bound is
  the least of the plain interval enclosure of ``e``, the mean-value form
  ``|e(c)| + sum_k sup|de/dx_k (cell)| h_k`` and the second-order Taylor form
  ``|e(c)| + sum_k |de/dx_k (c)| h_k + 1/2 sum_jk sup|d2e/dx_j dx_k (cell)| h_j h_k``, with
  ``e(c)`` and its gradient enclosed by interval arithmetic at the point and the derivatives
  enclosed over the cell by interval forward-mode differentiation of both ``P`` and ``f``
  (:mod:`ikseries.fit.interval`). Every intermediate value of ``P`` and ``f`` is evaluated in
  centred form (:mod:`ikseries.fit.centred`): its cell enclosure is intersected with its own
  mean-value and Taylor forms about the centre, so a Horner chain stays tight and a clamp whose
  argument provably stays inside its range over the cell passes the Hessian through. Where a
  clamp may switch inside the cell, ``e`` is not twice differentiable and only the first two
  forms apply;
- cells whose bound exceeds the target are bisected along the input contributing most to the
  bound, until every cell meets the target or the cell budget is spent (the bound is then
  still certified, only above the target). A half first gets the Taylor form with its
  parent's enclosure of the second derivatives (an enclosure of the supremum over the parent is
  one over the half), which needs ``e`` and its gradient at the centre only: a point
  evaluation, without second derivatives; only where that misses the target are the
  derivatives enclosed over the half itself (every second split, see ``FULL_AGE``).
  A cell whose bound is not finite (the reference has no enclosure there) is split first; one
  left once the budget is spent refuses the certificate (:class:`UnboundedCellError`).

A piecewise plan cuts inputs into table cells (``index``, ``mask``) and looks its
coefficients up per cell (``lut``): the initial cells are aligned to the table edges of every
cut input, cells are half-open along cut inputs with a degenerate last slab at the box's upper
end, so that on every cell each index is one value, the looked-up coefficients are constants
and the offset in the cell an exact affine function of the input; a grid over two inputs
(its table address from both cell numbers) is aligned along both (see :mod:`ikseries.fit.cut`
for the argument). A cut of a computed, rounded value (a feature cut: its cell edges are curves
across the certifier's cells) is split into cases instead, one per cell number the feature can
take over the certifier's cell once widened by its rounding bound, each case smooth and bounded
on its own (:class:`_ErrorFunction`).

The certified total error per servo adds the certified quantization bound of the integer
accumulator (:meth:`Plan.rounding_bounds`), the rounding from the accumulator to the output
integer (half a tick for round-half-up) and, if the output is clamped, the largest distance of
``f`` from the clamp range (0 when the reference stays inside it).

The box is ``[lo, hi] * 2**-frac`` of every plan input: the inputs are clamped to that range,
so it covers every value the hardware can see.
"""
from __future__ import annotations

from collections import Counter

import time
from functools import partial
from dataclasses import asdict, dataclass

import numpy as np

from . import centred as cn
from . import interval as ia
from .cut import chain_range, cut_chain, feature_cuts, forced_cell
from .ops import OPS
from .parallel import servo_map
from .plan import Plan

__all__ = ["CertificationError", "UnboundedCellError", "ServoCertificate", "Certificate", "certify", "output_rounding",
           "DEFAULT_MAX_CELLS", "MISS_GRID"]

#: Default budget of evaluated cells per servo.
DEFAULT_MAX_CELLS = 400_000
_CHUNK = 8192


class CertificationError(ValueError):
    """A plan whose certified error exceeds the tolerance."""


class UnboundedCellError(CertificationError):
    """A cell over which the error has no finite bound once the cell budget is spent: the
    reference (or the plan) has no enclosure there, so no refit can be certified either."""


@dataclass(frozen=True)
class ServoCertificate:
    """Certified error of one servo (all figures in pulse units unless stated)."""

    name: str
    approximation_pu: float   # certified sup |P - f| over the box
    sampled_pu: float         # max |P - f| enclosure at the evaluated cell centres (lower bound)
    rounding_pu: float        # certified |integer accumulator - P|
    output_rounding_pu: float  # accumulator -> output integer (half a tick for round-half-up)
    clamp_pu: float           # largest distance of f from the output clamp range (0 if inside)
    target_pu: float          # refinement target for approximation_pu
    converged: bool           # every cell met the target
    cells: int                # cells in the final cover of the box
    evaluated: int            # cells evaluated during refinement
    worst: dict               # the cell with the largest bound: lo, hi per input, bound_pu
    seconds: float
    #: sampled counterexamples: evaluated cells whose centre errs by more than the target, the
    #: worst of each region of a ``MISS_GRID``-per-input grid over the box, as (lo, hi, error_pu)
    #: with lo, hi per input in the box's order (the fit samples them on a refit)
    misses: tuple = ()

    @property
    def total_pu(self) -> float:
        """Certified bound of |emitted pulse - reference pulse| over the box."""
        return self.approximation_pu + self.rounding_pu + self.output_rounding_pu + self.clamp_pu


@dataclass(frozen=True)
class Certificate:
    """Certified error bounds of every servo of a plan over the workspace box."""

    servos: tuple[ServoCertificate, ...]
    box: dict                 # input name -> (lo, hi) real values certified over
    method: str

    def check(self, tolerance: float) -> None:
        """Raise :class:`CertificationError` if any servo's certified total exceeds ``tolerance``.

        Raises
        ------
        CertificationError
            Naming the first failing servo, its certified total and the tolerance.
        """
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not tolerance > 0:
            raise ValueError(f"tolerance must be a number > 0 pu, not {tolerance!r}")
        for s in self.servos:
            if not s.total_pu <= tolerance:
                raise CertificationError(
                    f"servo {s.name}: certified error {s.total_pu:.4f} pu exceeds the tolerance "
                    f"{tolerance:g} pu (approximation {s.approximation_pu:.4f}"
                    f"{'' if s.converged else ' (cell budget spent)'} + quantization "
                    f"{s.rounding_pu:.4f} + output rounding {s.output_rounding_pu:.4f}"
                    f"{f' + clamp {s.clamp_pu:.4f}' if s.clamp_pu else ''} pu)")

    def to_json(self) -> dict:
        return {"method": self.method, "box": {k: list(v) for k, v in self.box.items()},
                "servos": [{**asdict(s), "total_pu": s.total_pu} for s in self.servos]}

    def lines(self) -> list[str]:
        """Human-readable summary, one line per servo."""
        return [f"{s.name}: certified <= {s.total_pu:.4f} pu (approximation {s.approximation_pu:.4f}, "
                f"sampled {s.sampled_pu:.4f}; quantization {s.rounding_pu:.4f}; output rounding "
                f"{s.output_rounding_pu:.4f}{f'; clamp {s.clamp_pu:.4f}' if s.clamp_pu else ''}) "
                f"over {s.cells} cells, {s.seconds:.1f} s" + ("" if s.converged else " [budget spent]")
                for s in self.servos]


# -- the plan's ideal function over intervals ----------------------------------------------------
def _plan_function(plan: Plan, node: int):
    """``(values, force) -> Interval`` of the ideal real value of ``node`` for input Intervals by
    name (over each cell; half-open along the inputs that index / mask nodes cut, unless
    degenerate there: see :mod:`ikseries.fit.cut`); ``force`` maps a feature cut's ``(argument
    node, shift)`` to the cell number its index and mask nodes take in each cell
    (:func:`~ikseries.fit.cut.forced_cell`)."""
    run = _plan_values(plan, (node,))
    return lambda values, force=None: run(values, force)[0]


def _plan_values(plan: Plan, targets: tuple):
    """:func:`_plan_function` of every node of ``targets`` at once: ``(values, force) ->``
    their Intervals, in order (their shared cones evaluated once)."""
    order = sorted(set().union(*(plan.cone(t) for t in targets)))
    last = {}
    for i in order:
        for a in plan.nodes[i].args:
            last[a] = i
    nodes, keep = plan.nodes, set(targets)

    def run(values: dict, force: dict | None = None) -> tuple:
        vals: dict = {}
        with np.errstate(invalid="ignore"):     # 0 * inf of an unbounded derivative: NaN, no bound
            for i in order:
                n = nodes[i]
                if force is not None and n.op in ("index", "mask") and (n.args[0], n.param) in force:
                    vals[i] = forced_cell(n, nodes, vals[n.args[0]], force[n.args[0], n.param])
                else:
                    vals[i] = OPS[n.op].enclose(n, nodes, [vals[a] for a in n.args], values)
                for a in set(n.args):
                    if last.get(a) == i and a not in keep:
                        del vals[a]
        return tuple(vals[t] for t in targets)
    return run




# -- the reference --------------------------------------------------------------------------------
def _reference_function(robot, servo: int, ticks_per_pu: float):
    """``values -> Interval`` of the reference pulse width of ``servo`` in ticks."""
    cal = robot.joint_calibration
    names = [i.name for i in robot.workspace.inputs]

    def run(values: dict) -> ia.Interval:
        xp = cn.MATH if isinstance(values[names[0]], cn.Centred) else ia.MATH
        angle = robot.geometry.angles(xp, *(values[k] for k in names))[servo]
        # a calibration table is a sum of clamps (ikseries.calibration): cn.clamp takes both namespaces
        return cal.pulse(servo, angle, cn.clamp) * ticks_per_pu
    return run


# -- output stage -----------------------------------------------------------------------------------
def _summands(plan: Plan, i: int) -> tuple[Counter, int]:
    """The terms of the adder tree at node ``i``: its non-constant leaves (with multiplicity)
    and the integer sum of its constants (an addition's operands share its binary point, so
    the tree's value is the leaves' sum plus that). A table counts as its first entry (a
    constant) plus the table of its entries less that one, so a table with a constant added to
    every entry (:meth:`~ikseries.fit.plan.PlanBuilder.add` stores a rounding half there) is
    the same term."""
    leaves, const, todo = Counter(), 0, [i]
    while todo:
        n = plan.nodes[j := todo.pop()]
        if n.op == "add":
            todo.extend(n.args)
        elif n.op == "const":
            const += n.param
        elif n.op == "lut":
            const += n.param[0]
            leaves["lut", n.args, n.frac, tuple(v - n.param[0] for v in n.param)] += 1
        else:
            leaves[j] += 1
    return leaves, const


def _constant_offset(plan: Plan, i: int, acc: int) -> int | None:
    """The integer ``c`` with node ``i`` = accumulator ``acc`` + ``c`` when both are sums of
    the same non-constant terms on one binary point (the rounding constant added earlier in
    the tree, where it waits for no product), else None."""
    if plan.nodes[i].op != "add" or plan.nodes[i].frac != plan.nodes[acc].frac:
        return None
    (mine, c), (theirs, c_acc) = _summands(plan, i), _summands(plan, acc)
    return c - c_acc if mine == theirs else None


def output_rounding(plan: Plan, k: int) -> tuple[float, tuple[float, float] | None]:
    """Bound on |output integer - accumulator| (before any clamp) and the clamp range, in ticks.

    The path from ``outputs[k].node`` down to ``outputs[k].preround`` may be an optional clamp
    over additions of constants and shifts (round half up: ``shr(add(acc, half))`` gives half a
    tick); the additions may also be one sum of the accumulator's own terms plus constants.

    Raises
    ------
    ValueError
        If the path holds any other operation.
    """
    o = plan.outputs[k]
    i, rng = o.node, None
    n = plan.nodes[i]
    if n.op == "clamp":
        rng = (np.ldexp(float(n.param[0]), -n.frac), np.ldexp(float(n.param[1]), -n.frac))
        i = n.args[0]
    chain = []     # ("add", real constant) or ("shr", node), from the accumulator up
    while i != o.preround:
        n = plan.nodes[i]
        if n.op in ("shr", "shl"):     # a shl is exact: nothing to record
            if n.op == "shr":
                chain.append(("shr", n))
            i = n.args[0]
        elif (c := _constant_offset(plan, i, o.preround)) is not None:
            chain.append(("add", np.ldexp(float(c), -n.frac)))
            break
        elif n.op == "add" and any(plan.nodes[a].op == "const" for a in n.args):
            j = 1 if plan.nodes[n.args[1]].op == "const" else 0
            c = plan.nodes[n.args[j]]
            chain.append(("add", np.ldexp(float(c.param), -c.frac)))
            i = n.args[1 - j]
        else:
            raise ValueError(f"output {o.name}: the path from node {o.node} to the accumulator "
                             f"{o.preround} must be a clamp over constant additions and shifts, "
                             f"not a {n.op!r} node ({i})")
    lo = hi = 0.0      # range of (value - accumulator value), real
    for kind, x in reversed(chain):
        if kind == "add":
            lo, hi = lo + x, hi + x
        elif kind == "shr":   # floor to frac(x) bits: lowers the value by < 2**-frac(x)
            lo -= np.ldexp(1.0 - 2.0 ** -x.param, -x.frac)
    return max(abs(lo), abs(hi)), rng


# -- cells -------------------------------------------------------------------------------------------
def _sum_up(rows):
    """Upward-rounded sum over the first axis."""
    total = rows[0]
    for r in rows[1:]:
        total = ia._up(total + r)
    return total


def _taylor(e_c: ia.Interval, hmag: np.ndarray, h: np.ndarray):
    """The second-order Taylor form |e(c)| + sum_k |de/dx_k(c)| h_k + 1/2 sum_jk H_jk h_j h_k
    with ``hmag`` (m, N) >= sup |d2e/dx_j dx_k| over the cell; returns it and the per-input
    contributions (n, N) (each Hessian term attributed half to each of its two inputs)."""
    n = h.shape[0]
    j, k = ia.hessian_pairs(n)
    weight = np.where(j == k, 0.5, 1.0)[:, None]                          # off-diagonal twice
    q = ia._up(ia._up(hmag * ia._up(h[j] * h[k])) * weight)
    lin = ia._up(e_c.dmag(n) * h)
    c2 = lin.copy()
    for p in range(len(j)):                                                # attribute to axes
        c2[j[p]] = ia._up(c2[j[p]] + 0.5 * q[p])
        c2[k[p]] = ia._up(c2[k[p]] + 0.5 * q[p])
    return ia._up(ia._up(e_c.mag + _sum_up(lin)) + _sum_up(q)), c2


class _Bounds:
    """Per cell: the bound of |e|, the per-input contributions (N, n) of the form used, the
    enclosure of |e(c)|, the range of f, and sup |d2e| and sup |d2f| (m, N) over the cell
    (NaN where not twice differentiable), which every sub-cell inherits, and ``age``: 0 where
    those were enclosed over this cell itself, else the number of splits since."""

    __slots__ = ("bound", "contrib", "centre", "f_lo", "f_hi", "he", "hf", "age")

    def __init__(self, bound, contrib, centre, f_lo, f_hi, he, hf, age):
        self.bound, self.contrib, self.centre = bound, contrib, centre
        self.f_lo, self.f_hi, self.he, self.hf, self.age = f_lo, f_hi, he, hf, age

    @classmethod
    def empty(cls, size: int, n: int, inherited: "_Bounds | None") -> "_Bounds":
        m = n * (n + 1) // 2
        if inherited is None:
            inherited = cls(None, None, None, np.full(size, -np.inf), np.full(size, np.inf),
                            np.full((m, size), np.nan), np.full((m, size), np.nan), None)
        return cls(np.full(size, np.inf), np.full((size, n), np.inf), np.zeros(size), inherited.f_lo.copy(),
                   inherited.f_hi.copy(), inherited.he.copy(), inherited.hf.copy(),
                   np.full(size, np.iinfo(np.int64).max // 2) if inherited.age is None else inherited.age.copy())

    def put(self, rows, other: "_Bounds") -> None:
        """Take ``other``'s figures for ``rows`` where they are better (every one is valid)."""
        better = other.bound <= self.bound[rows]
        self.bound[rows] = np.fmin(self.bound[rows], other.bound)
        self.contrib[rows] = np.where(better[:, None], other.contrib, self.contrib[rows])
        self.centre[rows] = np.fmax(self.centre[rows], other.centre)
        self.f_lo[rows] = np.fmax(self.f_lo[rows], other.f_lo)
        self.f_hi[rows] = np.fmin(self.f_hi[rows], other.f_hi)
        if other.he is not None:   # both enclose the sup over the cell: keep the smaller
            self.he[:, rows] = np.fmin(self.he[:, rows], other.he)
            self.hf[:, rows] = np.fmin(self.hf[:, rows], other.hf)
            self.age[rows] = 0

    def subset(self, rows) -> "_Bounds":
        return _Bounds(self.bound[rows], self.contrib[rows], self.centre[rows], self.f_lo[rows],
                       self.f_hi[rows], self.he[:, rows], self.hf[:, rows], self.age[rows])

    def twice(self) -> "_Bounds":
        """The figures of each cell for both of its halves (in :func:`_split`'s order)."""
        rows = [np.concatenate([x, x]) for x in (self.bound, self.contrib, self.centre, self.f_lo, self.f_hi)]
        return _Bounds(*rows, *(np.concatenate([x, x], axis=1) for x in (self.he, self.hf)),
                       np.concatenate([self.age, self.age]) + 1)


def _finite(x):
    return np.where(np.isfinite(x), x, np.inf)


def _check_centres(e_c, names, lo, hi):
    bad = np.isnan(e_c.lo) | np.isnan(e_c.hi)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ia.IntervalDomainError(f"the plan and the reference must be defined at every cell "
                                     f"centre, not at {dict(zip(names, (0.5 * (lo[i] + hi[i])).tolist()))}")


def _cell_bounds(err, names, lo, hi) -> _Bounds:
    """Bounds of |e| on cells [lo, hi] (shape (N, n)): the least of the plain enclosure, the
    mean-value form and the second-order Taylor form, from a centred evaluation over each cell;
    with feature cuts, those of the worst case (:meth:`_ErrorFunction.cases`)."""
    if not err.keys:
        return _cell_bounds_at(err, names, lo, hi)
    rows, force, wild = err.cases(dict(zip(names, cn.variables(lo, hi))), len(lo))
    return _worst_case(_cell_bounds_at(partial(err, force=force), names, lo[rows], hi[rows]), rows, wild)


def _worst_case(b: _Bounds, rows, wild) -> _Bounds:
    """Per cell, the figures of its worst case among ``b``'s (case ``i`` in cell ``rows[i]``):
    no bound where ``wild``; the least |e(c)| of the cases (the hardware's is one of them);
    no second derivatives where there are several cases (a sub-cell's centre form must not
    take one case's for all)."""
    size = len(wild)
    order = np.lexsort((b.bound, rows))
    r = rows[order]
    pick = order[np.append(r[1:] != r[:-1], True)]           # the worst case of each cell, in order
    several = (np.bincount(rows, minlength=size) > 1) | wild
    centre = np.full(size, np.inf)
    np.minimum.at(centre, rows, b.centre)
    he, hf = (np.where(several, np.nan, x[:, pick]) for x in (b.he, b.hf))
    return _Bounds(np.where(wild, np.inf, b.bound[pick]), np.where(wild[:, None], np.inf, b.contrib[pick]),
                   np.where(wild, 0.0, centre), b.f_lo[pick], b.f_hi[pick], he, hf, None)


def _cell_bounds_at(err, names, lo, hi) -> _Bounds:
    """:func:`_cell_bounds` of one case per cell (``err`` with its cell numbers forced)."""
    n = len(names)
    cvars = cn.variables(lo, hi)
    h = cvars[0].h                                                        # (n, N) half-widths
    with ia.lenient():   # a cell too coarse for an enclosure gets NaN: it is split, not fatal
        e, f = err(dict(zip(names, cvars)))
    e_c, e_cell, f_cell = e.c, e.x, f.x
    _check_centres(e_c, names, lo, hi)
    # mean-value form: |e(c)| + sum_k sup|de/dx_k| h_k
    c1 = ia._up(e_cell.dmag(n) * h)
    b1 = ia._up(e_c.mag + _sum_up(c1))
    he = e_cell.hmag(n)
    b2, c2 = _taylor(e_c, he, h)
    bound = _finite(np.fmin(e_cell.mag, np.fmin(b1, b2)))
    contrib = _finite(np.where(np.isfinite(b2) & (b2 <= b1), c2, c1)).T
    size = len(lo)
    return _Bounds(bound, contrib, np.broadcast_to(e_c.mag, (size,)), np.broadcast_to(f_cell.lo, (size,)),
                   np.broadcast_to(f_cell.hi, (size,)), np.array(he), np.array(f_cell.hmag(n)), None)


def _centre_bounds(err, names, lo, hi, parent: _Bounds) -> _Bounds:
    """Bounds of |e| on cells [lo, hi] from e and its gradient at the cell centre alone and the
    second derivatives ``parent.he`` of a cell containing each one: the Taylor form with the
    parent's Hessian enclosure (valid, as the sub-cell's supremum is at most the parent's),
    without the Hessians of every intermediate value that :func:`_cell_bounds` carries. The
    range of f is the parent's, intersected with f's own Taylor form. With feature cuts, a cell
    whose centre reaches more than one case gets no bound (its parent's derivatives are those
    of the one case the parent reached)."""
    if not err.keys:
        return _centre_bounds_at(err, names, lo, hi, parent)
    c, _ = cn.centres(lo, hi)
    _, force, wild = err.cases(dict(zip(names, ia.variables(c, c, order=1))), len(lo), single=True)
    b = _centre_bounds_at(partial(err, force=force), names, lo, hi, parent)
    b.bound = np.where(wild, np.inf, b.bound)
    return b


def _centre_bounds_at(err, names, lo, hi, parent: _Bounds) -> _Bounds:
    """:func:`_centre_bounds` of one case per cell."""
    c, h = cn.centres(lo, hi)
    with ia.lenient():
        e_c, f_c = err(dict(zip(names, ia.variables(c, c, order=1))))
    _check_centres(e_c, names, lo, hi)
    bound, c2 = _taylor(e_c, parent.he, h)
    size = len(lo)
    f_rad, _ = _taylor(ia.Interval(np.zeros(size), np.zeros(size), f_c.d, order=1), parent.hf, h)
    f_lo = np.fmax(parent.f_lo, np.broadcast_to(ia._down(f_c.lo - f_rad), (size,)))
    f_hi = np.fmin(parent.f_hi, np.broadcast_to(ia._up(f_c.hi + f_rad), (size,)))
    return _Bounds(_finite(bound), _finite(c2).T, np.broadcast_to(e_c.mag, (size,)), f_lo, f_hi, None, None, None)


def _table_edges(plan: Plan, cone, names, box_lo, box_hi):
    """Per input, the points strictly inside the box where some index node of ``cone`` (whose
    argument is a :func:`~ikseries.fit.cut.cut_chain` of the input) steps to its next cell, and
    whether any index or mask node cuts the input."""
    edges = [[] for _ in names]
    cut = [False] * len(names)
    for i in sorted(cone):
        n = plan.nodes[i]
        chain = cut_chain(plan.nodes, n.args[0]) if OPS[n.op].cuts else None
        if chain is None:
            continue
        j = names.index(chain[0])
        cut[j] = True
        k = plan.nodes[n.args[0]].frac - n.param
        g_lo, g_hi, _ = chain_range(chain[1], box_lo[j], box_hi[j])
        for m in range(int(np.floor(np.ldexp(g_lo, k))) + 1, int(np.floor(np.ldexp(g_hi, k))) + 1):
            x = np.ldexp(float(m), -k)            # the argument's value at the step; back to the input
            for step in reversed(chain[1]):       # (a float nearest the edge if not exact: the
                if step[0] == "add":              # cells next to it then straddle, soundly)
                    x = x - step[1]
                elif step[0] == "scale":
                    x = np.ldexp(x, -step[1])
                elif not step[1] < x <= step[2]:  # a clamp: the index does not step inside it
                    break
            else:
                if box_lo[j] < x < box_hi[j]:
                    edges[j].append(float(x))
    return [np.array(sorted(set(e))) for e in edges], cut


def _initial_cells(box_lo, box_hi, per_axis, edges=None, cut=None):
    """Grid of ``per_axis`` equal cells per input, further cut at the input's table ``edges``;
    along every ``cut`` input a last, degenerate slab at the box's upper end (cells are
    half-open along cut inputs, so that point needs a cell of its own)."""
    n = len(box_lo)
    edges = edges or [()] * n
    cut = cut or [False] * n
    sides = []
    for a, b, m, e, c in zip(box_lo, box_hi, per_axis, edges, cut):
        ax = np.linspace(a, b, m + 1)
        ax[0], ax[-1] = a, b                                   # exact box ends
        ax = np.unique(np.concatenate([ax, e]))
        lo, hi = ax[:-1], ax[1:]
        if c:
            lo, hi = np.append(lo, b), np.append(hi, b)
        sides.append((lo, hi))
    idx = np.meshgrid(*(np.arange(len(lo)) for lo, _ in sides), indexing="ij")
    lo = np.stack([side[0][g.ravel()] for side, g in zip(sides, idx)], 1)
    hi = np.stack([side[1][g.ravel()] for side, g in zip(sides, idx)], 1)
    return lo, hi


def _split(lo, hi, axis):
    """Bisect every cell along its ``axis``; cells too narrow to split are returned apart.

    The halves [lo, mid) and [mid, hi) of a cell partition it (half-open along a cut input),
    so a cell within one table cell has both halves within it: splitting never straddles."""
    rows = np.arange(len(lo))
    mid = 0.5 * (lo[rows, axis] + hi[rows, axis])
    ok = (mid > lo[rows, axis]) & (mid < hi[rows, axis])
    lo, hi, mid, axis, rows = lo[ok], hi[ok], mid[ok], axis[ok], rows[ok]
    r = np.arange(len(lo))
    lo2, hi1 = lo.copy(), hi.copy()
    hi1[r, axis] = mid
    lo2[r, axis] = mid
    return np.concatenate([lo, lo2]), np.concatenate([hi1, hi]), ~ok


def _split_axis(contrib, lo, hi, box_width):
    """The input with the largest contribution sup|de/dx_k| h_k; the relatively widest side
    where the contributions are not all finite."""
    flat = hi <= lo                            # a degenerate side cannot be split
    contrib = np.where(flat, 0.0, contrib)
    axis = np.argmax(np.where(flat, -1.0, contrib), axis=1)
    wild = ~np.all(np.isfinite(contrib), axis=1)
    axis[wild] = np.argmax(np.where(flat, -1.0, (hi - lo) / box_width)[wild], axis=1)
    return axis


#: seconds between progress lines during refinement (a round of many cells can take long)
PROGRESS_SECONDS = 2.0


def _throttled(progress, seconds: float):
    """``progress`` passing on a message at most once every ``seconds`` (the first at once)."""
    last = [-np.inf]

    def say(msg):
        now = time.perf_counter()
        if now - last[0] >= seconds:
            last[0] = now
            progress(msg)
    return say


class _Cover:
    """The final cells of a refinement: their number, the worst one, the largest |e(c)| seen
    and the range of f over them."""

    def __init__(self):
        self.cells, self.sampled = 0, 0.0
        self.best = {"bound": -np.inf, "lo": None, "hi": None}
        self.f_lo, self.f_hi = np.inf, -np.inf

    def add(self, b: _Bounds, rows, lo, hi) -> None:
        """Cells ``rows`` of ``b`` (bounds of the cells [lo, hi]) as final."""
        self.cells += len(rows)
        if not len(rows):
            return
        j = rows[int(np.argmax(b.bound[rows]))]
        if b.bound[j] > self.best["bound"]:
            self.best.update(bound=float(b.bound[j]), lo=lo[j].copy(), hi=hi[j].copy())
        self.f_lo, self.f_hi = min(self.f_lo, float(b.f_lo[rows].min())), max(self.f_hi, float(b.f_hi[rows].max()))


#: cells per input of the grid over the box whose worst sampled counterexample each is kept
MISS_GRID = 8


class _Misses:
    """Sampled counterexamples of a refinement: per region of a ``MISS_GRID``-per-input grid
    over the box, the evaluated cell whose centre errs most, if by more than the target."""

    def __init__(self, box_lo, box_hi):
        self.box_lo, self.width = box_lo, np.where(box_hi > box_lo, box_hi - box_lo, 1.0)
        self.worst: dict = {}           # region -> (|e(c)|, lo, hi)

    def add(self, b: _Bounds, lo, hi, target) -> None:
        rows = np.flatnonzero(b.centre > target)
        if not len(rows):
            return
        c = 0.5 * (lo[rows] + hi[rows])
        cell = np.clip(((c - self.box_lo) / self.width * MISS_GRID).astype(np.int64), 0, MISS_GRID - 1)
        region = np.ravel_multi_index(cell.T, (MISS_GRID,) * lo.shape[1])
        order = np.lexsort((-b.centre[rows], region))        # per region, the worst first
        first = order[np.insert(region[order][1:] != region[order][:-1], 0, True)]
        for i in first:
            r, j = int(region[i]), rows[i]
            if r not in self.worst or b.centre[j] > self.worst[r][0]:
                self.worst[r] = (float(b.centre[j]), lo[j].copy(), hi[j].copy())

    def cells(self, tpp: float) -> tuple:
        """(lo, hi, error_pu) per region, the regions in order."""
        return tuple((tuple(lo.tolist()), tuple(hi.tolist()), e / tpp)
                     for e, lo, hi in (self.worst[r] for r in sorted(self.worst)))


#: a cell whose centre form misses the target, with second derivatives enclosed over an
#: ancestor fewer than ``FULL_AGE`` splits up, is split at once (an enclosure over the cell
#: itself would rarely be enough); else it is enclosed over itself first
FULL_AGE = 2


def _evaluate(err, names, lo, hi, inherited: _Bounds | None, target, say) -> _Bounds:
    """Bounds of cells [lo, hi]: where a cell inherits finite second derivatives, the centre
    form (:func:`_centre_bounds`); where that does not apply, or misses ``target`` with
    derivatives from ``FULL_AGE`` or more splits up, the centred evaluation over the cell
    (:func:`_cell_bounds`)."""
    out = _Bounds.empty(len(lo), len(names), inherited)
    cheap = np.zeros(len(lo), dtype=bool)
    done = [0, 0]                                  # centre forms, cell enclosures

    def report(rows):
        say(f"{len(lo)} cells: {done[0]} centre forms, {done[1]} cell enclosures evaluated, max bound so far "
            f"{float(np.max(out.bound[rows])):.4g} ticks")

    if inherited is not None:
        cheap = np.all(np.isfinite(inherited.he), axis=0)
        rows = np.flatnonzero(cheap)
        for s in range(0, len(rows), _CHUNK):
            part = rows[s:s + _CHUNK]
            out.put(part, _centre_bounds(err, names, lo[part], hi[part], inherited.subset(part)))
            done[0] += len(part)
            report(rows[:s + len(part)])
    fresh = cheap & (inherited.age < FULL_AGE) if inherited is not None else cheap
    rows = np.flatnonzero((out.bound > target) & ~fresh)
    for s in range(0, len(rows), _CHUNK):
        part = rows[s:s + _CHUNK]
        out.put(part, _cell_bounds(err, names, lo[part], hi[part]))
        done[1] += len(part)
        report(rows[:s + len(part)])
    return out


def _refine(err, names, box_lo, box_hi, target, per_axis, budget, progress, label, edges=None, cut=None):
    """Adaptive cover of the box within ``budget`` = (max_cells, per_start) evaluated cells (at
    least per_start times the starting cells); returns the summary of the final cells and the
    sampled counterexamples (:class:`_Misses`)."""
    lo, hi = _initial_cells(box_lo, box_hi, per_axis, edges, cut)
    max_cells = max(budget[0], budget[1] * len(lo))
    inherited, cover, misses = None, _Cover(), _Misses(box_lo, box_hi)
    evaluated, rnd = 0, 0
    say = _throttled(progress, PROGRESS_SECONDS)
    while len(lo):
        b = _evaluate(err, names, lo, hi, inherited, target, lambda msg: say(f"  {label}: round {rnd + 1}: {msg}"))
        cover.sampled = max(cover.sampled, float(b.centre.max()))
        misses.add(b, lo, hi, target)
        evaluated += len(lo)
        rnd += 1
        done = b.bound <= target
        cover.add(b, np.flatnonzero(done), lo, hi)
        todo = np.flatnonzero(~done)
        room = max(0, (max_cells - evaluated) // 2)
        if len(todo) > room:                      # split the worst cells the budget allows
            order = todo[np.argsort(b.bound[todo])[::-1]]
            cover.add(b, order[room:], lo, hi)
            todo = order[:room]
        say(f"  {label}: round {rnd}: {len(lo)} cells, {evaluated} evaluated, max bound {b.bound.max():.4g} "
            f"ticks (target {target:.4g}), {len(todo)} to split")
        if not len(todo):
            break
        new_lo, new_hi, stuck = _split(lo[todo], hi[todo], _split_axis(b.contrib[todo], lo[todo], hi[todo],
                                                                       box_hi - box_lo))
        cover.add(b, todo[stuck], lo, hi)         # too narrow to split: final as they are
        inherited = b.subset(todo[~stuck]).twice()
        lo, hi = new_lo, new_hi
    return cover.best, cover.sampled, cover.cells, evaluated, (cover.f_lo, cover.f_hi), misses


def _unbounded(err, names, servo: str, best: dict) -> str:
    """The message of a final cell without a finite bound: the cell and, from a strict
    evaluation over it, why (an exception's ``reason`` if it has one, else its message)."""
    lo, hi = best["lo"][None], best["hi"][None]
    box = ", ".join(f"{k} in [{a:.6g}, {b:.6g}]" for k, a, b in zip(names, lo[0], hi[0]))
    try:
        err(dict(zip(names, cn.variables(lo, hi))))
        why = "the enclosure of the error is unbounded there"
    except (ia.IntervalDomainError, ZeroDivisionError) as e:
        why = getattr(e, "reason", str(e))
    return f"servo {servo}: no finite error bound over the cell ({box}) once the cell budget is spent: {why}"


class _ErrorFunction:
    """``values -> (e, f)`` Intervals: e = P - f and f for output ``k``, in ticks; and the case
    split of the plan's feature cuts (:meth:`cases`).

    A feature cut takes cells of a computed, rounded value: the hardware's cell number and
    offset come from the integer feature, within ``quant`` (its rounding bound) of the ideal
    one, so near a cell edge either neighbour's polynomial may be the one evaluated. Per
    certifier cell, every cell number the feature's enclosure widened by its rounding bound
    reaches is a case: the ideal function with the index forced to that number and the offset
    taken from it (exact and affine, a little outside the cell near its edges) is smooth over
    the whole certifier cell, so the centred forms apply to each case, and the cell's bound is
    the worst case's. The hardware's value at any point is its case's, with the offset
    rounded as :meth:`Plan.rounding_bounds` accounts (the index then exact)."""

    def __init__(self, plan: Plan, robot, k: int, quant):
        o = plan.outputs[k]
        if o.name not in robot.servos:
            raise ValueError(f"plan output must be one of the robot's servos {list(robot.servos)}, "
                             f"not {o.name!r}")
        self.p_fn = _plan_function(plan, o.preround)
        self.f_fn = _reference_function(robot, robot.servos.index(o.name), o.ticks_per_pu)
        self.keys = feature_cuts(plan.nodes, plan.cone(o.preround), quant)
        self._feature_values = _plan_values(plan, tuple(a for a, _ in self.keys))
        self._args = [(float(quant[a]), plan.nodes[a].frac - sh, plan.nodes[a].lo >> sh, plan.nodes[a].hi >> sh)
                      for a, sh in self.keys]

    def __call__(self, values, force=None):
        f = self.f_fn(values)
        return self.p_fn(values, force) - f, f

    def cases(self, values, size: int, single: bool = False):
        """``(rows, force, wild)`` (with feature cuts, ``keys``): the certifier cell of each
        case, the forced cell numbers per case (``force`` of :func:`_plan_function`), and per
        cell whether it has no bound (an enclosure that is not finite, more than
        ``MAX_CASES`` cases, or with ``single`` more than one; such a cell gets one case, to
        be evaluated and then discarded)."""
        ranges, wild = [], np.zeros(size, dtype=bool)
        with ia.lenient():
            features = self._feature_values(values) if self.keys else ()
        for v, (eps, k, imin, imax) in zip(features, self._args):
            v = v.x if isinstance(v, cn.Centred) else v
            lo = np.floor(np.ldexp(np.broadcast_to(ia._down(v.lo - eps), (size,)), k))
            hi = np.floor(np.ldexp(np.broadcast_to(ia._up(v.hi + eps), (size,)), k))
            bad = ~(np.isfinite(lo) & np.isfinite(hi))
            lo = np.clip(np.where(bad, imin, lo), imin, imax)
            ranges.append((lo, np.maximum(lo, np.clip(np.where(bad, imin, hi), imin, imax))))
            wild |= bad
        count = np.prod([hi - lo + 1 for lo, hi in ranges], axis=0)
        wild |= count > (1 if single else MAX_CASES)
        count = np.where(wild, 1, count).astype(np.int64)
        rows = np.repeat(np.arange(size), count)
        j = np.arange(len(rows)) - np.repeat(np.cumsum(count) - count, count)   # case number in its cell
        force = {}
        for key, (lo, hi) in zip(self.keys, ranges):
            m = np.where(wild, 1, hi - lo + 1).astype(np.int64)[rows]
            force[key], j = lo[rows] + j % m, j // m
        return rows, force, wild


#: most cases (combinations of cell numbers of the feature cuts) per certifier cell; a cell
#: with more is split instead
MAX_CASES = 4


def _error_function(plan: Plan, robot, k: int, quant=None) -> _ErrorFunction:
    """The error function of output ``k`` (``quant``: the plan's rounding bounds, computed if
    not given)."""
    return _ErrorFunction(plan, robot, k, plan.rounding_bounds() if quant is None else quant)


def _box(robot, plan: Plan) -> tuple[list[str], np.ndarray, np.ndarray]:
    names = [i.name for i in robot.workspace.inputs]
    if sorted(names) != sorted(i.name for i in plan.inputs):
        raise ValueError(f"plan inputs must be the robot's inputs {names}, "
                         f"not {[i.name for i in plan.inputs]}")
    spec = {i.name: i for i in plan.inputs}
    lo = np.array([np.ldexp(float(spec[n].lo), -spec[n].frac) for n in names])
    hi = np.array([np.ldexp(float(spec[n].hi), -spec[n].frac) for n in names])
    return names, lo, hi


def certify(robot, plan: Plan, *, target_pu: float | None = None, max_cells: int = DEFAULT_MAX_CELLS,
            initial: int = 4, progress=lambda msg: None, jobs: int = 1, per_start: int = 0) -> Certificate:
    """Certified bound of every servo's error over the continuous workspace box.

    Parameters
    ----------
    robot : Robot
        Gives the reference: ``geometry.angles`` and the calibration.
    plan : Plan
        The fitted evaluation plan.
    target_pu : float, optional
        Refinement target for the approximation bound of every servo, in pu. Default: per
        servo, what the robot's tolerance leaves after the quantization and output rounding
        bounds (so that :meth:`Certificate.check` passes if the plan is good enough).
    max_cells : int
        Budget of evaluated cells per servo; when spent, the bound is still certified, only
        above the target.
    per_start : int
        A servo's budget is at least this many times its starting cells (a piecewise plan's
        table edges can make the starting grid a large part of ``max_cells``).
    initial : int
        Cells per input of the starting grid, which is further cut at the table edges of every
        input a piecewise plan cuts into cells.
    progress : callable
        Receives one progress message per refinement round.
    jobs : int
        Servos certified at a time, each in a process of its own (:func:`~.parallel.servo_map`);
        the certificate is the same whatever ``jobs``.

    Returns
    -------
    Certificate

    Raises
    ------
    UnboundedCellError
        Naming a cell where the error has no finite bound once the budget is spent (the
        reference could not be enclosed there, e.g. a chain's IK near a singular pose).
    """
    if isinstance(max_cells, bool) or not isinstance(max_cells, int) or max_cells < 1:
        raise ValueError(f"max_cells must be a positive integer, not {max_cells!r}")
    if isinstance(per_start, bool) or not isinstance(per_start, int) or per_start < 0:
        raise ValueError(f"per_start must be an integer >= 0, not {per_start!r}")
    if isinstance(initial, bool) or not isinstance(initial, int) or initial < 1:
        raise ValueError(f"initial must be a positive integer, not {initial!r}")
    if target_pu is not None and (isinstance(target_pu, bool) or not isinstance(target_pu, (int, float))
                                  or not target_pu > 0):
        raise ValueError(f"target_pu must be a number > 0 pu or None, not {target_pu!r}")
    names, box_lo, box_hi = _box(robot, plan)
    quant = plan.rounding_bounds()

    def one(k, say):
        c = _certify_output(robot, plan, k, names, box_lo, box_hi, quant, target_pu, (max_cells, per_start),
                            initial, say)
        say(Certificate((c,), {}, METHOD).lines()[0])
        return c
    servos = servo_map(one, range(len(plan.outputs)), jobs, progress)
    box = {n: (float(a), float(b)) for n, a, b in zip(names, box_lo, box_hi)}
    return Certificate(tuple(servos), box, METHOD)


def _certify_output(robot, plan, k, names, box_lo, box_hi, quant, target_pu, budget, initial, say):
    """The :class:`ServoCertificate` of output ``k`` (:func:`certify`); ``budget``: (max_cells,
    per_start)."""
    t0 = time.perf_counter()
    o = plan.outputs[k]
    tpp = o.ticks_per_pu
    out_round, clamp_rng = output_rounding(plan, k)
    rounding_pu, out_pu = quant[o.preround] / tpp, out_round / tpp
    target = robot.fit.tolerance_pu - rounding_pu - out_pu if target_pu is None else float(target_pu)
    err = _error_function(plan, robot, k, quant)
    edges, cut = _table_edges(plan, plan.cone(o.preround), names, box_lo, box_hi)
    best, sampled, cells, evaluated, (f_lo, f_hi), misses = _refine(
        err, names, box_lo, box_hi, target * tpp, [initial] * len(names), budget, say, o.name,
        edges, cut)
    if not np.isfinite(best["bound"]):
        raise UnboundedCellError(_unbounded(err, names, o.name, best))
    clamp = 0.0 if clamp_rng is None else max(0.0, clamp_rng[0] - f_lo, f_hi - clamp_rng[1])
    return ServoCertificate(
        o.name, best["bound"] / tpp, sampled / tpp, rounding_pu, out_pu, clamp / tpp, target,
        bool(best["bound"] <= target * tpp), cells, evaluated,
        {"lo": dict(zip(names, best["lo"].tolist())), "hi": dict(zip(names, best["hi"].tolist())),
         "bound_pu": best["bound"] / tpp},
        time.perf_counter() - t0, misses.cells(tpp))


METHOD = ("per cell the least of the plain interval enclosure, the mean-value form |e(c)| + "
          "sum_k sup|de/dx_k| h_k and the second-order Taylor form, on adaptively bisected cells "
          "(a half first with its parent's enclosure of the second derivatives); "
          "interval arithmetic with outward rounding and forward-mode first and second derivatives "
          "of the plan's ideal function and of the reference IK, every intermediate value in "
          "centred (mean-value / Taylor about the cell centre) form; box = plan input ranges "
          "[lo, hi] * 2**-frac")
