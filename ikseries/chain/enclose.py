"""Proven enclosures of a chain's IK over cells of targets: a Krawczyk (interval Newton) step.

The reference IK ``q(x)`` of a chain solves ``m(q) = g(x)``: ``m`` the solved quantities of the
servo angles (:meth:`Chain.measure_rows`: the fixed tip coordinates, the tool angle), ``g`` the
goal of the targets (:meth:`Chain.goal_rows`). Over a cell of targets whose goal box is ``P``:

- value: with ``q~`` the float Newton solution at the cell centre's goal (continued from the
  home pose, :mod:`.solve`) and ``Y`` the float inverse of ``J(q~) = dm/dq``, the test runs in
  the coordinates ``u``, ``q = q~ + Y u``, in which the solutions of a goal box lie in a box
  aligned with it (``u`` is about the goal's displacement): a box in ``q`` would have to hold
  the whole parallelepiped ``q~ + Y (P - m(q~))``, and the second-order terms over its corners
  make the test fail on cells a few mm wide. For ``phi(u) = u - (m(q~ + Y u) - p)`` and a box
  ``U`` about 0, the Krawczyk operator ``K(U) = (P - m(q~)) + C U`` with ``C`` enclosing
  ``I - J(z) Y`` over ``q~ + Y U``. If ``K(U)`` lies inside the interior of ``U``, every ``J Y``
  over ``U`` is nonsingular and every ``p`` in ``P`` has exactly one solution in ``q~ + Y U``,
  which lies in ``q~ + Y K(U)`` (Krawczyk 1969; Moore, Kearfott & Cloud, *Introduction to
  Interval Analysis*, 2009, sec. 8.4). ``C`` is ``I - J(q~) Y`` plus ``[Y^T m''(Q) Y] U`` (the
  second derivatives turned into ``u`` before magnitudes are taken, :meth:`_Centre.step`), and
  the second-order form ``K2`` (Taylor about 0) is tested too. ``U`` starts at
  ``+- 1.5 |P - m(q~)|`` and is inflated to 1.5 times the last ``K`` (not clipped to ``U``)
  up to :data:`TRIES` times; once proven, one more step over the hull of the enclosure and 0
  tightens it (for cells; a point's is tight at once).
- which solution: the centre's continued solution lies in ``Q = q~ + Y U`` (``q~`` does, within the
  Newton residual), and the unique solution in ``Q`` moves continuously with ``p`` across the
  (convex) box ``P`` without meeting a singular pose, so it is the home branch's over the
  whole cell: the continuation to any target of the cell can pass through the centre.
- gradient: differentiating ``m(q(x)) = g(x)``, ``J(q) dq/dx = dg/dx``, enclosed for every
  ``q`` in the enclosure and ``dg/dx`` in its own by the preconditioned fixed point
  ``X = Y B + (I - Y J) X`` (:func:`_solve`), with ``I - Y J`` over the enclosure written in
  ``u`` as well (:meth:`_Centre.contraction`);
- Hessian: once more, ``J(q) d2q/dx_j dx_k = d2g/dx_j dx_k - m''(q)[dq/dx_j, dq/dx_k]``, the
  same solve (:func:`_second`).

Every bound is rounded outwards with the operations of :mod:`ikseries.fit.interval`. Cells
where the continuation fails or ``K`` does not fall inside ``Q`` raise
:class:`ChainEnclosureError` naming the cell (within :func:`ikseries.fit.interval.lenient`:
NaN bounds, so that the certifier splits them).
"""
from __future__ import annotations

import numpy as np

from ..fit import centred as cn
from ..fit import interval as ia
from . import solve

__all__ = ["ChainEnclosureError", "enclosed_angles", "enclose", "TRIES"]

#: Krawczyk tests of one cell (each after inflating Q to 1.5 times the last K(Q)) before giving up
TRIES = 6
#: the first Q and every inflation: this many times the linear estimate / K(Q), about q~
INFLATE = 1.5
#: absolute slack of U (the solved quantities' units: mm, deg): a point cell's U is not degenerate
SLACK = 1e-12
#: iterations X <- (Y B + (I - Y J) X) intersected with X of the derivative solve
SOLVE_STEPS = 3


class ChainEnclosureError(ia.IntervalDomainError):
    """A cell of targets over which the chain's IK could not be enclosed; ``reason`` is the
    message without the cell."""

    def __init__(self, message: str, reason: str):
        super().__init__(message)
        self.reason = reason

    def __reduce__(self):      # pickles (from a fit's worker process) with its reason
        return type(self), (str(self), self.reason)


