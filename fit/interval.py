"""Vectorised interval arithmetic with forward-mode derivatives, outwardly rounded.

An :class:`Interval` holds, for each of N cells, an interval ``[lo, hi]`` enclosing a real
function's value and, up to its ``order``, enclosures of its partial derivatives with respect
to ``n`` inputs: the gradient ``d = (dlo, dhi)`` of shape ``(n, N)`` and the Hessian
``h = (hlo, hhi)`` of shape ``(n (n + 1) / 2, N)`` (upper triangle, in the order of
:func:`hessian_pairs`). ``d`` or ``h`` is ``None`` when it is exactly zero (a constant).
Every operation returns enclosures that contain the exact real result for every point of the
input cells:

- ``+ - * /`` and ``sqrt`` are correctly rounded in IEEE 754 (round to nearest), so each bound
  is moved outwards past the neighbouring float by Rump's ``x +- (2**-52 |x| + 2**-1073)``
  (cheaper than ``np.nextafter`` and at least as wide);
- ``cos sin acos asin atan2`` come from numpy's libm-style routines, which are not correctly
  rounded; their bounds are moved outwards by :data:`LIBM_ULPS` units in the last place
  (numpy documents at most 4 ULP for its SIMD float64 routines, glibc at most 2).

Floats and numpy arrays mix in as exact constants. :data:`MATH` has the same names as
``ikseries.kinematics.NUMPY_MATH``, so a formula written against that namespace evaluates
rigorously over cells when given :class:`Interval` inputs from :func:`variables`.

Errors (a division by an interval containing 0, a square root of a negative interval, ``acos``
outside [-1, 1], ``atan2`` over a box touching the branch cut) name the first offending cell;
within :func:`lenient` the offending cells get NaN bounds instead.
"""
from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from types import SimpleNamespace

import numpy as np

__all__ = ["Interval", "variables", "point", "clamp", "ldexp", "lenient", "hessian_pairs", "MATH",
           "LIBM_ULPS", "MAX_ORDER", "IntervalDomainError"]

#: Outward widening, in units in the last place, of numpy's transcendental functions.
LIBM_ULPS = 8
#: Highest derivative order carried (gradient 1, Hessian 2).
MAX_ORDER = 2

_TWO_PI_LO = 2.0 * np.nextafter(np.pi, 0.0)   # used only to locate extrema conservatively


class IntervalDomainError(ValueError):
    """An interval operation outside the domain where its enclosure is valid."""


_LENIENT = ContextVar("interval_lenient", default=False)


@contextmanager
def lenient():
    """Within this context a domain error does not raise: the offending cells get NaN bounds
    (which propagate), so that a branch-and-bound caller can split those cells instead."""
    token = _LENIENT.set(True)
    try:
        yield
    finally:
        _LENIENT.reset(token)


# -- outward-rounded bounds on plain arrays ------------------------------------------------------
_PHI = 2.0 ** -52      # >= one ulp of |x| relative to |x|
_ETA = 2.0 ** -1073    # >= the spacing of subnormals


def _down(x):
    """A float <= the float below ``x`` (the exact result of the operation that rounded to x)."""
    t = np.abs(x)
    if type(t) is np.ndarray and t.dtype == np.float64:   # in place: one temporary, not three
        t *= _PHI
        t += _ETA
        return np.subtract(x, t, out=t)
    return x - (t * _PHI + _ETA)


def _up(x):
    """A float >= the float above ``x``."""
    t = np.abs(x)
    if type(t) is np.ndarray and t.dtype == np.float64:
        t *= _PHI
        t += _ETA
        t += x
        return t
    return x + (t * _PHI + _ETA)


def _widen(lo, hi, ulps):
    for _ in range(ulps):
        lo, hi = _down(lo), _up(hi)
    return lo, hi


