"""Vectorised interval arithmetic with forward-mode derivatives, outwardly rounded.

An :class:`Interval` holds, for each of N cells, an interval ``[lo, hi]`` enclosing a real
function's value and, optionally, intervals ``[dlo, dhi]`` (shape ``(n, N)``) enclosing its
partial derivatives with respect to ``n`` inputs. Every operation returns enclosures that
contain the exact real result for every point of the input cells:

- ``+ - * /`` and ``sqrt`` are correctly rounded in IEEE 754, so each bound is moved outwards by
  one unit in the last place (``np.nextafter``);
- ``cos sin acos asin atan2`` come from numpy's libm-style routines, which are not correctly
  rounded; their bounds are moved outwards by :data:`LIBM_ULPS` units in the last place
  (numpy documents at most 4 ULP for its SIMD float64 routines, glibc at most 2).

Floats and numpy arrays mix in as exact constants. :data:`MATH` has the same names as
``ikseries.kinematics.NUMPY_MATH``, so a formula written against that namespace evaluates
rigorously over cells when given :class:`Interval` inputs from :func:`variables`.

Errors (a division by an interval containing 0, a square root of a negative interval, ``acos``
outside [-1, 1], ``atan2`` over a box touching the branch cut) name the first offending cell.
"""
from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from types import SimpleNamespace

import numpy as np

__all__ = ["Interval", "variables", "point", "clamp", "ldexp", "lenient", "MATH", "LIBM_ULPS",
           "IntervalDomainError"]

#: Outward widening, in units in the last place, of numpy's transcendental functions.
LIBM_ULPS = 8

_PI_LO = np.nextafter(np.pi, 0.0)          # float pi lies within one ulp of the real pi
_TWO_PI_LO = 2.0 * _PI_LO                   # used only to locate extrema conservatively


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


def _domain(bad, exc, message, *xs):
    """Raise ``exc(message())`` if any cell is ``bad``; in :func:`lenient` mode, return the
    operands with NaN in the bad cells instead."""
    if not np.any(bad):
        return xs
    if not _LENIENT.get():
        raise exc(message())
    return tuple(_nan_cells(x, bad) for x in xs)


def _nan_cells(x: "Interval", bad) -> "Interval":
    lo, hi = np.where(bad, np.nan, x.lo), np.where(bad, np.nan, x.hi)
    if x.dlo is None:
        return Interval(lo, hi)
    return Interval(lo, hi, np.where(bad, np.nan, x.dlo), np.where(bad, np.nan, x.dhi))


def _down(x):
    return np.nextafter(x, -np.inf)


def _up(x):
    return np.nextafter(x, np.inf)


def _widen(lo, hi, ulps):
    for _ in range(ulps):
        lo, hi = _down(lo), _up(hi)
    return lo, hi


def _mul_bounds(alo, ahi, blo, bhi):
    """Outward-rounded enclosure of the product of intervals (broadcasting)."""
    p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
    lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
    hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    return _down(lo), _up(hi)


def _sqr_bounds(lo, hi):
    """Outward-rounded enclosure of x**2 over [lo, hi] (never negative)."""
    a, b = lo * lo, hi * hi
    low = np.where((lo <= 0) & (hi >= 0), 0.0, _down(np.minimum(a, b)))
    return np.maximum(low, 0.0), _up(np.maximum(a, b))


def _first(mask) -> int:
    return int(np.flatnonzero(np.ravel(mask))[0])


def _fmt(lo, hi, mask) -> str:
    i = _first(mask)
    return f"[{np.ravel(lo)[i]:.17g}, {np.ravel(hi)[i]:.17g}] (cell {i})"


