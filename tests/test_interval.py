"""Interval arithmetic with derivatives: enclosures hold at sampled points; domain errors."""
import numpy as np
import pytest

from ikseries.fit import interval as ia
from ikseries.fit.interval import MATH, Interval, IntervalDomainError


def _boxes(rng, n_cells, lo, hi, width):
    a = rng.uniform(lo, hi, (n_cells, 2))
    return a, a + rng.uniform(0, width, (n_cells, 2))


def _expressions():
    m = MATH
    return {
        "poly": lambda x, y: 3.0 * x ** 3 - x * y + 2.0 - y ** 2 / 4.0 + (1.5 - x) * (x + y),
        "div": lambda x, y: (x + 1.0) / (y * y + 0.5) + 2.0 / (x + 3.0) + (x + 3.0) ** -2,
        "sqrt": lambda x, y: m.sqrt(x * x + y * y + 0.1) * y,
        "trig": lambda x, y: m.sin(3.0 * x) * m.cos(y * x) - m.cos(x - 2.0 * y),
        "inverse": lambda x, y: m.acos(x / 3.0 + 0.1) + m.asin(y / 4.0) * x,
        "atan2": lambda x, y: m.atan2(y, x + 3.5) + m.atan2(x + 3.5, -y - 4.0),
    }


def _point_ad(expr, pts):
    return expr(*ia.variables(pts, pts, order=2))