def _mul_bounds(alo, ahi, blo, bhi):
    """Outward-rounded enclosure of the product of intervals (broadcasting)."""
    p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
    lo, hi = np.minimum(p1, p2), np.maximum(p1, p2)
    if all(type(p) is np.ndarray and p.shape == lo.shape for p in (lo, p1, p2, p3, p4)):   # in place
        np.minimum(lo, np.minimum(p3, p4, out=p1), out=lo)
        np.maximum(hi, np.maximum(p3, p4, out=p2), out=hi)
    else:
        lo, hi = np.minimum(lo, np.minimum(p3, p4)), np.maximum(hi, np.maximum(p3, p4))
    return _down(lo), _up(hi)


def _sqr_bounds(lo, hi):
    """Outward-rounded enclosure of x**2 over [lo, hi] (never negative)."""
    a, b = lo * lo, hi * hi
    low = np.where((lo <= 0) & (hi >= 0), 0.0, _down(np.minimum(a, b)))
    return np.maximum(low, 0.0), _up(np.maximum(a, b))


def _add_pairs(parts):
    """Sum of (lo, hi) bound pairs, None entries being zero; None if all are zero."""
    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    lo, hi = parts[0]
    for plo, phi in parts[1:]:
        lo, hi = _down(lo + plo), _up(hi + phi)
    return lo, hi


def _scale(g, p):
    """g * p for a value pair g (shape (N,)) and a derivative pair p (shape (m, N)), or None."""
    return None if p is None else _mul_bounds(g[0], g[1], p[0], p[1])


def hessian_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of each stored Hessian entry (the upper triangle, row-major)."""
    return np.triu_indices(n)


def _outer_self(d):
    """Entries d_j d_k of the upper triangle (squares on the diagonal)."""
    lo, hi = d
    j, k = hessian_pairs(lo.shape[0])
    olo, ohi = _mul_bounds(lo[j], hi[j], lo[k], hi[k])
    diag = j == k
    slo, shi = _sqr_bounds(lo[j[diag]], hi[j[diag]])
    olo[diag], ohi[diag] = slo, shi
    return olo, ohi


def _outer_cross(a, b):
    """Entries a_j b_k + a_k b_j of the upper triangle."""
    j, k = hessian_pairs(a[0].shape[0])
    return _add_pairs([_mul_bounds(a[0][j], a[1][j], b[0][k], b[1][k]),
                       _mul_bounds(a[0][k], a[1][k], b[0][j], b[1][j])])


def _first(mask) -> int:
    return int(np.flatnonzero(np.ravel(mask))[0])


def _fmt(lo, hi, mask) -> str:
    i = _first(mask)
    return f"[{np.ravel(lo)[i]:.17g}, {np.ravel(hi)[i]:.17g}] (cell {i})"


def _domain(bad, exc, message, *xs):
    """Raise ``exc(message())`` if any cell is ``bad``; in :func:`lenient` mode, return the
    operands with NaN in the bad cells instead."""
    if not np.any(bad):
        return xs
    if not _LENIENT.get():
        raise exc(message())
    return tuple(_nan_cells(x, bad) for x in xs)


def _nan_pair(p, bad):
    return None if p is None else (np.where(bad, np.nan, p[0]), np.where(bad, np.nan, p[1]))


def _nan_cells(x: "Interval", bad) -> "Interval":
    return Interval(np.where(bad, np.nan, x.lo), np.where(bad, np.nan, x.hi),
                    _nan_pair(x.d, bad), _nan_pair(x.h, bad), x.order)


def _defers(op):
    """A binary operator that returns NotImplemented for an operand marked
    ``_interval_defers = True`` (a richer number built on Intervals, such as
    :class:`ikseries.fit.centred.Centred`), so Python calls that operand's reflected method."""
    def run(self, other):
        if getattr(other, "_interval_defers", False):
            return NotImplemented
        return op(self, other)
    run.__name__, run.__doc__ = op.__name__, op.__doc__
    return run


