"""The structure search of one servo: the cheapest polynomial that meets its budget.

Per candidate variable set the degree rises until a Lawson near-minimax fit meets the
approximation budget on the check set; the best set is then tried piecewise; the winner is
pruned term by term while every removal saves a multiplier.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .context import FitError
from .lowering import structure_cost
from .polyfit import Basis, fit_least_squares, lawson
from .structure import FeatureSet, ServoFit

__all__ = ["Cells", "Rows", "Working", "fit_terms", "fit_servo", "prune", "MAX_DEGREE", "CUT_CELLS", "PRUNE_REJECTS"]

MAX_DEGREE = 12
PRUNE_REJECTS = 3
CUT_CELLS = (4, 8, 16)           # cell counts tried for a piecewise plan (tables of <= 16 entries)


class Rows:
    """Points (features, shape (N, n)) and target ticks of a fit or check set, with the
    points' monomial columns kept (:class:`~.polyfit.Basis`)."""

    __slots__ = ("x", "t", "basis")

    def __init__(self, x: np.ndarray, t: np.ndarray):
        self.x, self.t, self.basis = x, t, Basis(x)

    def __getstate__(self):
        return (self.x, self.t)

    def __setstate__(self, state):
        self.__init__(*state)

    def __iter__(self):           # unpacks as (x, t), like the (features, target) pairs it holds
        return iter((self.x, self.t))

    def matrix(self, terms) -> np.ndarray:
        return self.basis.matrix(terms)


class Working:
    """The rows a Lawson fit works on: the fit set and the check rows ``extra`` added by
    exchange rounds (in the order added), with the final Lawson weights ``w``."""

    __slots__ = ("fit", "check", "extra", "w")

    def __init__(self, fit: Rows, check: Rows, extra: np.ndarray, w):
        self.fit, self.check, self.extra, self.w = fit, check, extra, w

    def matrix(self, terms) -> np.ndarray:
        if not len(self.extra):
            return self.fit.matrix(terms)
        return np.concatenate([self.fit.matrix(terms), self.check.matrix(terms)[self.extra]])

    @property
    def target(self) -> np.ndarray:
        return np.concatenate([self.fit.t, self.check.t[self.extra]])


def fit_terms(terms, fit_set: Rows, check_set: Rows, budget_ticks, rounds: int = 4, warm: Working | None = None,
              iterations: int = 30):
    """Lawson near-minimax on the fit set, then exchange rounds adding the worst check
    points. Returns (coefficients, max error over fit and check sets, :class:`Working`)
    (the working rows and Lawson weights warm-start a fit of a subset of the terms)."""
    ca = check_set.matrix(terms)
    if warm is None:
        work = Working(fit_set, check_set, np.zeros(0, dtype=np.intp), None)
    else:
        work = warm
    w = work.w
    for _ in range(rounds):
        c, err, w = lawson(work.matrix(terms), work.target, iterations, w)
        cerr = np.abs(ca @ c - check_set.t)
        err = max(err, float(cerr.max()))
        if err <= budget_ticks:
            break
        worst = np.argsort(cerr)[-500:]
        work = Working(fit_set, check_set, np.concatenate([work.extra, worst]), None)
        w = None if warm is None else np.concatenate([w, np.full(len(worst), w.max())])
    return c, err, Working(fit_set, check_set, work.extra, w)


@dataclass
class Cells:
    """Fit and check sets of one servo polynomial, per cell of a piecewise fit (a single cell
    otherwise); each set is a :class:`Rows` of features (N, n) and target ticks."""
    fit: list
    check: list

    @classmethod
    def whole(cls, fit_set, check_set) -> "Cells":
        return cls([Rows(*fit_set)], [Rows(*check_set)])

    @classmethod
    def cut(cls, fs: FeatureSet, port, fit_set, check_set, raw) -> "Cells":
        """Rows of each cell of ``fs.cut``, the cut variable replaced by the offset in the cell;
        ``raw`` = real values of the cut port at the fit and check rows."""
        out = cls([], [])
        for c in range(fs.cut.cells):
            for dst, (x, t), v in ((out.fit, fit_set, raw[0]), (out.check, check_set, raw[1])):
                sel, off = fs.cut.rows(port, v, c)
                xc = x[sel].copy()
                xc[:, fs.cut.var] = off
                dst.append(Rows(xc, t[sel]))
        return out

    def poly(self, terms, coef: np.ndarray) -> dict:
        """{exponents: coefficient} (a tuple per cell when piecewise) from coef (cells, terms)."""
        if len(self.fit) == 1:
            return {e: float(v) for e, v in zip(terms, coef[0])}
        return {e: tuple(float(v) for v in coef[:, j]) for j, e in enumerate(terms)}

    def coef(self, poly: dict, terms) -> np.ndarray:
        return np.array([[poly[e] for e in terms]]) if len(self.fit) == 1 else \
            np.array([poly[e] for e in terms]).T

    def lsq_error(self, terms) -> float:
        err = 0.0
        for rows in self.fit:
            a = rows.matrix(terms)
            err = max(err, float(np.max(np.abs(a @ fit_least_squares(a, rows.t) - rows.t))))
        return err

    def fit_terms(self, terms, budget_ticks, rounds: int = 4, warm=None, iterations: int = 30):
        """:func:`fit_terms` in every cell: (coef (cells, terms), max error, states)."""
        coefs, err, states = [], 0.0, []
        for c, (fit_set, check_set) in enumerate(zip(self.fit, self.check)):
            cf, e, st = fit_terms(terms, fit_set, check_set, budget_ticks, rounds,
                                  None if warm is None else warm[c], iterations)
            coefs.append(cf)
            err, states = max(err, e), states + [st]
        return np.array(coefs), err, states

    def forget_columns(self) -> None:
        """Drop the kept monomial columns (they can take hundreds of MB per servo)."""
        for rows in self.fit + self.check:
            rows.basis = Basis(rows.x)