@pytest.mark.parametrize("name", sorted(_expressions()))
def test_cell_enclosures_hold_at_sampled_points(name):
    """Value, gradient and Hessian at random points of random cells lie in the cell enclosure,
    and the point derivatives match finite differences."""
    expr = _expressions()[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    lo, hi = _boxes(rng, 200, -2.0, 2.0, 0.7)
    cell = expr(*ia.variables(lo, hi, order=2))
    for _ in range(20):
        pts = lo + (hi - lo) * rng.random(lo.shape)
        p = _point_ad(expr, pts)
        for (plo, phi), (clo, chi) in [((p.lo, p.hi), (cell.lo, cell.hi)), (p.d, cell.d), (p.h, cell.h)]:
            mid = 0.5 * (plo + phi)
            assert np.all((clo <= mid) & (mid <= chi))
    pts = lo + (hi - lo) * rng.random(lo.shape)
    p = _point_ad(expr, pts)
    f = lambda q: expr(*ia.variables(q, q, order=0)).lo  # noqa: E731
    eps = 1e-6
    for k in range(2):
        step = np.zeros(2)
        step[k] = eps
        fd = (f(pts + step) - f(pts - step)) / (2 * eps)
        assert np.allclose(0.5 * (p.dlo[k] + p.dhi[k]), fd, rtol=1e-5, atol=1e-5)
        g = lambda q: _point_ad(expr, q).dlo  # noqa: E731
        fd2 = (g(pts + step) - g(pts - step)) / (2 * eps)      # column k of the Hessian
        j, kk = ia.hessian_pairs(2)
        for pair in range(len(j)):
            if kk[pair] == k:
                h = 0.5 * (p.h[0][pair] + p.h[1][pair])
                assert np.allclose(h, fd2[j[pair]], rtol=1e-4, atol=1e-4)


def test_point_enclosures_are_tight_and_contain_the_float_result():
    x = np.linspace(0.1, 3.0, 50)
    for f, ref in [(MATH.sin, np.sin), (MATH.cos, np.cos), (MATH.sqrt, np.sqrt),
                   (lambda v: MATH.acos(v / 3.1), lambda v: np.arccos(v / 3.1))]:
        v, r = f(ia.point(x)), ref(x)
        assert np.all((v.lo <= r) & (r <= v.hi))
        assert np.all(v.hi - v.lo <= 1e-13 * (1 + np.abs(r)))


def test_trig_extrema_inside_a_cell_are_included():
    v = MATH.sin(Interval(np.array([1.0, 0.0, -2.0]), np.array([2.0, 10.0, -1.0])))
    assert v.hi[0] == 1.0 and v.lo[1] == -1.0 and v.hi[1] == 1.0 and v.lo[2] == -1.0
    c = MATH.cos(Interval(-0.1, 0.1))
    assert c.hi == 1.0 and c.lo <= np.cos(0.1)


def test_even_power_and_square_over_zero_are_non_negative():
    x = Interval(-1.0, 2.0)
    assert (x ** 2).lo == 0.0 and (x * x).lo == 0.0 and (x ** 4).hi >= 16.0
    assert (x ** 3).lo <= -1.0 and (x ** 3).hi >= 8.0
    assert (x ** 0).lo == 1.0


def test_floats_and_arrays_mix_in_as_constants():
    x = ia.variables(np.array([[1.0]]), np.array([[2.0]]))[0]
    for v in (2.0 - x, np.float64(2.0) - x, np.array([2.0]) - x):
        assert v.lo[0] <= 0.0 and v.hi[0] >= 1.0 and v.dlo[0, 0] <= -1.0 <= v.dhi[0, 0]
    y = 3.0 / x
    assert y.lo[0] <= 1.5 and y.hi[0] >= 3.0


@pytest.mark.parametrize("call, exc, words", [
    (lambda: 1.0 / Interval(-1.0, 2.0), ZeroDivisionError, "must not contain 0, not [-1, 2]"),
    (lambda: Interval(1.0, 2.0) / Interval(0.0, 0.0), ZeroDivisionError, "must not contain 0"),
    (lambda: MATH.sqrt(Interval(-0.5, 2.0)), IntervalDomainError, "sqrt: the argument must be >= 0"),
    (lambda: MATH.sqrt(ia.variables([[0.0]], [[1.0]])[0]), IntervalDomainError, "unbounded at 0"),
    (lambda: MATH.acos(Interval(0.5, 1.5)), IntervalDomainError, "within [-1, 1], not [0.5, 1.5]"),
    (lambda: MATH.asin(ia.variables([[0.5]], [[1.0]])[0]), IntervalDomainError, "unbounded at -1 and 1"),
    (lambda: MATH.atan2(Interval(-1.0, 1.0), Interval(-1.0, 1.0)), IntervalDomainError, "origin"),
    (lambda: MATH.atan2(Interval(-1.0, 1.0), Interval(-3.0, -1.0)), IntervalDomainError, "branch cut"),
    (lambda: Interval(1.0, 2.0) ** 0.5, TypeError, "must be an integer, not 0.5"),
    (lambda: Interval(1.0, 2.0) + "a", TypeError, "not str"),
])
def test_domain_errors_are_clear(call, exc, words):
    with pytest.raises(exc) as e:
        call()
    assert words in str(e.value)


def test_atan2_on_the_upper_side_of_the_cut_is_allowed():
    v = MATH.atan2(Interval(0.0, 1.0), Interval(-3.0, -1.0))
    assert v.lo <= np.arctan2(1.0, -1.0) and v.hi >= np.pi


def test_lenient_mode_marks_bad_cells_nan_and_keeps_the_others():
    x = Interval(np.array([0.5, 1.5]), np.array([0.7, 1.8]))
    with pytest.raises(IntervalDomainError):
        MATH.acos(x)
    with ia.lenient():
        v = MATH.acos(x)
    assert np.isfinite(v.lo[0]) and np.isnan(v.lo[1])


def test_clamp_derivatives():
    x = ia.variables(np.array([[0.0], [2.0], [0.5]]), np.array([[1.0], [3.0], [1.5]]), order=2)[0]
    c = ia.clamp(x * 2.0, -0.5, 2.5)          # inside, outside (above), straddling
    assert c.dlo[0].tolist() == pytest.approx([2.0, 0.0, 0.0]) and c.dhi[0].tolist() == pytest.approx([2.0, 0.0, 2.0])
    assert c.h[0][0, 0] == 0.0 and c.h[0][0, 1] == 0.0 and np.isnan(c.h[0][0, 2])
    assert c.hi.tolist() == pytest.approx([2.0, 2.5, 2.5]) and c.lo[1] == 2.5
