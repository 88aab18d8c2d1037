"""Centred interval evaluation: every intermediate value enclosed in Taylor form about the
cell centre as well as by plain interval arithmetic.

A :class:`Centred` number carries, for N cells with centres ``c`` and half-widths ``h``,

- ``c``: an :class:`~ikseries.fit.interval.Interval` of order 1 at the centre point (value
  and gradient at ``c``, enclosed with outward rounding), and
- ``x``: an Interval of order 2 over the whole cell (value, gradient, Hessian).

After every operation the cell enclosure is intersected with the centred forms

- value: ``v(c) + sum_k [-1, 1] sup|dv/dx_k| h_k`` (mean-value form, valid wherever ``v`` is
  Lipschitz with its generalized gradient in the enclosure, which is what
  :func:`~ikseries.fit.interval.clamp` guarantees), and
  ``v(c) + sum_k [-1, 1] |dv/dx_k(c)| h_k + 1/2 sum_jk H_jk [delta_j delta_k]`` with the
  Hessian ``H`` enclosed over the cell (second-order Taylor form, used only where that
  enclosure is finite, i.e. where ``v`` is twice differentiable over the cell);
- gradient: ``dv/dx_k(c) + sum_j [-1, 1] sup|d2v/dx_k dx_j| h_j`` (mean-value form of each
  partial derivative, same condition).

Each form encloses the same range, so the intersection does too. Plain interval arithmetic
loses correlations (a Horner chain over a cell is widened by the magnitudes of all its terms);
the centred forms shrink with the cell like ``h**2`` and keep every later operation tight. In
particular a clamp whose plain argument enclosure crosses the clamp limit only by
overestimation is seen not to act, so the composition stays twice differentiable and the
second-order Taylor form of the error applies.

:data:`MATH` has the names of ``ikseries.kinematics.NUMPY_MATH``, so a formula written
against that namespace evaluates in centred form when given :func:`variables`.
"""
from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np

from . import interval as ia

__all__ = ["Centred", "centres", "variables", "clamp", "ldexp", "MATH"]


def _down(x):
    return ia._down(x)


def _up(x):
    return ia._up(x)


def _sum_up(rows):
    """Upward-rounded sum over the first axis, row by row (each later axis is summed apart, so
    a stack of several sums rounds exactly as each would alone)."""
    total = rows[0]
    for r in rows[1:]:
        total = _up(total + r)
    return total


@functools.lru_cache(maxsize=None)
def _pair_index(n: int) -> np.ndarray:
    """(n, n) position in :func:`~ikseries.fit.interval.hessian_pairs` of the pair {r, q}."""
    j, k = ia.hessian_pairs(n)
    index = np.empty((n, n), dtype=np.intp)
    index[j, k] = index[k, j] = np.arange(len(j))
    return index