class Interval:
    """Interval value and interval partial derivatives of a real function, per cell.

    Parameters
    ----------
    lo, hi : array_like
        Bounds of the value, broadcastable to one shape ``(N,)`` (or scalars).
    dlo, dhi : ndarray or None
        Bounds of the partial derivatives, shape ``(n, N)`` (or ``(n, 1)``); ``None`` when the
        function does not depend on the inputs (all partials are exactly 0).
    """

    __slots__ = ("lo", "hi", "dlo", "dhi")
    __array_ufunc__ = None  # make numpy defer to the reflected operators (2.0 * x, arr + x)

    def __init__(self, lo, hi, dlo=None, dhi=None):
        self.lo = np.asarray(lo, dtype=np.float64)
        self.hi = np.asarray(hi, dtype=np.float64)
        if (dlo is None) != (dhi is None):
            raise ValueError("dlo and dhi must both be given or both be None")
        self.dlo = None if dlo is None else np.asarray(dlo, dtype=np.float64)
        self.dhi = None if dhi is None else np.asarray(dhi, dtype=np.float64)

    # -- views -------------------------------------------------------------------------
    @property
    def mag(self) -> np.ndarray:
        """Upper bound of |value| per cell."""
        return np.maximum(np.abs(self.lo), np.abs(self.hi))

    @property
    def dmag(self) -> np.ndarray | None:
        """Upper bound of |partial derivative| per input and cell (shape (n, N)), or None."""
        return None if self.dlo is None else np.maximum(np.abs(self.dlo), np.abs(self.dhi))

    def __repr__(self) -> str:
        return f"Interval(lo={self.lo!r}, hi={self.hi!r}, dlo={self.dlo!r}, dhi={self.dhi!r})"

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

    def _chain(self, glo, ghi, lo, hi) -> "Interval":
        """Result with value [lo, hi] and derivative g'(self) * d(self), g' in [glo, ghi]."""
        if self.dlo is None:
            return Interval(lo, hi)
        dlo, dhi = _mul_bounds(glo, ghi, self.dlo, self.dhi)
        return Interval(lo, hi, dlo, dhi)

    # -- arithmetic --------------------------------------------------------------------------
    def __neg__(self):
        if self.dlo is None:
            return Interval(-self.hi, -self.lo)
        return Interval(-self.hi, -self.lo, -self.dhi, -self.dlo)

    def __pos__(self):
        return self

    def __add__(self, other):
        o = self._lift(other)
        lo, hi = _down(self.lo + o.lo), _up(self.hi + o.hi)
        if self.dlo is None and o.dlo is None:
            return Interval(lo, hi)
        if o.dlo is None:
            return Interval(lo, hi, self.dlo, self.dhi)
        if self.dlo is None:
            return Interval(lo, hi, o.dlo, o.dhi)
        return Interval(lo, hi, _down(self.dlo + o.dlo), _up(self.dhi + o.dhi))

    __radd__ = __add__

    def __sub__(self, other):
        return self + (-self._lift(other))

    def __rsub__(self, other):
        return self._lift(other) + (-self)

    def __mul__(self, other):
        if other is self:
            return self.sqr()
        o = self._lift(other)
        lo, hi = _mul_bounds(self.lo, self.hi, o.lo, o.hi)
        parts = []
        if o.dlo is not None:
            parts.append(_mul_bounds(self.lo, self.hi, o.dlo, o.dhi))
        if self.dlo is not None:
            parts.append(_mul_bounds(o.lo, o.hi, self.dlo, self.dhi))
        if not parts:
            return Interval(lo, hi)
        if len(parts) == 1:
            return Interval(lo, hi, *parts[0])
        (alo, ahi), (blo, bhi) = parts
        return Interval(lo, hi, _down(alo + blo), _up(ahi + bhi))

    __rmul__ = __mul__

    def sqr(self) -> "Interval":
        """x**2 with the tight (non-negative) enclosure."""
        lo, hi = _sqr_bounds(self.lo, self.hi)
        return self._chain(2.0 * self.lo, 2.0 * self.hi, lo, hi)  # doubling is exact

    def reciprocal(self) -> "Interval":
        """1 / x; the interval must not contain 0."""
        bad = (self.lo <= 0) & (self.hi >= 0)
        self, = _domain(bad, ZeroDivisionError, lambda: f"interval division: the divisor must not "
                        f"contain 0, not {_fmt(self.lo, self.hi, bad)}", self)
        lo, hi = _down(1.0 / self.hi), _up(1.0 / self.lo)
        if self.dlo is None:
            return Interval(lo, hi)
        # d(1/x) = -dx / x**2
        slo, shi = _sqr_bounds(self.lo, self.hi)
        glo, ghi = _down(-1.0 / slo), _up(-1.0 / shi)
        return self._chain(glo, ghi, lo, hi)

    def __truediv__(self, other):
        o = self._lift(other)
        if o.dlo is None and np.all((o.lo == o.hi) & (o.lo != 0)):
            # exact divisor: one rounding per bound (tighter than multiplying by 1/o)
            qlo, qhi = _div_point(self.lo, self.hi, o.lo)
            if self.dlo is None:
                return Interval(qlo, qhi)
            dlo, dhi = _div_point(self.dlo, self.dhi, o.lo)
            return Interval(qlo, qhi, dlo, dhi)
        return self * o.reciprocal()

    def __rtruediv__(self, other):
        return self._lift(other) * self.reciprocal()

    def __pow__(self, k):
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise TypeError(f"an Interval power must be an integer, not {k!r}")
        k = int(k)
        if k < 0:
            return (self ** -k).reciprocal()
        if k == 0:
            return Interval(np.ones_like(self.lo), np.ones_like(self.hi))
        if k == 1:
            return self
        lo, hi = _pow_bounds(self.lo, self.hi, k)
        if self.dlo is None:
            return Interval(lo, hi)
        plo, phi = _pow_bounds(self.lo, self.hi, k - 1)
        glo, ghi = _mul_bounds(float(k), float(k), plo, phi)
        return self._chain(glo, ghi, lo, hi)


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
    if x.dlo is None:
        return Interval(lo, hi)
    bad = x.lo <= 0
    x, = _domain(bad, IntervalDomainError, lambda: f"sqrt: the derivative is unbounded at 0; the "
                 f"argument must be > 0, not {_fmt(x.lo, x.hi, bad)}", x)
    lo, hi = np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)
    glo, ghi = _down(0.5 / hi), _up(0.5 / lo)  # 1 / (2 sqrt(x)), decreasing
    return x._chain(glo, ghi, lo, hi)