class Interval:
    """Interval value and interval derivatives of a real function, per cell.

    Parameters
    ----------
    lo, hi : array_like
        Bounds of the value, broadcastable to one shape ``(N,)`` (or scalars).
    d : tuple of ndarray or None
        ``(dlo, dhi)``, bounds of the partial derivatives, shape ``(n, N)``; None if all are 0.
    h : tuple of ndarray or None
        ``(hlo, hhi)``, bounds of the second partial derivatives, shape ``(n (n + 1) / 2, N)``
        in the order of :func:`hessian_pairs`; None if all are 0.
    order : int
        Highest derivative order enclosed (0: value only, 1: gradient, 2: Hessian).
    """

    __slots__ = ("lo", "hi", "d", "h", "order")
    __array_ufunc__ = None  # make numpy defer to the reflected operators (2.0 * x, arr + x)

    def __init__(self, lo, hi, d=None, h=None, order=MAX_ORDER):
        self.lo = np.asarray(lo, dtype=np.float64)
        self.hi = np.asarray(hi, dtype=np.float64)
        if order not in range(MAX_ORDER + 1):
            raise ValueError(f"order must be 0, 1 or 2, not {order!r}")
        self.order = order
        self.d = None if d is None or order < 1 else d
        self.h = None if h is None or order < 2 else h

    # -- views -------------------------------------------------------------------------
    @property
    def mag(self) -> np.ndarray:
        """Upper bound of |value| per cell."""
        return np.maximum(np.abs(self.lo), np.abs(self.hi))

    @property
    def dlo(self):
        return None if self.d is None else self.d[0]

    @property
    def dhi(self):
        return None if self.d is None else self.d[1]

    def dmag(self, n: int) -> np.ndarray:
        """Upper bound of |partial derivative| per input and cell, shape (n, N)."""
        if self.order < 1:
            raise ValueError(f"the gradient needs order >= 1, not {self.order}")
        if self.d is None:
            return np.zeros((n, self.lo.size))
        return np.broadcast_to(np.maximum(np.abs(self.d[0]), np.abs(self.d[1])), (n, self.lo.size))

    def hmag(self, n: int) -> np.ndarray:
        """Upper bound of |second partial derivative| per stored pair and cell."""
        if self.order < 2:
            raise ValueError(f"the Hessian needs order 2, not {self.order}")
        m = n * (n + 1) // 2
        if self.h is None:
            return np.zeros((m, self.lo.size))
        return np.broadcast_to(np.maximum(np.abs(self.h[0]), np.abs(self.h[1])), (m, self.lo.size))

    def value(self) -> "Interval":
        """The value alone, as a constant (no derivatives)."""
        return Interval(self.lo, self.hi)

    def __repr__(self) -> str:
        return f"Interval(lo={self.lo!r}, hi={self.hi!r}, d={self.d!r}, h={self.h!r}, order={self.order})"

    # -- helpers ---------------------------------------------------------------------------
    @staticmethod
    def _lift(x) -> "Interval":
        if isinstance(x, Interval):
            return x
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number, np.ndarray)):
            raise TypeError(f"an Interval operand must be an Interval, a real number or an array, "
                            f"not {type(x).__name__}")
        v = np.asarray(x, dtype=np.float64)
        return Interval(v, v)

    def _chain(self, lo, hi, g1, g2) -> "Interval":
        """g(self) with value [lo, hi], g' in the pair ``g1`` and g'' in the pair ``g2()``:
        gradient g' d, Hessian g' h + g'' d d^T."""
        if self.d is None:
            return Interval(lo, hi, order=self.order)
        d = _scale(g1, self.d)
        h = None
        if self.order >= 2:
            h = _add_pairs([_scale(g1, self.h), _scale(g2(), _outer_self(self.d))])
        return Interval(lo, hi, d, h, self.order)

    # -- arithmetic --------------------------------------------------------------------------
    def __neg__(self):
        neg = (lambda p: None if p is None else (-p[1], -p[0]))
        return Interval(-self.hi, -self.lo, neg(self.d), neg(self.h), self.order)

    def __pos__(self):
        return self

    @_defers
    def __add__(self, other):
        o = self._lift(other)
        return Interval(_down(self.lo + o.lo), _up(self.hi + o.hi), _add_pairs([self.d, o.d]),
                        _add_pairs([self.h, o.h]), min(self.order, o.order))

    __radd__ = __add__

    @_defers
    def __sub__(self, other):
        return self + (-self._lift(other))

    @_defers
    def __rsub__(self, other):
        return self._lift(other) + (-self)

    @_defers
    def __mul__(self, other):
        if other is self:
            return self.sqr()
        o = self._lift(other)
        order = min(self.order, o.order)
        a, b = (self.lo, self.hi), (o.lo, o.hi)
        lo, hi = _mul_bounds(*a, *b)
        d = _add_pairs([_scale(a, o.d), _scale(b, self.d)]) if order >= 1 else None
        h = None
        if order >= 2:
            cross = _outer_cross(self.d, o.d) if self.d is not None and o.d is not None else None
            h = _add_pairs([_scale(a, o.h), _scale(b, self.h), cross])
        return Interval(lo, hi, d, h, order)

    __rmul__ = __mul__

    def sqr(self) -> "Interval":
        """x**2 with the tight (non-negative) enclosure."""
        lo, hi = _sqr_bounds(self.lo, self.hi)
        two = np.full_like(self.lo, 2.0)
        return self._chain(lo, hi, (2.0 * self.lo, 2.0 * self.hi), lambda: (two, two))  # exact

    def reciprocal(self) -> "Interval":
        """1 / x; the interval must not contain 0."""
        bad = (self.lo <= 0) & (self.hi >= 0)
        self, = _domain(bad, ZeroDivisionError, lambda: f"interval division: the divisor must not "
                        f"contain 0, not {_fmt(self.lo, self.hi, bad)}", self)
        lo, hi = _down(1.0 / self.hi), _up(1.0 / self.lo)
        if self.d is None:
            return Interval(lo, hi, order=self.order)
        r = Interval(lo, hi)
        g1 = -(r * r)                      # -1/x**2
        return self._chain(lo, hi, (g1.lo, g1.hi), lambda: _pair(2.0 * (r * r * r)))  # 2/x**3

    @_defers
    def __truediv__(self, other):
        o = self._lift(other)
        if o.d is None and np.all((o.lo == o.hi) & (o.lo != 0)):
            # exact divisor: one rounding per bound (tighter than multiplying by 1/o)
            c = o.lo
            div = (lambda p: None if p is None else _div_point(p[0], p[1], c))
            qlo, qhi = _div_point(self.lo, self.hi, c)
            return Interval(qlo, qhi, div(self.d), div(self.h), min(self.order, o.order))
        return self * o.reciprocal()

    @_defers
    def __rtruediv__(self, other):
        return self._lift(other) * self.reciprocal()

    def __pow__(self, k):
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise TypeError(f"an Interval power must be an integer, not {k!r}")
        k = int(k)
        if k < 0:
            return (self ** -k).reciprocal()
        if k == 0:
            return Interval(np.ones_like(self.lo), np.ones_like(self.hi), order=self.order)
        if k == 1:
            return self
        lo, hi = _pow_bounds(self.lo, self.hi, k)
        g1 = _mul_bounds(float(k), float(k), *_pow_bounds(self.lo, self.hi, k - 1))
        c2 = float(k * (k - 1))
        g2 = (lambda: _mul_bounds(c2, c2, *_pow_bounds(self.lo, self.hi, k - 2))
              if k > 2 else (np.full_like(self.lo, c2), np.full_like(self.lo, c2)))
        return self._chain(lo, hi, g1, g2)