class Centred:
    """Centre-point and whole-cell enclosures of one real function over N cells.

    Parameters
    ----------
    c : Interval
        Value and gradient (order >= 1) at the cell centres.
    x : Interval
        Value, gradient and Hessian (order 2) over the cells.
    h : ndarray
        Half-widths of the cells, shape (n, N), rounded up (the centre lies within ``h_k`` of
        every point of the cell along input k).
    tighten : bool
        Intersect ``x`` with the centred forms (see the module docstring).
    """

    __slots__ = ("c", "x", "h")
    __array_ufunc__ = None  # make numpy defer to the reflected operators
    _interval_defers = True  # and Interval too

    def __init__(self, c: ia.Interval, x: ia.Interval, h: np.ndarray, tighten: bool = True):
        self.c, self.h = c, h
        self.x = _tighten(c, x, h) if tighten else x

    # -- helpers ---------------------------------------------------------------------------
    def _parts(self, other):
        if isinstance(other, Centred):
            return other.c, other.x
        return other, other           # a constant: the same for both evaluations

    def _new(self, c, x, other=None) -> "Centred":
        # an affine map of one centred value (a constant operand) keeps its tightness: only
        # operations combining two varying operands, or nonlinear ones, are re-tightened
        return Centred(c, x, self.h, tighten=other is None or isinstance(other, Centred))

    @property
    def mag(self) -> np.ndarray:
        """Upper bound of |value| over each cell."""
        return self.x.mag

    # -- arithmetic --------------------------------------------------------------------------
    def __neg__(self):
        return Centred(-self.c, -self.x, self.h, tighten=False)   # exact: nothing to gain

    def __pos__(self):
        return self

    def __add__(self, other):
        oc, ox = self._parts(other)
        return self._new(self.c + oc, self.x + ox, other)

    def __radd__(self, other):
        return self.__add__(other)

    def __sub__(self, other):
        oc, ox = self._parts(other)
        return self._new(self.c - oc, self.x - ox, other)

    def __rsub__(self, other):
        oc, ox = self._parts(other)
        return self._new(oc - self.c, ox - self.x, other)

    def __mul__(self, other):
        if other is self:
            return self.sqr()
        oc, ox = self._parts(other)
        return self._new(self.c * oc, self.x * ox, other)

    def __rmul__(self, other):
        return self.__mul__(other)

    def __truediv__(self, other):
        oc, ox = self._parts(other)
        return self._new(self.c / oc, self.x / ox, other)

    def __rtruediv__(self, other):
        oc, ox = self._parts(other)
        return self._new(oc / self.c, ox / self.x)

    def __pow__(self, k):
        return self._new(self.c ** k, self.x ** k)

    def sqr(self) -> "Centred":
        """x**2 with the tight (non-negative) enclosure."""
        return self._new(self.c.sqr(), self.x.sqr())

    def reciprocal(self) -> "Centred":
        """1 / x; the interval must not contain 0."""
        return self._new(self.c.reciprocal(), self.x.reciprocal())


def _tighten(c: ia.Interval, x: ia.Interval, h: np.ndarray) -> ia.Interval:
    """``x`` intersected with the centred forms about ``c`` (module docstring)."""
    if x.d is None:
        return x                                    # a constant: exact already
    n, size = h.shape
    lo, hi = np.broadcast_to(x.lo, (size,)), np.broadcast_to(x.hi, (size,))
    nan = np.isnan(lo) | np.isnan(hi)
    d = x.d
    if x.order < 2:
        # first order: v(c) + sum_k [-1, 1] sup|dv/dx_k| h_k
        r1 = _sum_up(_up(x.dmag(n) * h))
        best_lo, best_hi = _down(c.lo - r1), _up(c.hi + r1)
    else:
        best_lo, best_hi, d = _second_order(c, x, h)
    new_lo = np.where(nan, np.nan, np.fmax(lo, best_lo))
    new_hi = np.where(nan, np.nan, np.fmin(hi, best_hi))
    return ia.Interval(new_lo, new_hi, d, x.h, x.order)