def _one_minus_sqr_sqrt(x: Interval):
    """Enclosure of sqrt(1 - x**2) over x's value interval (for the acos/asin derivative)."""
    slo, shi = _sqr_bounds(x.lo, x.hi)
    return np.sqrt(np.maximum(_down(1.0 - shi), 0.0)), np.sqrt(_up(1.0 - slo))


def _inverse_trig(x: Interval, name: str, f, sign: float) -> Interval:
    x = Interval._lift(x)
    bad = (x.lo < -1) | (x.hi > 1)
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the argument must lie within [-1, 1], "
                 f"not {_fmt(x.lo, x.hi, bad)}", x)
    a, b = f(x.lo), f(x.hi)
    lo, hi = _widen(np.minimum(a, b), np.maximum(a, b), LIBM_ULPS)
    if x.dlo is None:
        return Interval(lo, hi)
    bad = (x.lo <= -1) | (x.hi >= 1)
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the derivative is unbounded at -1 and "
                 f"1; the argument must lie within (-1, 1), not {_fmt(x.lo, x.hi, bad)}", x)
    rlo, rhi = _one_minus_sqr_sqrt(x)
    rlo, rhi = _down(rlo), _up(rhi)         # sqrt rounding
    bad = rlo <= 0
    x, = _domain(bad, IntervalDomainError, lambda: f"{name}: the argument is too close to -1 or 1 "
                 f"for a finite derivative bound: {_fmt(x.lo, x.hi, bad)}", x)
    lo, hi = np.where(np.isnan(x.lo), np.nan, lo), np.where(np.isnan(x.lo), np.nan, hi)
    g = (_down(sign / rhi), _up(sign / rlo)) if sign > 0 else (_down(sign / rlo), _up(sign / rhi))
    return x._chain(*g, lo, hi)


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


def sin(x: Interval) -> Interval:
    """Sine (radians); maxima at pi/2 + 2 pi k and minima at -pi/2 + 2 pi k are included."""
    x = Interval._lift(x)
    lo, hi = _trig_bounds(x.lo, x.hi, np.sin, 0.5 * np.pi, -0.5 * np.pi)
    if x.dlo is None:
        return Interval(lo, hi)
    glo, ghi = _trig_bounds(x.lo, x.hi, np.cos, 0.0, np.pi)
    return x._chain(glo, ghi, lo, hi)