def _pair(x: Interval):
    return x.lo, x.hi


def _div_point(lo, hi, c):
    """[lo, hi] / c for exact nonzero c, outward rounded."""
    a, b = lo / c, hi / c
    return _down(np.minimum(a, b)), _up(np.maximum(a, b))


def _pow_nonneg(x, k, rnd):
    """x**k for x >= 0 by repeated products, each rounded with ``rnd`` (down or up)."""
    r = x
    for _ in range(k - 1):
        r = rnd(r * x)
    return np.maximum(r, 0.0)


def _pow_bounds(lo, hi, k):
    """Enclosure of x**k over [lo, hi] for an integer k >= 1."""
    if k == 1:
        return lo, hi
    alo, ahi = np.abs(lo), np.abs(hi)
    amax = np.maximum(alo, ahi)
    if k % 2 == 0:
        amin = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(alo, ahi))
        return _pow_nonneg(amin, k, _down), _pow_nonneg(amax, k, _up)
    # odd: monotone increasing; x**k = sign(x) |x|**k
    plo = np.where(lo >= 0, _pow_nonneg(alo, k, _down), -_pow_nonneg(alo, k, _up))
    phi = np.where(hi >= 0, _pow_nonneg(ahi, k, _up), -_pow_nonneg(ahi, k, _down))
    return plo, phi


