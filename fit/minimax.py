"""Discrete minimax (Chebyshev, L-inf) polynomial fits on a large point set, by exchange.

The problem ``min_c max_i |a_i . c - b_i|`` over a pool of points is a linear programme whose
dual, ``max sum_i y_i b_i`` subject to ``sum_i y_i a_i = 0`` and ``sum_i |y_i| = 1``, has a
basis of ``n + 1`` signed points (a *reference*). :class:`_Exchange` runs the primal simplex
method on that dual over an *active* subset of the pool: its multipliers are the coefficients
``c`` and the levelled error ``t`` of the reference; a point whose error exceeds ``t`` enters,
and one reference point leaves by the ratio test (the Stiefel exchange in several variables).
:func:`minimax` wraps it in rounds over the whole pool: the subset's optimum is checked on
every point, the worst violators (the worst of each region of the pool, so that one round
reaches many of the error's local maxima, not one of them many times) join the subset, until no
point errs by more than ``t`` (within ``GAP``). The exchange works in coordinates orthonormal
over the first active rows: references of high-degree monomials stay well conditioned.

Every reference's ``t`` is a lower bound of the pool's minimax error (weak duality: a feasible
dual point), so a structure that cannot meet a budget is refused as soon as ``t`` passes it,
usually after a few dozen pivots on a few hundred points; a fit that meets it is returned at
its optimum, which leaves the certifier the most room.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["MinimaxFit", "minimax", "subset_minimax", "region_ids", "GAP", "REGIONS"]

#: relative gap between the error over the pool and the reference's level at which a fit within
#: its budget is taken as optimal (``_TIGHT`` for one that is not, until its level passes the budget)
GAP = 1e-3
_TIGHT = 1e-4
_PER_ROUND = 2               # rows joining the subset per round, times (terms + 1)
_SLACK = 2e-7                # a row errs by more than the level t if by more than t (1 + _SLACK) + floor
_FLOOR = 1e-12               # ... floor = _FLOOR * max |target| (rounding noise of the residuals)
_RANK = 1e-12                # columns dependent to within this (relative) are dependent
#: regions of the pool (a grid over its coordinates) whose worst violators join the subset per round
REGIONS = 128
_ROUNDS = 60                 # exchange rounds over the pool before the best fit seen is returned
_REFACTOR = 25               # pivots between refactorisations of the basis inverse


@dataclass(frozen=True)
class MinimaxFit:
    """A minimax fit over a pool of points.

    Attributes
    ----------
    coef : ndarray
        Coefficients (one per term).
    error : float
        Max |error| over the pool of ``coef``; when ``refused``, the lower bound instead.
    lower : float
        The reference's levelled error: no coefficients do better on the pool.
    active : ndarray of int
        The pool rows the exchange worked on (warm-starts a related fit).
    reference : ndarray of int
        The pool rows of the final reference (``n + 1`` of ``active``).
    refused : bool
        The lower bound exceeds the budget: no coefficients of these terms meet it.
    optimal : bool
        ``error`` is within ``GAP`` of ``lower``.
    """
    coef: np.ndarray
    error: float
    lower: float
    active: np.ndarray
    reference: np.ndarray
    refused: bool = False
    optimal: bool = False


def region_ids(points: np.ndarray, regions: int = REGIONS) -> np.ndarray:
    """Region of each point (N, n): a grid of about ``regions`` cells over the bounding box of its
    non-constant coordinates."""
    lo, hi = points.min(0), points.max(0)
    live = hi > lo
    dims = int(live.sum())
    if dims == 0:
        return np.zeros(len(points), dtype=np.intp)
    per = int(np.ceil(regions ** (1 / dims)))
    q = ((points[:, live] - lo[live]) / (hi - lo)[live] * per).astype(np.intp)
    return np.ravel_multi_index(np.clip(q, 0, per - 1).T, (per,) * dims)


def _start(a: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A feasible reference among rows ``a`` (k, n): ``n`` rows spanning R^n best (QR with column
    pivoting of a^T), one more, and the signs of the null vector of the n x (n + 1) system; None
    if the rows do not span R^n."""
    n = a.shape[1]
    if len(a) < n + 1:
        return None
    _, r, piv = scipy.linalg.qr(a.T, mode="economic", pivoting=True)
    if not abs(r[n - 1, n - 1]) > _RANK * abs(r[0, 0]):
        return None
    ref = piv[:n + 1]
    mu = np.linalg.svd(a[ref].T)[2][-1]
    return ref, np.where(mu >= 0, 1.0, -1.0)


