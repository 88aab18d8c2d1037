"""The structure search of one servo: the cheapest polynomial that meets its budget.

Per candidate variable set the degree rises until the minimax fit (:mod:`.minimax`) over the fit
and check samples meets the approximation budget; the best set is then tried piecewise, cut
along one input port and then on a grid over two; the winner is pruned term by term while every
removal saves a multiplier.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .context import FitError
from .formats import fitted_cost
from .lowering import structure_cost, structure_multipliers
from .minimax import minimax, region_ids
from .polyfit import Basis
from .features import FEATURE_GRID_ENTRIES
from .structure import FeatureSet, ServoFit

__all__ = ["Cells", "CellsFit", "Rows", "fit_servo", "prune", "MAX_DEGREE", "MAX_COST", "CUT_CELLS", "GRID_CELLS", "MAX_GRID_CELLS",
           "PRUNE_REJECTS", "FINALISTS", "FINALIST_MARGIN"]

MAX_DEGREE = 12
MAX_COST = 100                   # no structure of more multiplications is tried, whatever the cost model
                                 # (issue 3: <= 100 multiply-adds per servo):
                                 # where no whole polynomial fits, the climb to MAX_DEGREE of a tensor set of three
                                 # variables reaches 1183 terms, a minimax fit of minutes each, all futile
PRUNE_REJECTS = 5                # refused removals in a row that end pruning (a refusal is cheap: a lower bound)
FINALISTS = 2                    # the cheapest structures found that are pruned (the fewest multipliers after wins),
FINALIST_MARGIN = 3              # those costing at most this much more than the cheapest
CUT_CELLS = (4, 8, 16)           # cell counts tried for a piecewise plan (tables of <= 16 entries)
GRID_CELLS = (2, 4)              # cells tried per port of a two-port grid (rounded to the ports' powers of two);
                                 # with 8 too, cylinder-leg's plan needs products wider than 18 x 18 (fit.products = "dsp" refused)
SCREEN_STRIDE = 1                # a grid's screening fit: every this many fit samples (a subset of the pool)
MAX_GRID_CELLS = 16              # cells and table entries (row padding included) of a grid at most
FEATURE_BITS = (1, 4)            # a feature's cells are 2**-bits wide (4 to 32 cells over [-1, 1))
MIN_CELL_ROWS = 32               # a feature cell with fewer sample rows is fitted on a window around it,
CELL_WINDOWS = (0.0, 0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 64.0)   # widened by these many cell widths each side
SPREAD_RANK = 1e-6               # ... as is one whose quadratics in its cut variables are dependent to this


class Rows:
    """The pool of one fit: points (features, shape (N, n)) and target ticks of the fit and check
    samples together, with the points' monomial columns kept (:class:`~.polyfit.Basis`) and their
    regions (:func:`~.minimax.region_ids`)."""

    __slots__ = ("x", "t", "basis", "_regions")

    def __init__(self, x: np.ndarray, t: np.ndarray):
        self.x, self.t, self.basis, self._regions = x, t, Basis(x), None

    def __getstate__(self):
        return (self.x, self.t)

    def __setstate__(self, state):
        self.__init__(*state)

    def __iter__(self):           # unpacks as (x, t), like the (features, target) pairs it holds
        return iter((self.x, self.t))

    def matrix(self, terms) -> np.ndarray:
        return self.basis.matrix(terms)

    @property
    def regions(self) -> np.ndarray:
        if self._regions is None:
            self._regions = region_ids(self.x)
        return self._regions

    def fit(self, terms, budget_ticks, start=None, settle=True):
        """The minimax fit of ``terms`` (:class:`~.minimax.MinimaxFit`), refused once it cannot
        meet ``budget_ticks``; ``start``: pool rows to begin with; without ``settle`` the first
        coefficients within the budget."""
        return minimax(self.basis, self.t, list(terms), budget_ticks, self.regions, start, settle)

    def error(self, terms, coef) -> float:
        """Max |error| of coefficients ``coef`` of ``terms`` over the pool."""
        return float(np.max(np.abs(self.basis.residual(list(terms), coef, self.t))))


class CellsFit(NamedTuple):
    """Minimax fit of one polynomial in every cell: coefficients (cells, terms) (None when
    refused), max error over the cells (a lower bound when refused), per cell its
    :class:`~.minimax.MinimaxFit` (the state a related fit warm-starts from)."""
    coef: np.ndarray | None
    error: float
    states: list
    refused: bool


@dataclass
class Cells:
    """The pool (:class:`Rows`: fit and check samples, features (N, n) and target ticks) of one
    servo polynomial per cell of a piecewise fit (a single cell otherwise)."""
    rows: list
    hard: int = 0          # the cell that refused the last fit

    @classmethod
    def whole(cls, fit_set, check_set) -> "Cells":
        return cls([Rows(np.concatenate([fit_set[0], check_set[0]]), np.concatenate([fit_set[1], check_set[1]]))])

    @classmethod
    def cut(cls, fs: FeatureSet, ports: dict, fit_set, check_set, raw: dict, memo: dict | None = None) -> "Cells":
        """Rows of each cell of ``fs.cut`` (a grid's cells in its cell order), each cut variable
        replaced by the offset in its cell; ``ports``: PlanInputs by name, ``raw[port]`` = real
        values of a cut port at the fit and check rows; ``memo``: a dict keeping each cut's
        per-cell offsets for the next call on the same samples. A cell of a computed feature
        whose rows are too few or all on one curve (:func:`_spread`: the feature's range need
        not fill its cells) is fitted on a window around it, widened until they are enough (its
        polynomial then extends over the window)."""
        memo = {} if memo is None else memo
        cuts = fs.cut.cuts
        per_cut = [_feature_offsets(c, (fit_set[0], check_set[0]), memo) if c.port is None
                   else _cut_offsets(c, ports[c.port], raw[c.port], memo) for c in cuts]
        out = cls([])
        for cell in range(fs.cut.cells):
            per = np.unravel_index(cell, [c.cells for c in cuts])
            for widen in CELL_WINDOWS:
                offs = [[po[int(k)][s] for s in range(2)] if c.port is not None or not widen else
                        [_widened(c, x[:, c.var], int(k), widen) for x in (fit_set[0], check_set[0])]
                        for c, po, k in zip(cuts, per_cut, per)]
                rows = _cell_rows(cuts, offs, (fit_set, check_set))
                if all(c.port is not None for c in cuts) or _spread(rows, cuts):
                    break
            out.rows.append(rows)
        return out

    def poly(self, terms, coef: np.ndarray) -> dict:
        """{exponents: coefficient} (a tuple per cell when piecewise) from coef (cells, terms)."""
        if len(self.rows) == 1:
            return {e: float(v) for e, v in zip(terms, coef[0])}
        return {e: tuple(float(v) for v in coef[:, j]) for j, e in enumerate(terms)}

    def coef(self, poly: dict, terms) -> np.ndarray:
        return np.array([[poly[e] for e in terms]]) if len(self.rows) == 1 else \
            np.array([poly[e] for e in terms]).T

    def fit_terms(self, terms, budget_ticks, warm=None, settle=True) -> CellsFit:
        """The minimax fit in every cell, refused as soon as one cell's is; ``warm``: the states
        of a related fit (their active rows start this one's); without ``settle`` the first
        coefficients within the budget (enough to decide). The cell that refused last is fitted
        first (the next, larger term set is likely refused there too): the outcome and the fit
        are the same in any order, only a refusal's lower bound may come from another cell."""
        order = [self.hard] + [c for c in range(len(self.rows)) if c != self.hard]
        err, states = 0.0, [None] * len(self.rows)
        for c in order:
            st = self.rows[c].fit(terms, budget_ticks, None if warm is None else warm[c].active, settle)
            if st.refused:
                self.hard = c
                return CellsFit(None, st.error, [st], True)
            err, states[c] = max(err, st.error), st
        return CellsFit(np.array([st.coef for st in states]), err, states, False)

    def forget_columns(self) -> None:
        """Drop the kept monomial columns (they can take hundreds of MB per servo)."""
        for rows in self.rows:
            rows.basis = Basis(rows.x)


def _cut_offsets(cut, port, raw, memo: dict) -> list:
    """Per cell of ``cut``, per sample set (fit, check), the offset in the cell of every row
    (NaN off the cell), kept in ``memo``."""
    return _memo_offsets(memo, (cut.port, cut.shift, cut.cells), cut.cells,
                         [(len(v), lambda cell, v=v: cut.rows(port, v, cell)) for v in raw])


def _memo_offsets(memo: dict, key, cells: int, sets) -> list:
    """``memo[key]``, made on first use: per cell, per sample set, the offset of every row (NaN
    off the cell); ``sets``: per set its rows and ``rows_of(cell) -> (selected rows, offsets)``."""
    if key not in memo:
        memo[key] = []
        for cell in range(cells):
            per_set = []
            for size, rows_of in sets:
                sel, off = rows_of(cell)
                full = np.full(size, np.nan)
                full[sel] = off
                per_set.append(full)
            memo[key].append(per_set)
    return memo[key]


def _cell_rows(cuts, offs, sets) -> Rows:
    """The rows of one cell: per sample set, the rows every cut's offset (``offs[cut][set]``,
    NaN off the cell) keeps, each cut variable replaced by its offset."""
    xs, ts = [], []
    for s, (x, t) in enumerate(sets):
        keep = np.logical_and.reduce([~np.isnan(o[s]) for o in offs])
        xc = x[keep]
        for c, o in zip(cuts, offs):
            if c.var is not None:
                xc[:, c.var] = o[s][keep]
        xs.append(xc)
        ts.append(t[keep])
    return Rows(np.concatenate(xs), np.concatenate(ts))


def _spread(rows: Rows, cuts) -> bool:
    """Whether a cell's rows are enough to fit it: at least ``MIN_CELL_ROWS`` of them, and not
    all on one curve of its cut variables (the quadratics in them independent over the rows).
    A cell at the workspace's rim may hold only the samples of one face, e.g. on the circle
    x**2 + y**2 = r_max**2 of a cylinder: a fit there is free across the circle, where the
    cell still holds targets between the face and the last interior samples."""
    if len(rows.t) < MIN_CELL_ROWS:
        return False
    v = rows.x[:, [c.var for c in cuts if c.var is not None]]
    cols = [np.ones(len(v))] + [v[:, i] for i in range(v.shape[1])] + \
        [v[:, i] * v[:, j] for i in range(v.shape[1]) for j in range(i, v.shape[1])]
    sv = np.linalg.svd(np.column_stack(cols), compute_uv=False)
    return bool(sv[-1] > SPREAD_RANK * sv[0])


def _widened(cut, values, cell: int, widen: float) -> np.ndarray:
    """Offsets from cell ``cell`` of a feature cut of the rows within ``widen`` cell widths of
    it (NaN elsewhere)."""
    u = cut.position(values) - cell
    return np.where((u >= -widen) & (u < 1.0 + widen), 2.0 * u - 1.0, np.nan)


def _feature_offsets(cut, xs, memo: dict) -> list:
    """:func:`_cut_offsets` of a :class:`~.features.FeatureCut`: from the exact normalised
    feature values of the fit and check rows ``xs`` (column ``cut.var``)."""
    return _memo_offsets(memo, ("feature", cut.var, cut.bits, *map(id, xs)), cut.cells,
                         [(len(x), lambda cell, x=x: cut.offsets(x[:, cut.var], cell)) for x in xs])


def _fit_note(fit: CellsFit) -> str:
    if fit.refused:
        return f"minimax error above {fit.error:.4g} ticks"
    settled = all(st.optimal for st in fit.states)
    return f"max fit error {fit.error:.4g} ticks" + ("" if settled else " (within the budget, not settled)")


def fit_servo(ctx, name, candidates, sets, raw, budget_ticks, progress) -> ServoFit:
    """The cheapest (fewest multipliers) polynomial over any candidate variable set whose
    minimax fit over the fit and check samples meets ``budget_ticks``, pruned.

    ``sets[kind]`` = (fit set, check set), each (features, target ticks); ``raw[port]`` = the
    real values of an input port at the fit and check rows. Per candidate the total degree
    rises until the fit meets the budget or the structure already costs more than the best
    plan found. Then the best variable set is tried piecewise, with either term set (total
    degree or tensor): cut along each of its variables that is an input port into
    ``CUT_CELLS`` cells (coefficient tables, a lower degree); a piecewise plan wins only with
    strictly fewer multipliers, the fewest cells first. Then the best variable set is tried on
    two-port grids (:func:`_grid_sets`, :class:`_Grids`: every pair of input ports, each in
    ``GRID_CELLS`` cells, at most ``MAX_GRID_CELLS`` table entries), again winning only with strictly
    fewer multipliers. Where ``fit.table_entries`` allows ``FEATURE_GRID_ENTRIES`` or more, the
    variable sets with a computed variable (:func:`_feature_bases`) are then tried on cells of
    it, alone or on a grid with another variable (:func:`_feature_grid_sets`). The ``FINALISTS`` cheapest structures
    found (those within ``FINALIST_MARGIN`` of the cheapest) are each pruned (a cheaper one may
    prune less), the cheapest after pruning winning (on a tie the cheaper before); with a cost
    model that prices coefficient values (:class:`~.cost.DeviceCost`) the structures found are
    ranked for the finals, and the finalists after pruning, by their prices with their fitted
    coefficients (:func:`_ranked`). The candidates of one kind share their pool (and its
    monomial columns).
    """
    found: list = []           # (cost, ServoFit, states, Cells) of every new best, costs falling
    pools: dict = {}
    ctx.format_hints.pop(name, None)   # prices follow this search alone, in any process (jobs)

    def search(fs, data):
        for deg in range(1, MAX_DEGREE + 1):
            terms = fs.terms(deg)
            cost = _affordable(ctx, fs, terms, name, found)
            if cost is None:
                return
            fit = data.fit_terms(terms, budget_ticks, settle=False)
            progress(f"  {name}: {fs.label()}, {'degree per variable' if fs.tensor else 'degree'} {deg}, "
                     f"{len(terms)} terms, {ctx.cost_model.label(cost)}, {_fit_note(fit)}")
            if not fit.refused and fit.error <= budget_ticks:
                found.append((cost, ServoFit(name, fs, deg, data.poly(terms, fit.coef), fit.error), fit.states, data))
                return

    for fs in candidates:
        if fs.kind not in pools:
            pools[fs.kind] = Cells.whole(*sets[fs.kind])
        search(fs, pools[fs.kind])
    if not found:   # an enlarged box: cells may still fit, cut from the cheapest-looking candidate
        progress(f"  {name}: no whole polynomial of at most {MAX_COST} multipliers reaches the budget; "
                 f"trying cells of {candidates[0].label()}")
    ports = {i.name: i for i in ctx.inputs}
    memo: dict = {}
    bases = _cut_bases(found[-1][1].features if found else candidates[0], candidates)
    for base in bases:
        for var, nm in enumerate(base.names):
            if nm not in ports or base.allowed[var] == "none":
                continue
            for cells in CUT_CELLS:
                fs = base.piecewise(var, ports[nm], cells)
                if fs.cut.cells > 1:
                    search(fs, Cells.cut(fs, ports, *sets[base.kind], raw, memo))
    grid = _Grids(ctx, name, sets[bases[0].kind], raw, ports, budget_ticks, progress)
    for fs in _grid_sets(bases[0], ports):
        grid.search(fs, found)
    entries = ctx.robot.fit.table_entries
    if entries >= FEATURE_GRID_ENTRIES:
        for base in _feature_bases(bases[0], candidates, ports):
            grid = _Grids(ctx, name, sets[base.kind], raw, ports, budget_ticks, progress)
            for fs in _feature_grid_sets(base, ports, entries):
                grid.search(fs, found)
    if not found:
        raise FitError(f"servo {name}: no polynomial of at most {MAX_COST} multipliers (total degree <= "
                       f"{MAX_DEGREE}, whole or in cells) reaches the approximation budget of {budget_ticks:g} ticks")
    pools.clear()
    ranked = _ranked(ctx, found[::-1], progress)
    finalists = [e for price, e in ranked[:FINALISTS] if price <= ranked[0][0] + FINALIST_MARGIN]
    pruned = [_settle_and_prune(ctx, entry, budget_ticks, progress) for entry in finalists]
    return _ranked(ctx, pruned, progress)[0][1][1]


def _ranked(ctx, entries: list, progress) -> list:
    """``[(price, entry)]`` of ``entries`` (cost, ServoFit, ...), the cheapest first (on a tie,
    in their order). The price is the cost, or with a cost model that prices coefficient values
    (:attr:`~.cost.CostModel.prices_values`) the price with the entry's fitted coefficients
    (:func:`~.formats.fitted_cost`): the search priced structures on stand-in coefficients,
    whose widths are not the fitted ones (with exact products, cylinder-leg s2 on the ECP5
    model: 2 x 3 cells in r x theta 64.7 against 3 cells in z 70.0 on stand-ins, 88.8 against
    76.0 fitted). No format chosen, no plan built for a model that counts operations."""
    if not ctx.cost_model.prices_values or len(entries) < 2:
        return sorted(((e[0], e) for e in entries), key=lambda p: p[0])
    out = []
    for entry in entries:
        sf = entry[1]
        price = fitted_cost(ctx, sf)
        why = "" if price < float("inf") else " (no format meets the quantization budget, or not at the rate)"
        progress(f"  {sf.name}: {sf.features.label()}, {len(sf.poly)} terms, with its fitted coefficients "
                 f"{ctx.cost_model.label(price)}{why}")
        out.append((price, entry))
    return sorted(out, key=lambda p: p[0])


def _affordable(ctx, fs, terms, name: str, found: list) -> float | None:
    """The cost of structure ``fs`` with ``terms`` for servo ``name`` if it is to be tried: at
    most ``MAX_COST`` multiplications (the effort bound, whatever the cost model) and cheaper
    than the best found so far; else None."""
    cost = structure_cost(ctx, fs, terms, name)
    if structure_multipliers(ctx, fs, terms, name) > MAX_COST or (found and cost >= found[-1][0]):
        return None
    return cost


class _Grids:
    """The search of one servo's grids (:class:`~.features.CutGrid`) over one variable kind's
    samples ``sets`` = (fit set, check set)."""

    def __init__(self, ctx, name, sets, raw, ports, budget_ticks, progress):
        self.ctx, self.name, self.sets, self.raw, self.ports = ctx, name, sets, raw, ports
        self.budget, self.progress = budget_ticks, progress
        self.memo, self.screen_memo = {}, {}
        k = SCREEN_STRIDE
        self.screen_sets = ((sets[0][0][::k], sets[0][1][::k]), (sets[1][0][:0], sets[1][1][:0]))
        self.screen_raw = {p: (v[0][::k], v[1][:0]) for p, v in raw.items()}

    def search(self, fs: FeatureSet, found: list) -> None:
        """Append to ``found`` the fit of ``fs`` at the lowest degree meeting the budget that
        costs less than ``found[-1]``, if any. The term sets rise with the degree, each holding
        the last, so a refusal at the costliest affordable degree refuses every lower one (a
        minimax refusal is a lower bound): that degree is tried first, on every ``SCREEN_STRIDE``-th
        fit sample alone (a subset of the pool, so a refusal there is one on the pool), then
        downwards on the pool until refused."""
        degrees = []
        for deg in range(1, MAX_DEGREE + 1):
            cost = _affordable(self.ctx, fs, fs.terms(deg), self.name, found)
            if cost is None:
                break
            degrees.append((deg, cost))
        if not degrees:
            return
        screen = Cells.cut(fs, self.ports, *self.screen_sets, self.screen_raw, self.screen_memo)
        if not self._fits(fs, screen, *degrees[-1], "screen samples"):
            return
        data, best = Cells.cut(fs, self.ports, *self.sets, self.raw, self.memo), None
        for deg, cost in degrees[::-1]:
            fit = self._fits(fs, data, deg, cost)
            if not fit:
                break
            best = (cost, ServoFit(self.name, fs, deg, data.poly(fs.terms(deg), fit.coef), fit.error), fit.states, data)
        if best is not None:
            found.append(best)

    def _fits(self, fs, data, deg, cost, note="") -> CellsFit | None:
        terms = fs.terms(deg)
        fit = data.fit_terms(terms, self.budget, settle=False)
        self.progress(f"  {self.name}: {fs.label()}, {'degree per variable' if fs.tensor else 'degree'} {deg}, "
                      f"{len(terms)} terms, {self.ctx.cost_model.label(cost)}{', ' + note if note else ''}, "
                      f"{_fit_note(fit)}")
        return None if fit.refused or fit.error > self.budget else fit


def _grid_sets(base: FeatureSet, ports: dict) -> list:
    """The grids tried for ``base``: every pair of input ports (a variable of ``base``, made the
    offset in its cell, or a port that is no variable), ``GRID_CELLS`` cells each, at most
    ``MAX_GRID_CELLS`` table entries (so cells) in all."""
    var = {nm: (base.names.index(nm) if nm in base.names else None) for nm in ports}
    use = [nm for nm in ports if var[nm] is None or base.allowed[var[nm]] != "none"]
    out = []
    for pa, pb in itertools.combinations(use, 2):
        for ca, cb in itertools.product(GRID_CELLS, repeat=2):
            fs = base.piecewise(var[pa], ports[pa], ca, (var[pb], ports[pb], cb))
            if fs.cut.a.cells > 1 and fs.cut.b.cells > 1 and fs.cut.entries <= MAX_GRID_CELLS:
                out.append(fs)
    return out


def _feature_bases(fs: FeatureSet, candidates, ports: dict) -> list:
    """The variable sets tried with feature cells: ``fs`` and every candidate of total degree
    terms, those with a variable that is no input port (a computed feature) only."""
    out = []
    for c in [fs, *candidates]:
        c = dataclasses.replace(c, tensor=False, cut=None)
        if c not in out and any(nm not in ports and a != "none" for nm, a in zip(c.names, c.allowed)):
            out.append(c)
    return out


def _feature_grid_sets(base: FeatureSet, ports: dict, entries: int) -> list:
    """The feature grids tried for ``base`` with at most ``entries`` table entries: each
    computed variable (no input port) cut into cells of each of ``FEATURE_BITS`` alone, and on a
    grid with each other variable (a port in as many cells, or another feature), the most
    cells first (the lowest degree)."""
    live = [j for j, a in enumerate(base.allowed) if a != "none"]
    feats = [j for j in live if base.names[j] not in ports]
    out = []
    for j in feats:
        bits = [b for b in range(FEATURE_BITS[0], FEATURE_BITS[1] + 1) if 2 ** (b + 1) <= entries]
        out += [base.feature_piecewise(j, b) for b in bits]
        for k in live:
            if k == j or (k in feats and k < j):
                continue
            for b, b2 in itertools.product(bits, repeat=2):
                if base.names[k] in ports:
                    fs = base.feature_piecewise(j, b, (k, ports[base.names[k]], 2 ** (b2 + 1)))
                else:
                    fs = base.feature_piecewise(j, b, (k, b2))
                if fs.cut.entries <= entries:
                    out.append(fs)
    return sorted(out, key=lambda fs: -fs.cut.cells)


def _cut_bases(fs: FeatureSet, candidates) -> list:
    """The variable sets tried piecewise: ``fs`` and its twin with the other term set."""
    twins = [c for c in candidates if c.tensor != fs.tensor and dataclasses.replace(c, tensor=fs.tensor) == fs]
    return [fs, *twins[:1]]


def _settle_and_prune(ctx, entry, budget_ticks, progress) -> tuple:
    """(cost, ServoFit) of a structure the search found (cost, fit, states, Cells) once its
    coefficients are optimal (the search only needed to know it fits) and it is pruned."""
    cost, sf, state, data = entry
    if not all(st.optimal for st in state):
        terms = list(sf.poly)
        fit = data.fit_terms(terms, budget_ticks, warm=state)
        sf, state = dataclasses.replace(sf, poly=data.poly(terms, fit.coef), fit_error_ticks=fit.error), fit.states
    return prune(ctx, sf, cost, data, state, budget_ticks, progress)


def prune(ctx, sf: ServoFit, cost: int, data: Cells, state, budget_ticks, progress) -> tuple:
    """Drop terms while the refitted polynomial still meets the budget.

    Only removals that save a multiplier are tried (in a nested Horner scheme most
    inner coefficients cost an add, not a multiply), least important first
    (|coefficient| x largest |monomial| over the pool, the largest over the cells); stops
    after ``PRUNE_REJECTS`` refused removals in a row. Each trial's minimax fit starts from the
    current fit's active rows. Returns the cost and the fit, which carries its fit data
    (``refit``) for the coefficient refit after quantization.
    """
    terms = list(sf.poly)
    coef = data.coef(sf.poly, terms)
    rejected: set = set()
    misses = 0
    while misses < PRUNE_REJECTS:
        scale = np.max([[rows.basis.magnitude(t) for t in terms] for rows in data.rows], axis=0)
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
        fit = data.fit_terms(rest, budget_ticks, warm=state, settle=False)
        if not fit.refused and fit.error <= budget_ticks:
            terms, coef, cost, misses, state = rest, fit.coef, c2, 0, fit.states
            sf = ServoFit(sf.name, sf.features, sf.degree, data.poly(terms, fit.coef), fit.error)
        else:
            rejected.add(t)
            misses += 1
    if not all(st.optimal for st in state):     # the trials only needed to know they fit
        fit = data.fit_terms(terms, budget_ticks, warm=state)
        sf, state = dataclasses.replace(sf, poly=data.poly(terms, fit.coef), fit_error_ticks=fit.error), fit.states
    progress(f"  {sf.name}: pruned to {len(terms)} terms, {ctx.cost_model.label(cost)}, "
             f"max fit error {sf.fit_error_ticks:.4g} ticks")
    data.forget_columns()
    return cost, dataclasses.replace(sf, refit=(data, state, budget_ticks))