# -- elementary functions ---------------------------------------------------------------------
def sqrt(x: Interval) -> Interval:
    """Square root; needs lo >= 0 (and lo > 0 when derivatives are carried)."""
    x = Interval._lift(x)
    bad = x.lo < 0
    x, = _domain(bad, IntervalDomainError,
                 lambda: f"sqrt: the argument must be >= 0, not {_fmt(x.lo, x.hi, bad)}", x)
    lo, hi = np.maximum(_down(np.sqrt(x.lo)), 0.0), _up(np.sqrt(x.hi))
    if x.d is None:
        return Interval(lo, hi, order=x.order)
    bad = x.lo <= 0
    x, = _domain(bad, IntervalDomainError, lambda: f"sqrt: the derivative is unbounded at 0; the "
                 f"argument must be > 0, not {_fmt(x.lo, x.hi, bad)}", x)
    lo, hi = np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)
    s = Interval(lo, hi)
    g1 = 0.5 / s                                       # 1 / (2 sqrt x)
    return x._chain(lo, hi, _pair(g1), lambda: _pair(-0.5 * g1 / x.value()))  # -1 / (4 x sqrt x)


def _inverse_trig(x: Interval, name: str, f, sign: float) -> Interval:
    x = Interval._lift(x)
    bad = (x.lo < -1) | (x.hi > 1)
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the argument must lie within [-1, 1], "
                 f"not {_fmt(x.lo, x.hi, bad)}", x)
    a, b = f(x.lo), f(x.hi)
    lo, hi = _widen(np.minimum(a, b), np.maximum(a, b), LIBM_ULPS)
    if x.d is None:
        return Interval(lo, hi, order=x.order)
    bad = (x.lo <= -1) | (x.hi >= 1)
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the derivative is unbounded at -1 and "
                 f"1; the argument must lie within (-1, 1), not {_fmt(x.lo, x.hi, bad)}", x)
    v = x.value()
    one_minus = 1.0 - v.sqr()
    bad = one_minus.lo <= 0
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the argument is too close to -1 or 1 "
                 f"for a finite derivative bound: {_fmt(x.lo, x.hi, bad)}", x)
    lo, hi = np.where(np.isnan(x.lo), np.nan, lo), np.where(np.isnan(x.lo), np.nan, hi)
    g1 = sign / sqrt(_nan_cells(one_minus, bad))       # +-1 / sqrt(1 - x**2)
    return x._chain(lo, hi, _pair(g1), lambda: _pair(g1 * v / one_minus))  # +-x / (1 - x**2)**1.5


def acos(x: Interval) -> Interval:
    """Arc cosine (radians) over [-1, 1]; derivatives need the open interval (-1, 1)."""
    return _inverse_trig(x, "acos", np.arccos, -1.0)


def asin(x: Interval) -> Interval:
    """Arc sine (radians) over [-1, 1]; derivatives need the open interval (-1, 1)."""
    return _inverse_trig(x, "asin", np.arcsin, 1.0)


def _contains_phase(lo, hi, phase):
    """Whether [lo, hi] may contain a point phase + 2 pi k (conservative: may say yes wrongly,
    never no wrongly)."""
    slack = 1e-12 * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    k = np.ceil((lo - phase - slack) / _TWO_PI_LO)
    return phase + k * 2.0 * np.pi <= hi + slack