def _independent(a: np.ndarray, most: int) -> np.ndarray:
    """Indices of a largest set of linearly independent columns of ``a``, at most ``most`` of
    them (QR with pivoting: the best conditioned first)."""
    _, r, piv = scipy.linalg.qr(a, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    if most < 1 or not len(d) or not d[0] > 0:
        return np.zeros(0, dtype=np.intp)
    return np.sort(piv[:min(most, int(np.sum(d > _RANK * d[0])))])


class _Exchange:
    """The primal simplex on the dual LP over rows ``a`` (k, n) and targets ``b``: the reference
    ``ref`` (row positions) with signs ``sig``, the inverse of its basis and the multipliers
    ``w`` = (coefficients, level) kept up to date by rank-one updates, refactorised every
    ``_REFACTOR`` pivots."""

    def __init__(self, a: np.ndarray, b: np.ndarray, ref, sig):
        self.a, self.b = a, b
        self.ref, self.sig = np.array(ref, dtype=np.intp), np.array(sig, dtype=np.float64)
        self._refactor()

    def _refactor(self) -> None:
        basis = np.vstack([(self.a[self.ref] * self.sig[:, None]).T, np.ones(len(self.ref))])
        self.inv = np.linalg.inv(basis)
        self.w = self.inv.T @ (self.sig * self.b[self.ref])
        self.since = 0

    def extend(self, a: np.ndarray, b: np.ndarray, ref) -> None:
        """The same reference (at its new positions ``ref``) among more rows."""
        self.a, self.b, self.ref = a, b, np.asarray(ref, dtype=np.intp)

    def run(self, budget: float, floor: float) -> tuple[np.ndarray, float, str]:
        """Pivot until no row errs by more than ``t (1 + _SLACK) + floor`` ("optimal") or the
        level ``t`` exceeds ``budget`` ("refused"); returns (coefficients, t, how). After ``2 (n + 1)``
        pivots in a row that do not raise ``t``, Bland's rule (the first violator enters) avoids
        cycling."""
        n1 = len(self.ref)
        stall, last = 0, -np.inf
        for _ in range(50 * n1):
            if self.w[-1] > budget:
                self._refactor()         # a refusal is a proof: not from a drifted inverse
                if self.w[-1] > budget:
                    return self.w[:-1].copy(), float(self.w[-1]), "refused"
            t = float(self.w[-1])
            stall, last = (stall + 1 if t <= last else 0), max(t, last)
            r = self.b - self.a @ self.w[:-1]
            v = np.abs(r)
            v -= t
            tol = _SLACK * abs(t) + floor
            i = int(v.argmax())
            if v[i] <= tol:
                return self.w[:-1].copy(), t, "optimal"
            if stall > 2 * n1:
                i = int(np.flatnonzero(v > tol)[0])
            s = 1.0 if r[i] > 0 else -1.0
            if np.any((self.ref == i) & (self.sig == s)):    # a reference row errs by more than t:
                if self.since == 0:                         # the inverse has drifted, or (just
                    return self.w[:-1].copy(), t, "stuck"   # refactorised) is too inaccurate
                self._refactor()
                continue
            if not self._pivot(i, s, float(v[i])):
                return self.w[:-1].copy(), t, "stuck"
        return self.w[:-1].copy(), float(self.w[-1]), "pivots"

    def _pivot(self, i: int, s: float, gain: float) -> bool:
        """Row ``i`` with sign ``s`` (reduced cost ``gain``) enters; the Harris ratio test picks
        the leaving point among the near-ties with the largest pivot element."""
        inv = self.inv
        d = inv[:, :-1] @ (s * self.a[i])
        d += inv[:, -1]
        pos = d > 1e-9 * np.abs(d).max()
        if not pos.any():
            return False
        z = np.maximum(inv[:, -1], 0.0)
        dp = np.where(pos, d, 1.0)
        theta = np.where(pos, (z + 1e-12) / dp, np.inf).min()
        j = int(np.where(pos & (z / dp <= theta), d, -np.inf).argmax())
        was = self.ref[j], self.sig[j]
        self.ref[j], self.sig[j] = i, s
        if self.since + 1 >= _REFACTOR:
            try:
                self._refactor()
            except np.linalg.LinAlgError:              # numerically singular: keep the old basis
                self.ref[j], self.sig[j] = was
                self._refactor()
                return False
            return True
        row = inv[j] / d[j]
        self.w += gain * row         # the multipliers of the new basis
        inv -= d[:, None] * row
        inv[j] = row
        self.since += 1
        return True


def _new_rows(err: np.ndarray, level: float, regions: np.ndarray, active: np.ndarray, count: int) -> np.ndarray:
    """Up to ``count`` rows not in ``active`` erring by more than ``level``: the worst of each
    region (the first such row on a tie), the worst regions first."""
    out = err > level
    out[active] = False
    viol = np.flatnonzero(out)
    ev, rv = err[viol], regions[viol]
    worst = np.full(int(regions.max()) + 1, -np.inf)
    np.maximum.at(worst, rv, ev)
    hit = viol[ev == worst[rv]]
    _, first = np.unique(regions[hit], return_index=True)
    reps = hit[first]
    return np.sort(reps[np.argsort(-err[reps], kind="stable")[:count]])


def minimax(basis, target: np.ndarray, terms: list, budget: float, regions: np.ndarray,
            start: np.ndarray | None = None, settle: bool = True) -> MinimaxFit:
    """The minimax fit of ``terms`` (columns of ``basis``, a :class:`~.polyfit.Basis`) to
    ``target`` over all its points, or its refusal once no fit can meet ``budget``.

    ``start``: pool rows to begin with (e.g. the active rows of a related fit); a stride over the
    pool is added. ``regions``: :func:`region_ids` of the pool's points. Without ``settle`` the
    first coefficients that meet the budget are returned (``optimal`` False): enough to decide.
    Terms that are linearly dependent over the pool (e.g. powers of an offset that takes two
    values in a cell) are fitted by an independent subset of them, the others' coefficients 0.
    """
    m, n = len(target), len(terms)
    norm = np.array([basis.norm(t) for t in terms])
    stride = np.arange(0, m, max(1, m // (4 * (n + 1))))
    active = stride if start is None else np.union1d(start, stride)
    a = basis.rows(terms, active) / norm
    first = _start(a)
    if first is None:            # the rows so far do not span the terms: the whole pool decides
        full = basis.matrix(terms) / norm
        cols = _independent(full, len(full) - 1)
        if len(cols) < n:
            fit = minimax(basis, target, [terms[j] for j in cols], budget, regions, start, settle)
            coef = np.zeros(n)
            coef[cols] = fit.coef
            return dataclasses.replace(fit, coef=coef)
        _, _, piv = scipy.linalg.qr(full.T, mode="economic", pivoting=True)
        for take in (n + 1, 4 * (n + 1), 16 * (n + 1)):   # the most independent rows: n + 1 of
            active = np.union1d(active, piv[:take])       # them can fall short of the rank test
            a = basis.rows(terms, active) / norm          # the whole pool passes
            first = _start(a)
            if first is not None:
                break
        else:                    # a borderline rank: fit the terms independent over these rows
            cols = _independent(a, n - 1)   # (at least the least independent one dropped)
            fit = minimax(basis, target, [terms[j] for j in cols], budget, regions, active, settle)
            coef = np.zeros(n)
            coef[cols] = fit.coef
            return dataclasses.replace(fit, coef=coef)
    frame = _frame(a) / norm[:, None]
    a = basis.rows(terms, active) @ frame
    ex = _Exchange(a, target[active], *first)
    return _rounds(basis, target, terms, budget, regions, settle, frame, active, ex)


def _frame(a: np.ndarray) -> np.ndarray:
    """The upper triangular T with ``a @ T`` orthonormal columns (QR of ``a``, of full column
    rank): the exchange works in these coordinates, where the reference systems of high-degree
    monomials stay well conditioned (the same references and signs: T is invertible)."""
    r = np.linalg.qr(a, mode="r")
    return scipy.linalg.solve_triangular(r, np.eye(a.shape[1]))


def _rounds(basis, target, terms, budget, regions, settle, frame, active, ex) -> MinimaxFit:
    """The exchange rounds of :func:`minimax` from the exchange ``ex`` over the ``active`` rows,
    in the coordinates ``frame`` (coefficients = frame @ the exchange's)."""
    n = len(terms)
    floor = _FLOOR * float(np.abs(target).max())
    best = None
    for _ in range(_ROUNDS):
        u, t, how = ex.run(budget, floor)
        c = frame @ u
        if how == "refused":
            return MinimaxFit(c, t, t, active, active[ex.ref], refused=True)
        err = np.abs(basis.residual(terms, c, target))
        e = float(err.max())
        if best is None or e < best.error:
            best = MinimaxFit(c, e, t, active, active[ex.ref])
        if e <= t * (1 + (GAP if e <= budget else _TIGHT)) + floor:
            best = dataclasses.replace(best, optimal=True)
            break
        if not settle and e <= budget:
            break
        new = _new_rows(err, t * (1 + _TIGHT / 2), regions, active, _PER_ROUND * (n + 1))
        if not len(new):
            break
        kept = active[ex.ref]
        active = np.union1d(active, new)
        ex.extend(basis.rows(terms, active) @ frame, target[active], np.searchsorted(active, kept))
    return best


def subset_minimax(a: np.ndarray, b: np.ndarray, near: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Minimax coefficients over the rows ``a`` (k, n) alone (a small subset, e.g. a fit's
    active rows) and the rows of their reference.

    ``near``: rows of a related fit's reference (e.g. with one more term); the first reference
    is chosen among them, so that the exchange starts close to the optimum. Columns dependent
    over the rows get coefficient 0 (an independent subset is fitted, at least one column fewer
    than the rows do not span).
    """
    norm = np.linalg.norm(a, axis=0)
    norm[norm == 0] = 1.0
    an = a / norm
    first = None
    if near is not None:
        near = np.asarray(near)
        first = _start(an[near])
        first = None if first is None else (near[first[0]], first[1])
    if first is None:
        first = _start(an)
    if first is None:
        # a reference needs a row more than columns, and spanning rows: at least the least
        # independent column goes (QR of the rows and of the columns may judge a borderline
        # rank differently), so the recursion ends
        cols = _independent(an, min(len(a), a.shape[1]) - 1)
        coef = np.zeros(a.shape[1])
        if len(cols):
            coef[cols], ref = subset_minimax(a[:, cols], b)
            return coef, ref
        return coef, np.zeros(0, dtype=np.intp)
    frame = _frame(an)
    ex = _Exchange(an @ frame, b, *first)
    u, _, _ = ex.run(np.inf, _FLOOR * float(np.abs(b).max()))
    return (frame @ u) / norm, ex.ref.copy()