def _second_order(c: ia.Interval, x: ia.Interval, h: np.ndarray):
    """The value bounds of the first- and second-order forms (intersected) and the gradient
    intersected with its mean-value form, for ``x`` of order 2. Every sum of rows is one
    :func:`_sum_up` over a stack (per element the same roundings in the same order as summing
    each alone, at a fraction of the calls: these run after every operation of a certificate)."""
    n, size = h.shape
    j, k = ia.hessian_pairs(n)
    diag = j == k
    cd = c.dmag(n)
    # first order v(c) + sum_k [-1, 1] sup|dv/dx_k| h_k, and the linear term sum_k |dv/dx_k(c)| h_k
    r1, lin = _sum_up(_up(np.stack([x.dmag(n) * h, cd * h], axis=1)))
    hm = x.hmag(n)                                  # (m, N), NaN where not twice differentiable
    hlo, hhi = (np.zeros_like(hm),) * 2 if x.h is None else x.h
    hh = _up(h[j] * h[k])                           # |delta_j delta_k| <= hh (delta_k**2 on the diagonal)
    off = _up(hm[~diag] * hh[~diag])                # |H_jk delta_j delta_k|
    # 1/2 H_kk delta_k**2 in [-neg, pos]
    negpos = _up(0.5 * np.maximum(np.stack(np.broadcast_arrays(-hlo[diag], hhi[diag]), axis=1), 0.0)
                 * hh[diag][:, None])
    off2 = np.broadcast_to(off[:, None], (len(off), 2, size))
    qlo, qhi = _sum_up(np.concatenate([negpos, off2]))     # the quadratic term is in [-qlo, qhi]
    best_lo = np.fmax(_down(c.lo - r1), _down(_down(c.lo - lin) - qlo))
    best_hi = np.fmin(_up(c.hi + r1), _up(_up(c.hi + lin) + qhi))
    d = x.d
    # gradient: dv/dx_k(c) + sum_j [-1, 1] sup|d2v/dx_k dx_j| h_j
    if d is not None and c.d is not None:
        terms = np.moveaxis(_up(hm[_pair_index(n)] * h[None]), 1, 0)   # [j] = |H_kj| h_j, (n, n, N)
        terms[0] = _up(terms[0])    # the sum starts from 0 rounded up: 0 + t rounds once more
        rad = _sum_up(terms)
        d = (np.fmax(d[0], _down(c.d[0] - rad)), np.fmin(d[1], _up(c.d[1] + rad)))
    return best_lo, best_hi, d


# -- functions ------------------------------------------------------------------------------------
def _lift_pair(v):
    return (v.c, v.x) if isinstance(v, Centred) else (v, v)


def _apply(fn, *args):
    h = next(a.h for a in args if isinstance(a, Centred))
    parts = [_lift_pair(a) for a in args]
    return Centred(fn(*(p[0] for p in parts)), fn(*(p[1] for p in parts)), h)


def _unary(fn):
    def run(x):
        if not isinstance(x, Centred):
            return fn(x)
        return _apply(fn, x)
    run.__doc__ = fn.__doc__
    return run


def atan2(y, x):
    """Angle of (x, y) in radians; see :func:`ikseries.fit.interval.atan2`."""
    if not isinstance(y, Centred) and not isinstance(x, Centred):
        return ia.atan2(y, x)
    return _apply(ia.atan2, y, x)


def clamp(x, lo: float, hi: float):
    """min(max(x, lo), hi); see :func:`ikseries.fit.interval.clamp`."""
    if not isinstance(x, Centred):
        return ia.clamp(x, lo, hi)
    return _apply(lambda v: ia.clamp(v, lo, hi), x)


def ldexp(x, k: int):
    """x * 2**k, exact."""
    if not isinstance(x, Centred):
        return ia.ldexp(x, k)
    return Centred(ia.ldexp(x.c, k), ia.ldexp(x.x, k), x.h, tighten=False)


def centres(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, n) of cells ``[lo, hi]`` (the midpoint rounded into the cell) and their
    half-widths (n, N), rounded up."""
    c = np.minimum(np.maximum(0.5 * (lo + hi), lo), hi)
    return c, _up(np.maximum(_up(c - lo), _up(hi - c))).T


def variables(lo, hi) -> list[Centred]:
    """The n input variables over cells ``[lo, hi]`` (arrays of shape (N, n)) in centred form.

    The centre is the midpoint (rounded into the cell); the half-widths are rounded up.
    """
    lo, hi = np.atleast_2d(np.asarray(lo, dtype=np.float64)), np.atleast_2d(np.asarray(hi, dtype=np.float64))
    cells = ia.variables(lo, hi, order=2)           # validates the shapes and lo <= hi
    c, h = centres(lo, hi)
    points = ia.variables(c, c, order=1)
    return [Centred(pc, px, h, tighten=False) for pc, px in zip(points, cells)]


#: Centred namespace with the names of ``ikseries.kinematics.NUMPY_MATH``.
MATH = SimpleNamespace(sqrt=_unary(ia.sqrt), acos=_unary(ia.acos), asin=_unary(ia.asin),
                       cos=_unary(ia.cos), sin=_unary(ia.sin), atan2=atan2)
