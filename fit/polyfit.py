"""Multivariable polynomial bases and near-minimax fitting (float64).

Conventions follow numpy.polynomial: a term is an exponent tuple ``e`` standing
for ``prod(x[k] ** e[k])``; a polynomial is a dict ``{e: coefficient}``.
"""
from __future__ import annotations

import itertools

import numpy as np

__all__ = ["total_degree_terms", "vander", "Basis", "evaluate", "fit_lawson", "lawson", "fit_least_squares"]


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
    return Basis(points).matrix(terms)


class Basis:
    """The monomial columns of one point set, each computed once.

    A structure search builds design matrices of many overlapping term lists over the same
    points (degrees rising, terms pruned one at a time); with the columns kept, each matrix
    is a gather of columns instead of a product per entry. The columns are exactly those of
    :func:`vander`. The cache is not pickled (it is rebuilt on use).
    """

    def __init__(self, points: np.ndarray):
        self.points = np.asarray(points, dtype=np.float64)
        self._powers: dict = {}
        self._columns: dict = {}
        self._magnitudes: dict = {}
        self._norms: dict = {}
        self._scratch = None

    def __getstate__(self):
        return {"points": self.points}

    def __setstate__(self, state):
        self.__init__(state["points"])

    def _power(self, k: int, e: int) -> np.ndarray:
        """points[:, k] ** e by one multiplication from the power below (``**`` with an
        integer exponent calls ``pow`` per entry, several times slower)."""
        key = (k, e)
        if key not in self._powers:
            x = self.points[:, k]
            self._powers[key] = np.ones_like(x) if e == 0 else x.copy() if e == 1 else self._power(k, e - 1) * x
        return self._powers[key]

    def column(self, term: tuple[int, ...]) -> np.ndarray:
        col = self._columns.get(term)
        if col is None:
            factors = [self._power(k, e) for k, e in enumerate(term) if e]
            if not factors:
                col = np.ones(len(self.points))
            else:
                col = factors[0].copy()
                for f in factors[1:]:
                    col *= f
            self._columns[term] = col
        return col

    def magnitude(self, term: tuple[int, ...]) -> float:
        """max |column(term)| over the points."""
        if term not in self._magnitudes:
            self._magnitudes[term] = float(np.abs(self.column(term)).max())
        return self._magnitudes[term]

    def norm(self, term: tuple[int, ...]) -> float:
        """Root mean square of column(term) over the points (1 for a zero column)."""
        if term not in self._norms:
            v = float(np.sqrt(np.mean(np.square(self.column(term), out=self.scratch()))))
            self._norms[term] = v if v > 0 else 1.0
        return self._norms[term]

    def scratch(self) -> np.ndarray:
        """A work array of one column's length, kept: a column-sized temporary freed at the top
        of the heap is handed back to the system and page-faulted in again on the next use, which
        cost more than the arithmetic on it (a third of the search's CPU time went to the kernel)."""
        if self._scratch is None:
            self._scratch = np.empty(len(self.points))
        return self._scratch

    def matrix(self, terms: list[tuple[int, ...]]) -> np.ndarray:
        if not terms:
            return np.zeros((len(self.points), 0))
        return np.stack([self.column(tuple(t)) for t in terms], 1)

    def rows(self, terms: list[tuple[int, ...]], index: np.ndarray) -> np.ndarray:
        """matrix(terms)[index], without forming the whole matrix."""
        return np.stack([self.column(tuple(t))[index] for t in terms], 1).reshape(len(index), len(terms))

    def residual(self, terms: list[tuple[int, ...]], coef: np.ndarray, target: np.ndarray) -> np.ndarray:
        """target - matrix(terms) @ coef, a column at a time (no matrix of all points is formed:
        at a few hundred thousand points its allocation costs more than the products)."""
        r = np.array(target, dtype=np.float64)
        tmp = self.scratch()
        for t, c in zip(terms, coef):
            np.multiply(self.column(tuple(t)), c, out=tmp)
            r -= tmp
        return r


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