def _trig_bounds(lo, hi, f, max_phase, min_phase):
    a, b = f(lo), f(hi)
    vlo, vhi = _widen(np.minimum(a, b), np.maximum(a, b), LIBM_ULPS)
    full = (hi - lo) >= _TWO_PI_LO
    vhi = np.where(full | _contains_phase(lo, hi, max_phase), 1.0, vhi)
    vlo = np.where(full | _contains_phase(lo, hi, min_phase), -1.0, vlo)
    return np.maximum(vlo, -1.0), np.minimum(vhi, 1.0)


def _sin_bounds(lo, hi):
    return _trig_bounds(lo, hi, np.sin, 0.5 * np.pi, -0.5 * np.pi)


def _cos_bounds(lo, hi):
    return _trig_bounds(lo, hi, np.cos, 0.0, np.pi)


def sin(x: Interval) -> Interval:
    """Sine (radians); maxima at pi/2 + 2 pi k and minima at -pi/2 + 2 pi k are included."""
    x = Interval._lift(x)
    lo, hi = _sin_bounds(x.lo, x.hi)
    return x._chain(lo, hi, _cos_bounds(x.lo, x.hi), lambda: (-hi, -lo))


def cos(x: Interval) -> Interval:
    """Cosine (radians); maxima at 2 pi k and minima at pi + 2 pi k are included."""
    x = Interval._lift(x)
    lo, hi = _cos_bounds(x.lo, x.hi)
    if x.d is None:
        return Interval(lo, hi, order=x.order)
    slo, shi = _sin_bounds(x.lo, x.hi)
    return x._chain(lo, hi, (-shi, -slo), lambda: (-hi, -lo))


def atan2(y: Interval, x: Interval) -> Interval:
    """Angle of (x, y) in radians, in (-pi, pi].

    The box must not contain the origin and must not cross the branch cut on the negative x
    axis (a box with x < 0 and y on both sides of 0). Over such a box the angle is extreme at
    two of the four corners.
    """
    y, x = Interval._lift(y), Interval._lift(x)
    origin = (x.lo <= 0) & (x.hi >= 0) & (y.lo <= 0) & (y.hi >= 0)
    y, x = _domain(origin, IntervalDomainError, lambda: f"atan2: the box must not contain the "
                   f"origin, not x {_fmt(x.lo, x.hi, origin)}, y {_fmt(y.lo, y.hi, origin)}", y, x)
    cut = (x.lo < 0) & (y.lo < 0) & (y.hi >= 0)
    y, x = _domain(cut, IntervalDomainError, lambda: f"atan2: the box must not cross the branch cut "
                   f"on the negative x axis, not x {_fmt(x.lo, x.hi, cut)}, y {_fmt(y.lo, y.hi, cut)}",
                   y, x)
    corners = [np.arctan2(yy, xx) for yy in (y.lo, y.hi) for xx in (x.lo, x.hi)]
    lo, hi = _widen(np.minimum.reduce(corners), np.maximum.reduce(corners), LIBM_ULPS)
    lo = np.maximum(lo, -np.pi - 1e-15)
    hi = np.minimum(hi, np.pi + 1e-15)
    order = min(x.order, y.order)
    if x.d is None and y.d is None:
        return Interval(lo, hi, order=order)
    # gradient (x dy - y dx) / r2; Hessian: first partials times the operands' Hessians plus
    # second partials atan_xx = 2xy / r2**2 = -atan_yy, atan_xy = (y**2 - x**2) / r2**2
    xv, yv = x.value(), y.value()
    inv = (xv.sqr() + yv.sqr()).reciprocal()
    gx, gy = -yv * inv, xv * inv
    d = _add_pairs([_scale(_pair(gx), x.d), _scale(_pair(gy), y.d)])
    h = None
    if order >= 2:
        inv2 = inv.sqr()
        gxx, gxy = 2.0 * (xv * yv) * inv2, (yv.sqr() - xv.sqr()) * inv2
        parts = [_scale(_pair(gx), x.h), _scale(_pair(gy), y.h)]
        if x.d is not None:
            parts.append(_scale(_pair(gxx), _outer_self(x.d)))
        if y.d is not None:
            parts.append(_scale(_pair(-gxx), _outer_self(y.d)))
        if x.d is not None and y.d is not None:
            parts.append(_scale(_pair(gxy), _outer_cross(x.d, y.d)))
        h = _add_pairs(parts)
    return Interval(lo, hi, d, h, order)


