"""Multivariable polynomial bases and near-minimax fitting (float64).

Conventions follow numpy.polynomial: a term is an exponent tuple ``e`` standing
for ``prod(x[k] ** e[k])``; a polynomial is a dict ``{e: coefficient}``.
"""
from __future__ import annotations

import itertools

import numpy as np

__all__ = ["total_degree_terms", "vander", "evaluate", "fit_lawson", "fit_least_squares"]


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


def fit_least_squares(a: np.ndarray, target: np.ndarray, weights=None) -> np.ndarray:
    if weights is not None:
        sw = np.sqrt(weights)
        a, target = a * sw[:, None], target * sw
    # column scaling keeps the normal problem well conditioned
    norm = np.linalg.norm(a, axis=0)
    norm[norm == 0] = 1.0
    c, *_ = np.linalg.lstsq(a / norm, target, rcond=None)
    return c / norm


def fit_lawson(a: np.ndarray, target: np.ndarray, iterations: int = 25) -> tuple[np.ndarray, float]:
    """Near-minimax coefficients by Lawson's iteratively reweighted least squares.

    Returns the coefficients with the smallest maximum error seen and that error.
    """
    w = np.full(len(target), 1.0 / len(target))
    best_c, best_e = None, np.inf
    for _ in range(iterations):
        c = fit_least_squares(a, target, w)
        err = np.abs(a @ c - target)
        m = float(err.max())
        if m < best_e:
            best_c, best_e = c, m
        w = w * err
        s = w.sum()
        if not np.isfinite(s) or s == 0:
            break
        w /= s
    return best_c, best_e