# -- interval vectors and matrices: (lo, hi) pairs of arrays (..., N), outward rounded -----------
def _add(a, b):
    return ia._down(a[0] + b[0]), ia._up(a[1] + b[1])


def _sub(a, b):
    return ia._down(a[0] - b[1]), ia._up(a[1] - b[0])


def _mag(a):
    return np.maximum(np.abs(a[0]), np.abs(a[1]))


def _sum(a, axis: int):
    """Outward-rounded sum of the pair ``a`` along ``axis``."""
    lo, hi = np.moveaxis(a[0], axis, 0), np.moveaxis(a[1], axis, 0)
    slo, shi = lo[0], hi[0]
    for i in range(1, lo.shape[0]):
        slo, shi = ia._down(slo + lo[i]), ia._up(shi + hi[i])
    return slo, shi


def _scale_bounds(lo, hi, y):
    """Outward-rounded enclosure of [lo, hi] * y for floats ``y`` (broadcasting): two products,
    not the four of two intervals."""
    p, q = lo * y, hi * y
    return ia._down(np.minimum(p, q)), ia._up(np.maximum(p, q))


def _matmul(a, b):
    """Interval matrices ``a`` (n, k, N) times ``b`` (k, m, N): (n, m, N). Either may instead be
    a float array (an exact matrix, such as the preconditioner)."""
    out = None
    for t in range((a if isinstance(a, np.ndarray) else a[0]).shape[1]):
        if isinstance(a, np.ndarray):
            p = _scale_bounds(b[0][None, t], b[1][None, t], a[:, t, None])
        elif isinstance(b, np.ndarray):
            p = _scale_bounds(a[0][:, t, None], a[1][:, t, None], b[None, t])
        else:
            p = ia._mul_bounds(a[0][:, t, None], a[1][:, t, None], b[0][None, t], b[1][None, t])
        out = p if out is None else _add(out, p)
    return out


def _matvec(a, v):
    """Interval (or float) matrices ``a`` (n, k, N) times interval vectors ``v`` (k, N): (n, N)."""
    p = _matmul(a, (v[0][:, None], v[1][:, None]))
    return p[0][:, 0], p[1][:, 0]


def _eye_minus(a):
    """I - a for square interval matrices a (n, n, N)."""
    n = a[0].shape[0]
    eye = np.eye(n)[:, :, None]
    return _sub((eye, eye), a)


# -- the chain's formulas on intervals -------------------------------------------------------------
def _rows(xs, size: int, n_in: int):
    """Value (m, N), gradient (m, n_in, N) and Hessian (m, n_in (n_in + 1) / 2, N) pairs of the
    Intervals (or floats) ``xs``, zeros where an Interval carries none."""
    xs = [ia.point(x) if not isinstance(x, ia.Interval) else x for x in xs]
    m2 = n_in * (n_in + 1) // 2

    def part(get, shape):
        lo = np.stack([np.broadcast_to(get(x)[0], shape) if get(x) is not None else np.zeros(shape) for x in xs])
        hi = np.stack([np.broadcast_to(get(x)[1], shape) if get(x) is not None else np.zeros(shape) for x in xs])
        return lo, hi
    value = part(lambda x: (x.lo, x.hi), (size,))
    grad = part(lambda x: x.d, (n_in, size))
    hess = part(lambda x: x.h, (m2, size))
    return value, grad, hess


def _stack(xs, size: int):
    """(lo, hi) (len(xs), N) of Intervals or floats."""
    xs = [ia.point(x) if not isinstance(x, ia.Interval) else x for x in xs]
    return (np.stack([np.broadcast_to(x.lo, (size,)) for x in xs]),
            np.stack([np.broadcast_to(x.hi, (size,)) for x in xs]))


def _derivatives(chain, qlo, qhi):
    """Enclosures over servo-angle boxes [qlo, qhi] (n, N) of the solved quantities m (n, N),
    their Jacobian (n, n, N) and second derivatives (n, mq, N): the chain's formulas
    (:meth:`Chain.derivatives`) on plain intervals, no derivative propagation needed."""
    size = qlo.shape[1]
    rows, jac, hess = chain.derivatives(ia.MATH, *ia.variables(qlo.T, qhi.T, order=0))

    def matrix(m):
        parts = [_stack(r, size) for r in m]
        return np.stack([p[0] for p in parts]), np.stack([p[1] for p in parts])
    return _stack(rows, size), matrix(jac), matrix(hess)


