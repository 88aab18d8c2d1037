"""The minimax exchange (fit/minimax.py) against a reference LP solver, its refusals as proofs,
its region choice and its determinism."""
import numpy as np
import pytest
from scipy.optimize import linprog

from ikseries.fit.minimax import GAP, _new_rows, minimax, region_ids, subset_minimax
from ikseries.fit.polyfit import Basis, total_degree_terms, vander


def _problem(n_points=20000, degree=5, seed=3):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n_points, 2))
    target = 1000 * np.exp(0.7 * x[:, 0]) * np.cos(1.3 * x[:, 1] + 0.2) + 50 * x[:, 0] * x[:, 1] ** 2
    return x, target, total_degree_terms(degree, ["any", "any"])


def _lp_minimax(a, b):
    """min t subject to |a c - b| <= t, by HiGHS (columns normalised)."""
    norm = np.linalg.norm(a, axis=0)
    an = a / norm
    m, n = an.shape
    ones = np.ones((m, 1))
    r = linprog(np.r_[np.zeros(n), 1.0], A_ub=np.block([[an, -ones], [-an, -ones]]), b_ub=np.r_[b, -b],
                bounds=[(None, None)] * (n + 1), method="highs")
    assert r.status == 0, r.message
    return r.x[:n] / norm, r.x[n]


def test_the_exchange_finds_the_minimax_error_of_the_whole_pool():
    x, target, terms = _problem()
    fit = minimax(Basis(x), target, terms, 1e9, region_ids(x))
    _, best = _lp_minimax(vander(x, terms), target)
    err = np.abs(vander(x, terms) @ fit.coef - target).max()
    assert fit.optimal and not fit.refused
    assert err == pytest.approx(fit.error, rel=1e-9)
    assert fit.lower <= best * (1 + 1e-6)                     # a lower bound of the optimum
    assert best <= fit.error <= best * (1 + 2 * GAP)          # and the fit is at it
    assert len(fit.reference) == len(terms) + 1 and np.isin(fit.reference, fit.active).all()


def test_a_refusal_is_a_lower_bound_above_the_budget():
    x, target, terms = _problem()
    _, best = _lp_minimax(vander(x, terms), target)
    fit = minimax(Basis(x), target, terms, 0.8 * best, region_ids(x))
    assert fit.refused
    assert 0.8 * best < fit.lower <= best * (1 + 1e-6)
    # a budget the optimum meets is never refused
    fit = minimax(Basis(x), target, terms, best * (1 + 1e-4), region_ids(x))
    assert not fit.refused and fit.error <= best * (1 + 1e-4)


def test_without_settling_the_first_fit_within_the_budget_is_returned():
    x, target, terms = _problem()
    _, best = _lp_minimax(vander(x, terms), target)
    fit = minimax(Basis(x), target, terms, 3 * best, region_ids(x), settle=False)
    assert not fit.refused and fit.error <= 3 * best
    settled = minimax(Basis(x), target, terms, 3 * best, region_ids(x), start=fit.active)
    assert settled.optimal and settled.error <= best * (1 + 2 * GAP)


def test_the_exchange_is_deterministic():
    x, target, terms = _problem(seed=5)
    fits = [minimax(Basis(x), target, terms, 1e9, region_ids(x)) for _ in range(2)]
    assert fits[0].coef.tobytes() == fits[1].coef.tobytes()
    assert np.array_equal(fits[0].active, fits[1].active)


def test_subset_minimax_is_the_lp_optimum_also_from_a_related_reference():
    x, target, terms = _problem(n_points=600, degree=4)
    a = vander(x, terms)
    coef, ref = subset_minimax(a, target)
    lp_coef, best = _lp_minimax(a, target)
    assert np.abs(a @ coef - target).max() == pytest.approx(best, rel=1e-7)
    # one term fewer (its coefficient fixed), starting among the reference just found
    rhs = target - a[:, 0] * lp_coef[0]
    coef2, _ = subset_minimax(a[:, 1:], rhs, ref)
    _, best2 = _lp_minimax(a[:, 1:], rhs)
    assert np.abs(a[:, 1:] @ coef2 - rhs).max() == pytest.approx(best2, rel=1e-7)


@pytest.mark.parametrize("rows", [1, 3, 6])
def test_subset_minimax_of_fewer_rows_than_a_reference_needs_fits_fewer_columns(rows):
    """A sparse cell may leave fewer active rows than terms + 1: the best conditioned columns,
    one fewer than the rows, are fitted (the rows are then interpolated) and the rest get 0."""
    x, target, terms = _problem(n_points=rows, degree=3)
    a = vander(x, terms)
    coef, ref = subset_minimax(a, target)
    assert np.count_nonzero(coef) <= rows - 1
    if rows > 1:
        assert np.abs(a @ coef - target).max() <= np.abs(target).max()


def test_new_rows_are_the_worst_outside_the_active_set_one_per_region():
    err = np.array([5.0, 9.0, 1.0, 7.0, 8.0, 6.0, 9.5])
    regions = np.array([0, 0, 1, 1, 2, 2, 0])
    active = np.array([6])                       # the worst of region 0, already in
    assert list(_new_rows(err, 4.0, regions, active, 10)) == [1, 3, 4]
    assert list(_new_rows(err, 4.0, regions, active, 2)) == [1, 4]      # the worst regions first
    assert list(_new_rows(err, 8.5, regions, active, 10)) == [1]


def test_regions_grid_the_varying_coordinates_only():
    x = np.column_stack([np.linspace(0, 1, 1000), np.full(1000, 3.0), np.linspace(-1, 1, 1000) ** 3])
    ids = region_ids(x, 16)
    assert ids.min() == 0 and len(np.unique(ids)) <= 16
    assert len(np.unique(region_ids(x[:, :2], 16))) == 16      # one varying coordinate: 16 slabs
    assert np.all(region_ids(np.ones((5, 2))) == 0)


def test_terms_dependent_over_the_pool_are_fitted_by_an_independent_subset():
    """An offset that takes two values in a cell: its square is affine in it over the pool."""
    rng = np.random.default_rng(7)
    x = np.column_stack([rng.choice([-0.5, 0.5], 4000), rng.uniform(-1, 1, 4000)])
    target = 100 * np.sin(x[:, 1] + x[:, 0]) + 30 * x[:, 0]
    terms = total_degree_terms(3, ["any", "any"])
    fit = minimax(Basis(x), target, terms, 1e9, region_ids(x))
    a = vander(x, terms)
    keep = np.flatnonzero(fit.coef != 0)
    _, best = _lp_minimax(a[:, keep], target)
    assert len(keep) < len(terms) and np.linalg.matrix_rank(a) == len(keep)
    assert np.abs(a @ fit.coef - target).max() <= best * (1 + 2 * GAP)
    coef, _ = subset_minimax(a[::10], target[::10])
    assert np.count_nonzero(coef) == len(keep)


def test_rows_that_do_not_span_the_terms_are_completed_from_the_pool():
    """The first rows (a stride) see x = 0 only; the few rows with x != 0 join them."""
    rng = np.random.default_rng(8)
    x = np.column_stack([np.zeros(4000), rng.uniform(-1, 1, 4000)])
    x[1:11, 0] = rng.uniform(0.5, 1, 10)
    target = 10 * x[:, 0] + np.cos(3 * x[:, 1])
    terms = [(0, 0), (1, 0), (0, 1), (0, 2)]
    fit = minimax(Basis(x), target, terms, 1e9, region_ids(x))
    _, best = _lp_minimax(vander(x, terms), target)
    assert np.all(fit.coef != 0) and fit.error <= best * (1 + 2 * GAP)
