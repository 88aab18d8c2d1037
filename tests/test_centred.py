"""Centred interval evaluation: enclosures hold at sampled points, are never wider than plain
interval arithmetic and are much tighter on a Horner chain; a clamp that cannot act is seen."""
import numpy as np
import pytest

from ikseries.fit import centred as cn
from ikseries.fit import interval as ia

from test_interval import _boxes, _expressions


def _cos_series(u, mathmod):
    """cos(pi x) by its Taylor series to degree 10 in x, Horner in u = x**2 (alternating, with
    large terms near x = 1: plain interval arithmetic loses the cancellation)."""
    coeffs = [(-1) ** k * np.pi ** (2 * k) / np.prod(np.arange(1, 2 * k + 1), dtype=float)
              for k in range(6)]
    acc = coeffs[-1]
    for c in coeffs[-2::-1]:
        acc = acc * u + c
    return acc


@pytest.mark.parametrize("name", sorted(_expressions()))
def test_centred_enclosures_hold_and_are_no_wider(name):
    """Value, gradient and Hessian at random points lie in the centred cell enclosure, which
    lies within the plain one."""
    expr = _expressions()[name]
    rng = np.random.default_rng(sum(map(ord, name)) + 1)
    lo, hi = _boxes(rng, 200, -2.0, 2.0, 0.3)
    xp_plain, xp = ia.MATH, cn.MATH
    plain = _expressions_with(name, xp_plain)(*ia.variables(lo, hi, order=2))
    cent = _expressions_with(name, xp)(*cn.variables(lo, hi))
    assert isinstance(cent, cn.Centred)
    cell = cent.x
    assert np.all((plain.lo <= cell.lo) & (cell.hi <= plain.hi))
    assert np.all((plain.d[0] <= cell.d[0]) & (cell.d[1] <= plain.d[1]))
    for _ in range(20):
        pts = lo + (hi - lo) * rng.random(lo.shape)
        p = expr(*ia.variables(pts, pts, order=2))
        for (plo, phi), (clo, chi) in [((p.lo, p.hi), (cell.lo, cell.hi)), (p.d, cell.d), (p.h, cell.h)]:
            mid = 0.5 * (plo + phi)
            assert np.all((clo <= mid) & (mid <= chi))
    # the centre part is the point evaluation at the midpoint
    c = 0.5 * (lo + hi)
    pc = expr(*ia.variables(c, c, order=1))
    assert np.allclose(cent.c.lo, pc.lo, rtol=1e-12, atol=1e-12)


def _expressions_with(name, xp):
    """The expression ``name`` of test_interval written against the namespace ``xp``."""
    m = xp
    return {
        "poly": lambda x, y: 3.0 * x ** 3 - x * y + 2.0 - y ** 2 / 4.0 + (1.5 - x) * (x + y),
        "div": lambda x, y: (x + 1.0) / (y * y + 0.5) + 2.0 / (x + 3.0) + (x + 3.0) ** -2,
        "sqrt": lambda x, y: m.sqrt(x * x + y * y + 0.1) * y,
        "trig": lambda x, y: m.sin(3.0 * x) * m.cos(y * x) - m.cos(x - 2.0 * y),
        "inverse": lambda x, y: m.acos(x / 3.0 + 0.1) + m.asin(y / 4.0) * x,
        "atan2": lambda x, y: m.atan2(y, x + 3.5) + m.atan2(x + 3.5, -y - 4.0),
    }[name]


def test_horner_chain_is_tight_and_a_clamp_that_cannot_act_keeps_the_hessian():
    """cos(pi x) near x = 0.95 (value ~ -0.985) on cells 0.01 wide: the plain enclosure is
    wide enough to cross a clamp at -(1 + 2**-10) and loses the Hessian; the centred one
    is within a few times the true range and keeps it."""
    lo = np.array([[0.94], [0.99]])
    hi = lo + 0.01
    pts = lo + (hi - lo) * np.linspace(0.0, 1.0, 101)            # the series' true range
    true = _cos_series(pts * pts, np)
    lim = 1.0 + 2.0 ** -10
    (xv,) = ia.variables(lo, hi, order=2)
    arg = _cos_series(xv.sqr(), ia)
    plain = ia.clamp(arg, -lim, lim)
    (xc,) = cn.variables(lo, hi)
    cent = cn.clamp(_cos_series(xc.sqr(), cn), -lim, lim)
    assert arg.lo[0] < -lim and np.isnan(plain.h[0][0, 0])        # plain: the clamp may act
    true_width = np.ptp(true[0])
    assert cent.x.hi[0] - cent.x.lo[0] < 3 * true_width
    assert cent.x.lo[0] <= true[0].min() and cent.x.hi[0] >= true[0].max()
    assert cent.x.h[0][0, 0] <= np.pi ** 2 * 0.98 <= cent.x.h[1][0, 0] < 2 * np.pi ** 2  # -pi**2 cos
    # at x = 1 the series (degree 10) dips below -1 only by its truncation error: still no kink
    assert np.isfinite(cent.x.h[0][0, 1]) and cent.x.lo[1] >= -lim


def test_constants_mix_in_on_either_side():
    (x,) = cn.variables(np.array([[1.0]]), np.array([[2.0]]))
    for v in (2.0 - x, np.float64(2.0) - x, x * -1.0 + 2.0, ia.point(2.0) - x.x):
        v = v.x if isinstance(v, cn.Centred) else v
        assert v.lo[0] <= 0.0 and v.hi[0] >= 1.0
    y = 3.0 / x
    assert y.x.lo[0] <= 1.5 and y.x.hi[0] >= 3.0 and y.c.lo[0] <= 2.0 <= y.c.hi[0]
    assert cn.ldexp(x, 3).x.hi[0] == 16.0 and cn.ldexp(ia.point(1.0), -1).lo == 0.5


def test_variables_reject_inverted_cells():
    with pytest.raises(ValueError, match="cell bounds must satisfy lo <= hi"):
        cn.variables(np.array([[1.0]]), np.array([[0.0]]))


def test_domain_errors_pass_through_and_lenient_marks_cells():
    (x,) = cn.variables(np.array([[0.5], [1.5]]), np.array([[0.7], [1.8]]))
    with pytest.raises(ia.IntervalDomainError, match="acos"):
        cn.MATH.acos(x)
    with ia.lenient():
        v = cn.MATH.acos(x)
    assert np.isfinite(v.x.lo[0]) and np.isnan(v.x.lo[1]) and np.isnan(v.x.h[0][0, 1])


def test_an_interval_constant_on_the_left_defers_to_centred():
    """A constant plan output minus a centred reference (quadruped-fore's fixed servo)."""
    (x,) = cn.variables(np.array([[1.0]]), np.array([[2.0]]))
    for v in (ia.point(3.0) - x, ia.point(3.0) + x, ia.point(3.0) * x, ia.point(3.0) / x):
        assert isinstance(v, cn.Centred) and v.c.d is not None
    v = ia.point(3.0) - x
    assert v.x.lo[0] <= 1.0 and v.x.hi[0] >= 2.0 and v.c.lo[0] <= 1.5 <= v.c.hi[0]