def _full(pairs, n: int):
    """The symmetric tensors (r, n, n, N) of second derivatives stored as pairs (r, mq, N)."""
    a, b = ia.hessian_pairs(n)
    index = np.zeros((n, n), dtype=int)
    index[a, b] = index[b, a] = np.arange(len(a))
    return pairs[0][:, index], pairs[1][:, index]


def _times_y(m, y):
    """sum_k m[..., k, :] y[k, t, :]: interval tensors ``m`` (..., n, N) times the float
    matrices ``y`` (n, n, N), giving (..., n, N)."""
    lead, (n, size) = m[0].shape[:-2], m[0].shape[-2:]
    flat = (int(np.prod(lead)), n, size)                         # explicit: size may be 0
    p = _matmul((m[0].reshape(flat), m[1].reshape(flat)), y)
    return p[0].reshape(lead + (n, size)), p[1].reshape(lead + (n, size))


def _contract(c0, slopes, d):
    """c0 - sum_t slopes[:, :, t] d_t: ``c0`` (n, n, N), ``slopes`` (n, n, n, N), ``d`` (n, N)."""
    t = ia._mul_bounds(slopes[0], slopes[1], d[0][None, None], d[1][None, None])
    return _sub(c0, _sum(t, 2))


class _Centre:
    """The float solutions ``qt`` (n, N) at the cell centres and what every step needs there:
    ``y`` the float inverse of the Jacobian (NaN where singular), ``f0`` the enclosure of
    m(q~), ``c0`` of I - Y J(q~) (the derivative solves) and ``c0u`` of I - J(q~) Y (the
    Krawczyk test in the coordinates u, q = q~ + Y u)."""

    def __init__(self, chain, qt):
        self.chain, self.qt = chain, qt
        f0, j0, _ = _derivatives(chain, qt, qt)
        jac = np.moveaxis(0.5 * (j0[0] + j0[1]), -1, 0)                 # (N, n, n)
        bad = ~np.all(np.isfinite(jac), axis=(1, 2))
        bad[~bad] = np.linalg.det(jac[~bad]) == 0.0
        jac[bad] = np.eye(jac.shape[1])
        y = np.linalg.inv(jac)
        y[bad] = np.nan
        self.y, self.f0 = np.moveaxis(y, 0, -1), f0
        self.c0 = _eye_minus(_matmul(self.y, j0))
        self.c0u = _eye_minus(_matmul(j0, self.y))

    def part(self, cells) -> "_Centre":
        out = object.__new__(_Centre)
        out.chain, out.qt, out.y = self.chain, self.qt[:, cells], self.y[:, :, cells]
        out.f0 = (self.f0[0][:, cells], self.f0[1][:, cells])
        out.c0 = (self.c0[0][:, :, cells], self.c0[1][:, :, cells])
        out.c0u = (self.c0u[0][:, :, cells], self.c0u[1][:, :, cells])
        return out

    def hull(self, u):
        """The boxes (n, N) enclosing q~ + Y u over the boxes ``u``."""
        return _add((self.qt, self.qt), _matvec(self.y, u))

    def slopes(self, u):
        """Over the boxes q~ + Y ``u``: the second derivatives preconditioned, [Y m''] (n, mq, N),
        and in the coordinates u, T = Y^T m'' Y (n, n, n, N; row, then the two u axes)."""
        q = self.hull(u)
        _, _, hess = _derivatives(self.chain, q[0], q[1])
        n = self.qt.shape[0]
        a = _times_y(_full(hess, n), self.y)                          # sum_k m''_rjk Y_kt
        t = _times_y((np.swapaxes(a[0], 1, 2), np.swapaxes(a[1], 1, 2)), self.y)   # sum_j Y_js (...)_rjt
        return _matmul(self.y, hess), t

    def contraction(self, yh, u):
        """An enclosure (n, n, N) of I - Y J(z) for every z = q~ + Y u with u in the boxes
        ``u``, from ``yh`` = [Y m''] over a box containing those z.

        J_rj(z) - J_rj(q~) = sum_k hbar_rjk (z - q~)_k with hbar_rjk an average of m''_rjk on
        the segment from q~ to z, and (z - q~)_k = sum_t Y_kt u_t; so Y (J(z) - J(q~)) lies in
        sum_t (sum_k [Y m'']_(., j, k) Y_kt) u_t. Preconditioning before the magnitudes are
        taken keeps the cancellations of Y J ~ I that plain interval arithmetic on J(Q) loses,
        and u, unlike z - q~, varies over a box aligned with the cell's goal box."""
        return _contract(self.c0, _times_y(_full(yh, self.qt.shape[0]), self.y), u)

    def step(self, base, u):
        """Enclosures over boxes ``u`` (containing 0) given ``base`` = P - m(q~): the Krawczyk
        operator K, the second-order form K2, ||C||_inf (N,) of its contraction C and [Y m'']
        over q~ + Y u (:meth:`slopes`).

        With phi(u) = u - (m(q~ + Y u) - p), whose Jacobian is I - J(q~ + Y u) Y, K = (P - m(q~))
        + C U with C enclosing I - J Y over U (as in :meth:`contraction`, with T for the slopes),
        and K2 = (P - m(q~)) + (I - J(q~) Y) U - 1/2 T(U)[U, U] (Taylor's theorem per row, with
        the same point in every entry of a row) both enclose phi(U) over P. K inside the
        interior of U proves one solution per p in U (Krawczyk); so does K2 inside U (Brouwer:
        phi maps U into itself) with ||C|| < 1 (phi contracts: at most one fixed point), needing
        about half the nonlinearity's margin. Either way the solutions lie in K, K2 and U, and
        q = q~ + Y u."""
        yh, t = self.slopes(u)
        c = _contract(self.c0u, t, u)
        k = _add(base, _matvec(c, u))
        n = self.qt.shape[0]
        a, b = ia.hessian_pairs(n)
        half = np.where(a == b, 0.5, 1.0)[None, :, None]              # off-diagonal pairs count twice
        outer = ia._outer_self(u)                                    # u_a u_b, squares >= 0
        tp = (half * t[0][:, a, b], half * t[1][:, a, b])
        quad = _sum(ia._mul_bounds(tp[0], tp[1], outer[0][None], outer[1][None]), 1)
        k2 = _sub(_add(base, _matvec(self.c0u, u)), quad)
        beta = np.max(_sum((_mag(c), _mag(c)), 1)[1], axis=0)
        return k, k2, beta, yh