def fit_servo(ctx, name, candidates, sets, raw, budget_ticks, progress) -> ServoFit:
    """The cheapest (fewest multipliers) polynomial over any candidate variable set whose
    near-minimax fit meets ``budget_ticks`` on the check set, then pruned.

    ``sets[kind]`` = (fit set, check set), each (features, target ticks); ``raw[port]`` = the
    real values of an input port at the fit and check rows. Per candidate the total degree
    rises until the fit meets the budget or the structure already costs more than the best
    plan found. Then the best variable set is tried piecewise: cut along each of its
    variables that is an input port into ``CUT_CELLS`` cells (coefficient tables, a lower
    degree); a piecewise plan wins only with strictly fewer multipliers, the fewest cells first.
    """
    best = None

    def search(fs, data):
        nonlocal best
        for deg in range(1, MAX_DEGREE + 1):
            terms = fs.terms(deg)
            cost = structure_cost(ctx, fs, terms, name)
            if best is not None and cost >= best[0]:
                return
            if data.lsq_error(terms) > 8 * budget_ticks:
                continue
            c, err, state = data.fit_terms(terms, budget_ticks)
            progress(f"  {name}: {fs.label()}, {'degree per variable' if fs.tensor else 'degree'} {deg}, "
                     f"{len(terms)} terms, {cost} multipliers, max fit error {err:.4g} ticks")
            if err <= budget_ticks:
                best = (cost, ServoFit(name, fs, deg, data.poly(terms, c), err), state, data)
                return

    for fs in candidates:
        search(fs, Cells.whole(*sets[fs.kind]))
    if best is None:
        raise FitError(f"servo {name}: no polynomial up to total degree {MAX_DEGREE} reaches the "
                       f"approximation budget of {budget_ticks:g} ticks")
    base = best[1].features
    ports = {i.name: i for i in ctx.inputs}
    for var, nm in enumerate(base.names):
        if nm not in ports or base.allowed[var] == "none":
            continue
        for cells in CUT_CELLS:
            fs = base.piecewise(var, ports[nm], cells)
            if fs.cut.cells > 1:
                search(fs, Cells.cut(fs, ports[nm], *sets[base.kind], raw[nm]))
    cost, sf, state, data = best
    return prune(ctx, sf, cost, data, state, budget_ticks, progress)


def prune(ctx, sf: ServoFit, cost: int, data: Cells, state, budget_ticks, progress) -> ServoFit:
    """Drop terms while the refitted polynomial still meets the budget.

    Only removals that save a multiplier are tried (in a nested Horner scheme most
    inner coefficients cost an add, not a multiply), least important first
    (|coefficient| x largest |monomial| on the check set, the largest over the cells); stops
    after ``PRUNE_REJECTS`` refused removals in a row. Each trial refit is warm-started from
    the current fit's working set and Lawson weights (one exchange round). The result carries
    its fit data (``refit``) for the coefficient refit after quantization.
    """
    terms = list(sf.poly)
    coef = data.coef(sf.poly, terms)
    rejected: set = set()
    misses = 0
    while misses < PRUNE_REJECTS:
        scale = np.max([[rows.basis.magnitude(t) for t in terms] for rows in data.check], axis=0)
        order = np.argsort(np.max(np.abs(coef), axis=0) * scale, kind="stable")
        pick = None
        for i in order:
            t = terms[i]
            if sum(t) == 0 or t in rejected:
                continue
            rest = terms[:i] + terms[i + 1:]
            c2 = structure_cost(ctx, sf.features, rest, sf.name)
            if c2 < cost:
                pick = (t, rest, c2)
                break
        if pick is None:
            break
        t, rest, c2 = pick
        c, err, st = data.fit_terms(rest, budget_ticks, rounds=1, warm=state, iterations=12)
        if err <= budget_ticks:
            terms, coef, cost, misses, state = rest, c, c2, 0, st
            sf = ServoFit(sf.name, sf.features, sf.degree, data.poly(terms, c), err)
        else:
            rejected.add(t)
            misses += 1
    progress(f"  {sf.name}: pruned to {len(terms)} terms, {cost} multipliers, "
             f"max fit error {sf.fit_error_ticks:.4g} ticks")
    data.forget_columns()
    return dataclasses.replace(sf, refit=(data, state, budget_ticks))