def clamp(x: Interval, lo: float, hi: float) -> Interval:
    """min(max(x, lo), hi).

    Where the value interval lies inside [lo, hi] the derivatives pass through; where it lies
    outside they are 0; otherwise the gradient is the hull with 0 (a bound on the generalized
    gradient of the Lipschitz clamp, valid in the mean-value theorem) and the Hessian is NaN
    (the clamp is not twice differentiable there: no second-order bound exists).
    """
    x = Interval._lift(x)
    vlo, vhi = np.clip(x.lo, lo, hi), np.clip(x.hi, lo, hi)
    inside = (x.lo >= lo) & (x.hi <= hi)
    if x.d is None or np.all(inside):
        return Interval(vlo, vhi, x.d, x.h, x.order)
    outside = (x.hi <= lo) | (x.lo >= hi)
    dlo = np.where(inside, x.dlo, np.where(outside, 0.0, np.minimum(x.dlo, 0.0)))
    dhi = np.where(inside, x.dhi, np.where(outside, 0.0, np.maximum(x.dhi, 0.0)))
    h = None
    if x.order >= 2:
        m = x.lo.size
        n = x.dlo.shape[0]
        hlo, hhi = (np.zeros((n * (n + 1) // 2, m)),) * 2 if x.h is None else x.h
        kink = ~inside & ~outside
        h = (np.where(inside, hlo, np.where(kink, np.nan, 0.0)),
             np.where(inside, hhi, np.where(kink, np.nan, 0.0)))
    return Interval(vlo, vhi, (dlo, dhi), h, x.order)


def ldexp(x: Interval, k: int) -> Interval:
    """x * 2**k, exact (barring overflow and underflow)."""
    x = Interval._lift(x)
    sc = (lambda p: None if p is None else (np.ldexp(p[0], k), np.ldexp(p[1], k)))
    return Interval(np.ldexp(x.lo, k), np.ldexp(x.hi, k), sc(x.d), sc(x.h), x.order)


# -- constructors -------------------------------------------------------------------------------
def point(x) -> Interval:
    """An exact real constant (no derivative)."""
    return Interval._lift(x)


def variables(lo, hi, order: int = 1) -> list[Interval]:
    """The n input variables over cells ``[lo, hi]`` (arrays of shape (N, n)).

    Variable k has value interval ``[lo[:, k], hi[:, k]]``, the unit gradient along input k if
    ``order >= 1`` and a zero Hessian if ``order == 2``.
    """
    if order not in range(MAX_ORDER + 1):
        raise ValueError(f"order must be 0, 1 or 2, not {order!r}")
    lo, hi = np.atleast_2d(np.asarray(lo, dtype=np.float64)), np.atleast_2d(np.asarray(hi, dtype=np.float64))
    if lo.shape != hi.shape:
        raise ValueError(f"lo and hi must have one shape, not {lo.shape} and {hi.shape}")
    bad = ~(lo <= hi)
    if np.any(bad):
        raise ValueError(f"cell bounds must satisfy lo <= hi, not {_fmt(lo, hi, bad)}")
    cells, n = lo.shape
    out = []
    for k in range(n):
        unit = np.zeros((n, 1))
        unit[k] = 1.0
        d = (np.broadcast_to(unit, (n, cells)),) * 2 if order >= 1 else None
        out.append(Interval(lo[:, k], hi[:, k], d, None, order))
    return out


#: Interval namespace with the names of ``ikseries.kinematics.NUMPY_MATH``.
MATH = SimpleNamespace(sqrt=sqrt, atan2=atan2, acos=acos, asin=asin, cos=cos, sin=sin)