def _proven(k, k2, beta, q):
    """Cells (N,) where the step over ``q`` proves one solution in Q (:meth:`_Centre.step`)."""
    inner = np.all((k[0] > q[0]) & (k[1] < q[1]), axis=0)
    second = np.all((k2[0] >= q[0]) & (k2[1] <= q[1]), axis=0) & (beta < 1.0)
    return inner | second


def _meet(*boxes):
    return np.fmax.reduce([b[0] for b in boxes]), np.fmin.reduce([b[1] for b in boxes])


def _value(centre: _Centre, goal, tighten: bool):
    """The Krawczyk enclosure of the solutions for goal boxes ``goal`` (n, N), in the
    coordinates u (q = q~ + Y u), the cells (N,) where none was proven and [Y m''] (n, mq, N)
    over a box containing q~ + Y u."""
    base = _sub(goal, centre.f0)
    r = ia._up(ia._up(INFLATE * _mag(base)) + SLACK)
    n, size = centre.qt.shape
    e_lo, e_hi = np.full((n, size), np.nan), np.full((n, size), np.nan)
    yh = (np.full((n, n * (n + 1) // 2, size), np.nan),) * 2
    yh = (yh[0], yh[1].copy())
    # a singular preconditioner: no test
    todo = np.flatnonzero(np.all(np.isfinite(r), axis=0) & np.all(np.isfinite(centre.y), axis=(0, 1)))
    for _ in range(TRIES):
        s = (slice(None), todo)
        u = (-r[s], r[s])
        k, k2, beta, slopes = centre.part(todo).step((base[0][s], base[1][s]), u)
        inside = _proven(k, k2, beta, u)
        e = _meet(k, k2, u)
        done = todo[inside]
        e_lo[:, done], e_hi[:, done] = e[0][:, inside], e[1][:, inside]
        yh[0][:, :, done], yh[1][:, :, done] = slopes[0][:, :, inside], slopes[1][:, :, inside]
        guess = _meet(k, k2)                 # not clipped to U: a degenerate side of U must grow
        spread = np.fmax(guess[1], -guess[0])
        r[:, todo] = np.where(inside, r[s], ia._up(INFLATE * spread + SLACK))
        todo = todo[~inside & np.all(np.isfinite(spread), axis=0)]     # a NaN or infinite K: no hope
        if not len(todo):
            break
    failed = np.any(np.isnan(e_lo), axis=0)
    if tighten:   # once more over the hull of the enclosure and 0: the solutions lie in its K, K2
        hull = (np.where(failed, 0.0, np.fmin(e_lo, 0.0)), np.where(failed, 0.0, np.fmax(e_hi, 0.0)))
        k, k2, _, yh = centre.step(base, hull)
        e_lo, e_hi = _meet(k, k2, hull)
    return (e_lo, e_hi), failed, yh


def _solve(c, z):
    """Enclosure (n, k, N) of the solutions X of J X = B for every J with I - Y J in ``c``
    (n, n, N) and B with Y B in ``z`` (n, k, N), and the cells (N,) where ||c||_inf >= 1 (no proof).

    A solution satisfies X = Y B + (I - Y J) X, so ||x|| <= ||Y b|| / (1 - ||c||) column by
    column, and every enclosure X of it gives the enclosure (z + c X) and X."""
    beta = np.max(_sum((_mag(c), _mag(c)), 1)[1], axis=0)           # (N,) row sums, rounded up
    with np.errstate(divide="ignore", invalid="ignore"):
        rad = ia._up(np.max(_mag(z), axis=0) / ia._down(1.0 - beta))  # (k, N)
    failed = ~(beta < 1.0)
    rad = np.where(failed, np.nan, rad)
    x = (np.broadcast_to(-rad, z[0].shape), np.broadcast_to(rad, z[0].shape))
    for _ in range(SOLVE_STEPS):
        nx = _add(z, _matmul(c, x))
        x = (np.fmax(x[0], nx[0]), np.fmin(x[1], nx[1]))
    return x, failed


def _second(y, grad, yh, hess_g):
    """Y d2g - [Y m''][dq, dq] (n, m2, N) from dq/dx ``grad`` (n, n_in, N), [Y m''] (n, mq, N)
    and d2g (n, m2, N), with [Y m''][u, v] = sum_a [Y m'']_aa u_a v_a + sum_{a<b} [Y m'']_ab
    (u_a v_b + u_b v_a)."""
    n, n_in = grad[0].shape[:2]
    a, b = ia.hessian_pairs(n)
    j, k = ia.hessian_pairs(n_in)
    lo, hi = grad

    def prod(u, v):
        return ia._mul_bounds(lo[u][:, j], hi[u][:, j], lo[v][:, k], hi[v][:, k])
    t1, t2 = prod(a, b), prod(b, a)
    both = _add(t1, t2)
    diag = (a == b)[:, None, None]
    t = (np.where(diag, t1[0], both[0]), np.where(diag, t1[1], both[1]))      # (mq, m2, N)
    s = ia._mul_bounds(yh[0][:, :, None], yh[1][:, :, None], t[0][None], t[1][None])
    return _sub(_matmul(y, hess_g), _sum(s, 1))


def _start(chain, qt) -> tuple[_Centre, np.ndarray]:
    """The :class:`_Centre` of the float solutions ``qt`` (n, N) and the cells where they are
    unknown (NaN): those get a stand-in solution, and fail."""
    unknown = np.any(np.isnan(qt), axis=0)
    return _Centre(chain, np.where(unknown, 0.0, qt)), unknown


def enclose(centre: _Centre, goal, order: int, tighten: bool = True):
    """Enclosures of the IK over goal Intervals (or floats) ``goal`` (one per solved quantity)
    from the float solutions at their centres (``centre``).

    Returns one :class:`~ikseries.fit.interval.Interval` per joint (deg) of order ``order``,
    with derivatives with respect to the inputs the goal's derivatives are taken in, and the
    cells (N,) where no enclosure was proven (their bounds are then meaningless). With
    ``tighten``, one more step over the hull of the first enclosure (for cells, not points)."""
    qt = centre.qt
    n, size = qt.shape
    n_in = next((g.d[0].shape[0] for g in goal if isinstance(g, ia.Interval) and g.d is not None), 0)
    order = min([order] + [g.order for g in goal if isinstance(g, ia.Interval)]) if n_in else 0
    (glo, ghi), g1, g2 = _rows(goal, size, n_in)
    unknown = np.any(np.isnan(glo) | np.isnan(ghi), axis=0)
    glo, ghi = np.where(unknown, qt, glo), np.where(unknown, qt, ghi)   # a stand-in: the cell fails
    u, failed, yh = _value(centre, (glo, ghi), tighten)
    q = centre.hull(u)
    failed |= unknown | np.any(np.isnan(q[0]) | np.isnan(q[1]), axis=0)
    if order == 0:
        return [ia.Interval(q[0][i], q[1][i], order=0) for i in range(n)], failed
    u = (np.where(failed, 0.0, u[0]), np.where(failed, 0.0, u[1]))
    yh = (np.where(failed, 0.0, yh[0]), np.where(failed, 0.0, yh[1]))
    c = centre.contraction(yh, u)
    d1, bad = _solve(c, _matmul(centre.y, g1))
    failed |= bad
    d2 = _solve(c, _second(centre.y, d1, yh, g2))[0] if order >= 2 else None
    return [ia.Interval(q[0][i], q[1][i], (d1[0][i], d1[1][i]),
                        None if d2 is None else (d2[0][i], d2[1][i]), order) for i in range(n)], failed


# -- the certifier's number types -----------------------------------------------------------------------
def _midpoints(goal, size: int) -> list[np.ndarray]:
    out = []
    for g in goal:
        g = ia.point(g) if not isinstance(g, ia.Interval) else g
        out.append(np.broadcast_to(0.5 * (g.lo + g.hi), (size,)))
    return out


def _centres(chain, goal, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Continued Newton solutions (n, N) at the goals' midpoints, and where they failed."""
    sol = solve.continued(chain, _midpoints(goal, size))
    return sol.angles.T.copy(), ~sol.ok


def _size(xs) -> int:
    return max([np.size(x.lo) for x in xs if isinstance(x, ia.Interval)] + [1])


def _box(names, lo, hi, i: int) -> str:
    return "(" + ", ".join(f"{k} in [{np.ravel(a)[i]:.6g}, {np.ravel(b)[i]:.6g}]"
                           for k, a, b in zip(names, lo, hi)) + ")"


def _report(chain, coords, failed, unreached, parts):
    """``parts`` (Intervals) with NaN bounds in the failed cells within ia.lenient(), else raise
    :class:`ChainEnclosureError` naming the first."""
    if not np.any(failed):
        return parts
    bounds = [(c.lo, c.hi) if isinstance(c, ia.Interval) else (c, c) for c in coords]
    i = int(np.flatnonzero(failed)[0])
    why = ("the Newton IK continued from the home pose does not reach the centre on the home pose's branch"
           if unreached[i] else f"the Krawczyk test K(Q) inside Q failed after {TRIES} inflations of Q "
           f"(the Jacobian is near-singular over the cell, or the cell is too large)")
    reason = f"the chain's IK is not enclosed there: {why}"
    return ia._domain(failed, lambda message: ChainEnclosureError(message, reason),
                      lambda: f"the chain's IK is not enclosed over the targets {_box(chain.inputs, *zip(*bounds), i)}: "
                              f"{why}", *parts)


def enclosed_angles(chain, xp, coords):
    """``chain.angles`` over the certifier's number types: ``xp`` is
    :data:`ikseries.fit.interval.MATH` (``coords`` Intervals) or
    :data:`ikseries.fit.centred.MATH` (``coords`` Centred numbers: the centre and the cell
    are enclosed from the same float solution at the centre)."""
    goal = chain.goal_rows(xp, *coords)
    if xp is ia.MATH:
        size = _size(list(coords) + [g for g in goal])
        qt, unreached = _centres(chain, goal, size)
        centre, unknown = _start(chain, np.where(unreached, np.nan, qt))
        q, failed = enclose(centre, goal, 2, tighten=False)
        return tuple(_report(chain, coords, failed | unknown, unreached, q))
    centre = [g.c if isinstance(g, cn.Centred) else g for g in goal]
    cell = [g.x if isinstance(g, cn.Centred) else g for g in goal]
    size = _size(centre + cell)
    qt, unreached = _centres(chain, centre, size)
    start, unknown = _start(chain, np.where(unreached, np.nan, qt))
    qc, fc = enclose(start, centre, 1, tighten=False)
    qx, fx = enclose(start, cell, 2)
    h = next(c.h for c in coords if isinstance(c, cn.Centred))
    qc = _report(chain, [c.c for c in coords], fc | unknown, unreached, qc)
    qx = _report(chain, [c.x for c in coords], fx | unknown, unreached, qx)
    return tuple(cn.Centred(c, x, h) for c, x in zip(qc, qx))