def cos(x: Interval) -> Interval:
    """Cosine (radians); maxima at 2 pi k and minima at pi + 2 pi k are included."""
    x = Interval._lift(x)
    lo, hi = _trig_bounds(x.lo, x.hi, np.cos, 0.0, np.pi)
    if x.dlo is None:
        return Interval(lo, hi)
    slo, shi = _trig_bounds(x.lo, x.hi, np.sin, 0.5 * np.pi, -0.5 * np.pi)
    return x._chain(-shi, -slo, lo, hi)


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
    if x.dlo is None and y.dlo is None:
        return Interval(lo, hi)
    # d atan2(y, x) = (x dy - y dx) / (x**2 + y**2)
    r2 = x.sqr() + y.sqr()
    num = _strip(x) * y - _strip(y) * x
    d = num * _strip(r2).reciprocal()
    return Interval(lo, hi, d.dlo, d.dhi)


def clamp(x: Interval, lo: float, hi: float) -> Interval:
    """min(max(x, lo), hi). The derivative passes through where the value interval lies inside
    [lo, hi], is 0 where it lies outside, and is the hull with 0 otherwise (a bound on the
    generalized gradient of the Lipschitz clamp, valid in the mean-value theorem)."""
    x = Interval._lift(x)
    vlo, vhi = np.clip(x.lo, lo, hi), np.clip(x.hi, lo, hi)
    if x.dlo is None:
        return Interval(vlo, vhi)
    inside = (x.lo >= lo) & (x.hi <= hi)
    if np.all(inside):
        return Interval(vlo, vhi, x.dlo, x.dhi)
    outside = (x.hi <= lo) | (x.lo >= hi)
    dlo = np.where(inside, x.dlo, np.where(outside, 0.0, np.minimum(x.dlo, 0.0)))
    dhi = np.where(inside, x.dhi, np.where(outside, 0.0, np.maximum(x.dhi, 0.0)))
    return Interval(vlo, vhi, dlo, dhi)


def ldexp(x: Interval, k: int) -> Interval:
    """x * 2**k, exact (barring overflow and underflow)."""
    x = Interval._lift(x)
    if x.dlo is None:
        return Interval(np.ldexp(x.lo, k), np.ldexp(x.hi, k))
    return Interval(np.ldexp(x.lo, k), np.ldexp(x.hi, k), np.ldexp(x.dlo, k), np.ldexp(x.dhi, k))


def _strip(v: Interval) -> Interval:
    """The value of ``v`` without its derivative (a constant factor in a product rule)."""
    return Interval(v.lo, v.hi)


# -- constructors -------------------------------------------------------------------------------
def point(x) -> Interval:
    """An exact real constant (no derivative)."""
    return Interval._lift(x)


def variables(lo, hi, derivatives: bool = True) -> list[Interval]:
    """The n input variables over cells ``[lo, hi]`` (arrays of shape (N, n)).

    Variable k has value interval ``[lo[:, k], hi[:, k]]`` and, if ``derivatives``, the unit
    partial derivative with respect to input k.
    """
    lo, hi = np.atleast_2d(np.asarray(lo, dtype=np.float64)), np.atleast_2d(np.asarray(hi, dtype=np.float64))
    if lo.shape != hi.shape:
        raise ValueError(f"lo and hi must have one shape, not {lo.shape} and {hi.shape}")
    bad = ~(lo <= hi)
    if np.any(bad):
        raise ValueError(f"cell bounds must satisfy lo <= hi, not {_fmt(lo, hi, bad)}")
    n, cells = lo.shape[1], lo.shape[0]
    out = []
    for k in range(n):
        if derivatives:
            d = np.zeros((n, 1))
            d[k] = 1.0
            out.append(Interval(lo[:, k], hi[:, k], np.broadcast_to(d, (n, cells)), np.broadcast_to(d, (n, cells))))
        else:
            out.append(Interval(lo[:, k], hi[:, k]))
    return out


#: Interval namespace with the names of ``ikseries.kinematics.NUMPY_MATH``.
MATH = SimpleNamespace(sqrt=sqrt, atan2=atan2, acos=acos, asin=asin, cos=cos, sin=sin)
