"""Fit every servo of a robot and lower the result to an evaluation plan.

Pipeline: sample the workspace -> reference pulses (ticks) -> per servo, detect
unused variables and the theta symmetry, pick the lowest total degree whose
near-minimax fit meets the approximation budget -> choose the narrowest
fixed-point formats whose *certified* rounding bound meets the quantization
budget -> plan.

Error budget (pu): ``tolerance = approximation + quantization + output rounding
+ margin``, output rounding being half a PWM tick, quantization 10 % of the tolerance (more
when products must fit the DSP blocks, see :func:`fit_robot`).
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field

import numpy as np

from ..constraints.devices import FAMILIES
from ..kinematics import UnreachableError
from .certify import CertificationError, certify
from .features import Cut, Normaliser, coordinate_stage
from .horner import estrin, lower_poly
from .plan import Plan, PlanBuilder, PlanInput, PlanOutput, bits_for, quantize
from .polyfit import fit_least_squares, lawson, total_degree_terms, vander

__all__ = ["FitError", "ServoFit", "FeatureSet", "fit_robot", "plan_inputs", "workspace_samples",
           "output_multipliers", "operand_bits"]

MAX_DEGREE = 12
CERTIFY_ATTEMPTS = 3   # fits (the first + refits with tighter budgets) before refusing
PRUNE_REJECTS = 3
FIT_SEED = 20261124
FIT_SAMPLES = (30000, 3000)      # random interior points, points per face
CHECK_SAMPLES = (100000, 10000)  # + points per edge / 4
MIX_EXTRA_MULTIPLIERS = 2       # fit.lowering = "mixed": extra multiplications allowed per servo
CUT_CELLS = (4, 8, 16)           # cell counts tried for a piecewise plan (tables of <= 16 entries)
#: shares of the tolerance given to the certified rounding error, tried in turn: the first
#: always; the others when fit.products = "dsp" leaves no format within the smaller share
QUANTIZATION_SHARES = (0.10, 0.25, 0.40)


class FitError(RuntimeError):
    """No plan meets the robot's tolerance."""


class FormatError(FitError):
    """No fixed-point format keeps the rounding error within the quantization budget."""


def operand_bits(robot) -> tuple[int, int] | None:
    """The signed operand widths every plan multiplication must fit: those of the DSP block
    of ``hardware.dsp`` when ``fit.products = "dsp"``; else None (exact products)."""
    if getattr(robot, "products", "exact") != "dsp" or robot.dsp not in FAMILIES:
        return None
    return FAMILIES[robot.dsp].dsp


@dataclass
class ServoFit:
    name: str
    features: "FeatureSet"   # the variables and their allowed powers
    degree: int
    poly: dict               # {exponents: float coefficient} over the features (ticks)
    fit_error_ticks: float   # max error on the fit and check samples (float coefficients)
    frac: int = 0            # accumulator / coefficient fractional bits
    bound_pu: float = 0.0    # certified rounding bound
    # fit data for the refit after quantization: (_Cells, per cell working set + Lawson weights, budget)
    refit: tuple | None = field(default=None, repr=False, compare=False)

    def integers(self) -> dict:
        """{exponents: coefficient integer on the 2**-frac grid} (a tuple per cell if piecewise)."""
        q = lambda c: quantize(c, self.frac)  # noqa: E731
        return {e: tuple(map(q, c)) if isinstance(c, tuple) else q(c) for e, c in self.poly.items()}

    def coefficient_bits(self) -> int:
        """Widest coefficient integer (two's complement bits)."""
        ints = np.ravel(list(self.integers().values()))
        return max(bits_for(min(0, int(q)), max(0, int(q)))[0] for q in ints)


@dataclass
class Budget:
    tolerance: float
    rounding: float
    quantization: float
    approximation: float

    @classmethod
    def split(cls, tolerance: float, ticks_per_pu: float, quantization_share: float = 0.1) -> "Budget":
        rounding = 0.5 / ticks_per_pu
        quant = quantization_share * tolerance
        approx = tolerance - rounding - quant - 0.15 * tolerance
        if approx <= 0:
            raise FitError(f"tolerance {tolerance:g} pu leaves no approximation budget after "
                           f"output rounding ({rounding:g} pu); raise hardware.clock_hz or the tolerance")
        return cls(tolerance, rounding, quant, approx)


def plan_inputs(robot) -> list[PlanInput]:
    out = []
    for i in robot.inputs:
        w, signed = bits_for(i.lo, i.hi)
        out.append(PlanInput(i.name, i.unit, i.frac_bits, i.lo, i.hi, w, signed))
    return out


def workspace_samples(robot, n_random: int, n_face: int, seed: int, edges: bool = False
                      ) -> tuple[np.ndarray, ...]:
    """Random interior points, points on every face and (optionally) every edge of the
    workspace box (real values)."""
    rng = np.random.default_rng(seed)
    lo = np.array([i.min for i in robot.inputs])
    hi = np.array([i.max for i in robot.inputs])
    pts = [lo + (hi - lo) * rng.random((n_random, len(lo)))]
    for k in range(len(lo)):
        for v in (lo[k], hi[k]):
            f = lo + (hi - lo) * rng.random((n_face, len(lo)))
            f[:, k] = v
            pts.append(f)
    if edges:
        for k, l in itertools.combinations(range(len(lo)), 2):
            for vk in (lo[k], hi[k]):
                for vl in (lo[l], hi[l]):
                    f = lo + (hi - lo) * rng.random((n_face // 4, len(lo)))
                    f[:, k], f[:, l] = vk, vl
                    pts.append(f)
    corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(len(lo), -1).T
    pts.append(corners)
    p = np.concatenate(pts)
    return tuple(p[:, k] for k in range(len(lo)))


@dataclass(frozen=True)
class FeatureSet:
    """The variables one servo polynomial is fitted over.

    ``kind``: "radial" (normalised rho2 = x**2 + y**2, then the remaining frame
    coordinates), "cartesian" (normalised frame coordinates) or "direct" (normalised
    input ports, e.g. R, theta, Z as in the integer power series paper).
    ``allowed[k]``: any / even / odd / none powers of variable k. ``zero_free``: index of
    an odd variable whose zero-power terms vanish except the constant (the servo value
    on that variable's zero plane is constant), or None.
    """
    kind: str
    names: tuple
    allowed: tuple
    zero_free: int | None = None
    tensor: bool = False      # every power up to ``degree`` per variable, not total degree
    cut: "Cut | None" = None  # piecewise: variable ``cut.var`` is the offset in a cell of its port

    def label(self) -> str:
        return f"{self.kind} {'/'.join(self.names)}" + self.extras()

    def structure(self) -> str:
        """Kind, term set and cells, e.g. ``radial, 3 cells in z`` (for reports)."""
        return self.kind + self.extras().replace(" tensor", ", tensor terms")

    def piecewise_record(self) -> dict | None:
        """JSON-ready description of the cells (None if not piecewise)."""
        if self.cut is None:
            return None
        return {"input": self.cut.port, "variable": self.names[self.cut.var], "cells": self.cut.cells,
                "port_values_per_cell": 2 ** self.cut.shift}

    def extras(self) -> str:
        return (" tensor" if self.tensor else "") + (f", {self.cut.cells} cells in {self.cut.port}"
                                                      if self.cut else "")

    def piecewise(self, var: int, port, cells: int) -> "FeatureSet":
        """The same variables with variable ``var`` (the normalised input ``port``) replaced by
        the offset inside ``cells`` equal cells of the port's integer range: the offset has no
        symmetry, so its powers are "any"."""
        per = -(-(port.hi - port.lo + 1) // cells)          # port values per cell, rounded up
        shift = max(1, (per - 1).bit_length())
        allowed = self.allowed[:var] + ("any",) + self.allowed[var + 1:]
        zero_free = None if self.zero_free == var else self.zero_free
        return dataclasses.replace(self, allowed=allowed, zero_free=zero_free,
                                   cut=Cut(var, port.name, shift, ((port.hi - port.lo) >> shift) + 1))

    def terms(self, degree: int) -> list:
        if self.tensor:
            terms = [e for e in total_degree_terms(degree * len(self.allowed), list(self.allowed))
                     if max(e, default=0) <= degree]
        else:
            terms = total_degree_terms(degree, list(self.allowed))
        if self.zero_free is not None:
            k = self.zero_free
            terms = [e for e in terms if e[k] > 0 or sum(e) == 0]
        return terms


def _analyse(f, coords: list, norms, names, kind: str) -> FeatureSet:
    """Parity and dependence of ``f`` (pulses of one servo) in each coordinate, numerically.

    Parity is only usable for a coordinate normalised about 0: "even" if
    f(..., -c, ...) = f(..., c, ...), "odd" if f(c) + f(-c) = 2 f(0). A target
    that the reflection makes unreachable means "any".
    """
    p0 = f(*coords)
    eps = 1e-9 * max(1.0, float(np.ptp(p0)))
    allowed, zero_free = [], None
    for k, (c, nm) in enumerate(zip(coords, norms)):
        def at(v):
            cc = list(coords)
            cc[k] = v
            try:
                return f(*cc)
            except UnreachableError:
                return None
        lo, hi = at(np.full_like(c, c.min())), at(np.full_like(c, c.max()))
        if lo is not None and hi is not None and np.max(np.abs(lo - hi)) < eps \
                and np.max(np.abs(lo - p0)) < eps:
            allowed.append("none")
            continue
        par = "any"
        if nm.centre == 0:
            pm, pz = at(-c), at(0 * c)
            if pm is not None and np.max(np.abs(pm - p0)) < eps:
                par = "even"
            elif pm is not None and pz is not None and np.max(np.abs(p0 + pm - 2 * pz)) < eps:
                par = "odd"
                if zero_free is None and np.ptp(pz) < eps:
                    zero_free = k
        allowed.append(par)
    return FeatureSet(kind, tuple(names), tuple(allowed), zero_free)


def _feature_sets(robot, stage, k: int) -> list[FeatureSet]:
    """Candidate variable sets for servo ``k``, cheapest-looking first."""
    rng = np.random.default_rng(FIT_SEED + k)
    n = 2000
    pts = [i.min + (i.max - i.min) * rng.random(n) for i in robot.inputs]
    cal = robot.calibration
    fk = lambda *c: cal.pulses(stage.ik_frame(*c))[k]  # noqa: E731
    frame = list(stage.frame(*pts))
    cartesian = _analyse(fk, frame, stage.norms, stage.names, "cartesian")
    out = []
    if stage.has_plan_axes:
        rho = np.hypot(frame[0], frame[1])
        p0 = fk(*frame)
        try:
            radial = np.max(np.abs(fk(rho, 0 * rho, *frame[2:]) - p0)) < 1e-9 * max(1.0, float(np.ptp(p0)))
        except UnreachableError:
            radial = False
        if radial:
            out.append(FeatureSet("radial", ("rho2", *stage.names[2:]), ("any", *cartesian.allowed[2:])))
    out.append(cartesian)
    if stage.kind != "cartesian":
        fi = lambda *c: robot.pulses_pu(*c)[k]  # noqa: E731
        out.append(_analyse(fi, pts, _input_norms(robot), [i.name for i in robot.inputs], "direct"))
    # the same variables with tensor-product terms (a per-variable degree) where that differs
    out += [dataclasses.replace(fs, tensor=True) for fs in list(out)
            if sum(a != "none" for a in fs.allowed) > 1]
    return out


def _input_norms(robot) -> list:
    return [Normaliser.for_range(i.min, i.max, i.frac_bits) for i in robot.inputs]


def _features(robot, stage, kind: str, pts) -> np.ndarray:
    """Exact feature values (N, n) of ``kind`` at real input points."""
    if kind == "radial":
        return stage.exact_radial(*pts)
    if kind == "cartesian":
        return stage.exact(*pts)
    return np.stack([nm(v) for nm, v in zip(_input_norms(robot), pts)], 1)


class _Nodes:
    """Feature nodes of every kind on one builder, built on first use."""

    def __init__(self, robot, stage, b: PlanBuilder, fv: int, mixed: bool = False):
        self.robot, self.stage, self.b, self.fv, self.mixed = robot, stage, b, fv, mixed
        self._kinds: dict = {}

    def __getitem__(self, kind: str) -> list:
        if "cartesian" not in self._kinds:
            self._kinds["cartesian"] = self.stage.build(self.b, self.fv, self.fv + 4, self.mixed)
        if kind not in self._kinds:
            if kind == "radial":
                self._kinds[kind] = self.stage.build_radial(self.b, self.fv)
            else:
                self._kinds[kind] = [nm.build(self.b, self.b.input_nodes[i.name], self.fv)
                                     for nm, i in zip(_input_norms(self.robot), self.robot.inputs)]
        return self._kinds[kind]


def parity_variable(fs: FeatureSet) -> int | None:
    """The variable whose parity the lowering splits (the first even/odd one), or None."""
    return next((j for j, a in enumerate(fs.allowed) if a in ("even", "odd")), None)


def poly_inputs(b: PlanBuilder, fs: FeatureSet, feats: list[int], fv: int) -> tuple[list[int], object]:
    """The variable nodes of a servo polynomial over ``fs`` and its coefficient builder: for a
    piecewise polynomial the cut variable becomes the offset in the cell (exact, widened to the
    features' ``fv`` fractional bits so that its powers keep them) and the coefficients are
    looked up by cell (``b.lut``); else ``feats`` and None (constants)."""
    if fs.cut is None:
        return feats, None
    port = next(i for i in b.inputs if i.name == fs.cut.port)
    cell, off = fs.cut.build(b, port)
    off = b.align(off, max(fv, b.frac(off)))
    return feats[:fs.cut.var] + [off] + feats[fs.cut.var + 1:], lambda v, f: b.lut(cell, v, f)


def _servo_nodes(b: PlanBuilder, fs: FeatureSet, poly: dict, feats: list[int], fv: int, frac: int,
                 mixed: bool = False) -> int:
    """Lower one servo polynomial: nested Horner, or with ``mixed`` the Horner/Estrin mix of
    least pipeline depth using at most ``MIX_EXTRA_MULTIPLIERS`` more multiplications
    (:func:`ikseries.fit.horner.lower_poly`). For the first even/odd variable v,
    ``E(..., v**2, ...) + v * O(..., v**2, ...)``. A piecewise polynomial (``fs.cut``) takes
    the offset in the cell for the cut variable and looks its coefficients up by cell."""
    feats, coefficient = poly_inputs(b, fs, feats, fv)
    k = parity_variable(fs)
    if mixed:
        return lower_poly(b, poly, feats, frac, coefficient, parity=k, max_extra_muls=MIX_EXTRA_MULTIPLIERS)
    return estrin(b, poly, feats, frac, coefficient, split=None, parity=k)


def _build(robot, inputs, stage, fits: list[ServoFit], fv: int, mixed: bool | None = None) -> Plan:
    """The plan of ``fits``; ``mixed`` None: as ``robot.lowering`` says."""
    mixed = getattr(robot, "lowering", "mixed") == "mixed" if mixed is None else mixed
    b = PlanBuilder(inputs, operand_bits=operand_bits(robot))
    nodes = _Nodes(robot, stage, b, fv, mixed)
    lo, hi = robot.pulse_limits_ticks()
    outs = []
    for sf in fits:
        acc = _servo_nodes(b, sf.features, sf.poly, nodes[sf.features.kind], fv, sf.frac, mixed)
        out = b.clamp(b.round(acc, 0), lo, hi)
        outs.append(PlanOutput(sf.name, out, acc, "ticks", robot.ticks_per_pu))
    return b.build(outs)


def output_multipliers(plan: Plan) -> dict:
    """Multipliers each output needs, counting the shared coordinate stage in full."""
    return {o.name: sum(1 for i in plan.cone(o.node) if plan.nodes[i].op == "mul") for o in plan.outputs}


def _cost(robot, inputs, stage, fs: FeatureSet, terms: list) -> int:
    """Multipliers of the servo evaluation (coordinate stage included) for ``terms``,
    known before fitting: the structure alone decides it."""
    # distinct coefficients: equal ones would share Horner sub-expressions
    cells = fs.cut.cells if fs.cut else 0
    sf = ServoFit("cost", fs, 0, {e: (1.0 + k / 4096,) * cells if cells else 1.0 + k / 4096
                                  for k, e in enumerate(terms)}, 0.0, frac=16)
    plan = _build(robot, inputs, stage, [sf], 16, mixed=False)
    return output_multipliers(plan)["cost"]


def _fit_terms(terms, fit_set, check_set, budget_ticks, rounds: int = 4, warm=None, iterations: int = 30):
    """Lawson near-minimax on the fit set, then exchange rounds adding the worst check
    points. Returns (coefficients, max error over fit and check sets, state); ``state``
    (working rows and Lawson weights) warm-starts a fit of a subset of the terms."""
    cpts, ctarget = check_set
    ca = vander(cpts, terms)
    if warm is None:
        xp, xt, w = fit_set[0], fit_set[1], None
    else:
        xp, xt, w = warm
    for _ in range(rounds):
        c, err, w = lawson(vander(xp, terms), xt, iterations, w)
        cerr = np.abs(ca @ c - ctarget)
        err = max(err, float(cerr.max()))
        if err <= budget_ticks:
            break
        worst = np.argsort(cerr)[-500:]
        xp, xt = np.concatenate([xp, cpts[worst]]), np.concatenate([xt, ctarget[worst]])
        w = None if warm is None else np.concatenate([w, np.full(len(worst), w.max())])
    return c, err, (xp, xt, w)


@dataclass
class _Cells:
    """Fit and check sets of one servo polynomial, per cell of a piecewise fit (a single cell
    otherwise); each set is (features (N, n), target ticks)."""
    fit: list
    check: list

    @classmethod
    def whole(cls, fit_set, check_set) -> "_Cells":
        return cls([fit_set], [check_set])

    @classmethod
    def cut(cls, fs: FeatureSet, port, fit_set, check_set, raw) -> "_Cells":
        """Rows of each cell of ``fs.cut``, the cut variable replaced by the offset in the cell;
        ``raw`` = real values of the cut port at the fit and check rows."""
        out = cls([], [])
        for c in range(fs.cut.cells):
            for dst, (x, t), v in ((out.fit, fit_set, raw[0]), (out.check, check_set, raw[1])):
                sel, off = fs.cut.rows(port, v, c)
                xc = x[sel].copy()
                xc[:, fs.cut.var] = off
                dst.append((xc, t[sel]))
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
        for x, t in self.fit:
            a = vander(x, terms)
            err = max(err, float(np.max(np.abs(a @ fit_least_squares(a, t) - t))))
        return err

    def fit_terms(self, terms, budget_ticks, rounds: int = 4, warm=None, iterations: int = 30):
        """:func:`_fit_terms` in every cell: (coef (cells, terms), max error, states)."""
        coefs, err, states = [], 0.0, []
        for c, (fit_set, check_set) in enumerate(zip(self.fit, self.check)):
            cf, e, st = _fit_terms(terms, fit_set, check_set, budget_ticks, rounds,
                                   None if warm is None else warm[c], iterations)
            coefs.append(cf)
            err, states = max(err, e), states + [st]
        return np.array(coefs), err, states


def _fit_servo(robot, inputs, stage, name, candidates, sets, raw, budget_ticks, progress) -> ServoFit:
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
            cost = _cost(robot, inputs, stage, fs, terms)
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
        search(fs, _Cells.whole(*sets[fs.kind]))
    if best is None:
        raise FitError(f"servo {name}: no polynomial up to total degree {MAX_DEGREE} reaches the "
                       f"approximation budget of {budget_ticks:g} ticks")
    base = best[1].features
    ports = {i.name: i for i in inputs}
    for var, nm in enumerate(base.names):
        if nm not in ports or base.allowed[var] == "none":
            continue
        for cells in CUT_CELLS:
            fs = base.piecewise(var, ports[nm], cells)
            if fs.cut.cells > 1:
                search(fs, _Cells.cut(fs, ports[nm], *sets[base.kind], raw[nm]))
    cost, sf, state, data = best
    return _prune(robot, inputs, stage, sf, cost, data, state, budget_ticks, progress)


def _prune(robot, inputs, stage, sf: ServoFit, cost: int, data: _Cells, state, budget_ticks,
           progress) -> ServoFit:
    """Drop terms while the refitted polynomial still meets the budget.

    Only removals that save a multiplier are tried (in a nested Horner scheme most
    inner coefficients cost an add, not a multiply), least important first
    (|coefficient| x largest |monomial| on the check set, the largest over the cells); stops
    after ``PRUNE_REJECTS`` refused removals in a row. Each trial refit is warm-started from
    the current fit's working set and Lawson weights (one exchange round).
    """
    terms = list(sf.poly)
    coef = data.coef(sf.poly, terms)
    rejected: set = set()
    misses = 0
    while misses < PRUNE_REJECTS:
        scale = np.max([np.abs(vander(x, terms)).max(axis=0) for x, _ in data.check], axis=0)
        order = np.argsort(np.max(np.abs(coef), axis=0) * scale, kind="stable")
        pick = None
        for i in order:
            t = terms[i]
            if sum(t) == 0 or t in rejected:
                continue
            rest = terms[:i] + terms[i + 1:]
            c2 = _cost(robot, inputs, stage, sf.features, rest)
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
    sf.refit = (data, state, budget_ticks)
    return sf


def _round_and_refit(sf: ServoFit, frac: int):
    """Coefficients on the grid 2**-frac, rounded one at a time (highest degree first) while
    the rest are refitted (weighted least squares with the fit's final Lawson weights on its
    working set) to absorb each rounding; plain rounding instead if that is better on the
    check set (the refit is a heuristic for the maximum error). Piecewise: in every cell.
    Returns (poly, max error on the check set) or None without fit data."""
    if sf.refit is None:
        return None
    data, states, _ = sf.refit
    terms = sorted(sf.poly, key=lambda e: (-sum(e), e))
    grid = 2.0 ** frac
    coefs, worst = [], 0.0
    for orig, (xp, xt, w), (cpts, ctarget) in zip(data.coef(sf.poly, terms), states, data.check):
        a = vander(xp, terms)
        coef = orig.copy()
        fixed = np.zeros(len(terms), dtype=bool)
        for k in range(len(terms)):
            coef[k] = np.round(coef[k] * grid) / grid
            fixed[k] = True
            free = ~fixed
            if free.any():
                rhs = xt - a[:, fixed] @ coef[fixed]
                coef[free] = fit_least_squares(a[:, free], rhs, w)
        ca = vander(cpts, terms)
        err = float(np.max(np.abs(ca @ coef - ctarget)))
        naive = np.round(orig * grid) / grid
        naive_err = float(np.max(np.abs(ca @ naive - ctarget)))
        if naive_err < err:          # the refit is a heuristic: never worse than plain rounding
            coef, err = naive, naive_err
        coefs.append(coef)
        worst = max(worst, err)
    return data.poly(terms, np.array(coefs)), worst


def _requantize(robot, inputs, stage, fits, fv, budget: Budget, progress) -> None:
    """Re-optimise each servo's coefficients after quantization, then take the narrowest
    accumulator format whose certified rounding bound still meets the quantization budget
    and whose refitted polynomial still meets the approximation budget on the check set."""
    tpp = robot.ticks_per_pu
    for sf in fits:
        best = None
        for frac in range(sf.frac, max(-1, sf.frac - 4), -1):
            r = _round_and_refit(sf, frac)
            if r is None or r[1] > sf.refit[2]:
                break
            trial = ServoFit(sf.name, sf.features, sf.degree, r[0], r[1], frac=frac)
            try:
                plan = _build(robot, inputs, stage, [trial], fv)
            except OverflowError:
                break
            if plan.rounding_bounds()[plan.outputs[0].preround] / tpp > budget.quantization:
                break
            best = trial
        if best is not None:
            progress(f"  {sf.name}: coefficients re-optimised on the 2^-{best.frac} grid "
                     f"(was 2^-{sf.frac}), max fit error {best.fit_error_ticks:.4g} ticks")
            sf.poly, sf.fit_error_ticks, sf.frac = best.poly, best.fit_error_ticks, best.frac


def _choose_formats(robot, inputs, stage, fits, budget: Budget, progress) -> int:
    """Narrowest feature precision ``fv`` and per-servo accumulator precision meeting the
    certified quantization budget. Sets ``ServoFit.frac``; returns ``fv``."""
    tpp = robot.ticks_per_pu

    def bound(sf, fv, frac):
        sf.frac = frac
        try:
            plan = _build(robot, inputs, stage, [sf], fv)
        except OverflowError:
            return np.inf
        return plan.rounding_bounds()[plan.outputs[0].preround] / tpp

    for fv in range(8, 40):
        fracs = []
        for sf in fits:
            lo, hi = 0, 24
            if bound(sf, fv, hi) > budget.quantization:
                break
            while lo < hi:           # the bound falls as frac grows: bisect
                mid = (lo + hi) // 2
                if bound(sf, fv, mid) <= budget.quantization:
                    hi = mid
                else:
                    lo = mid + 1
            fracs.append(lo)
        if len(fracs) == len(fits):
            for sf, fr in zip(fits, fracs):
                sf.frac = fr
            progress(f"  formats: features {fv} fractional bits, accumulators "
                     + ", ".join(f"{sf.name} {sf.frac}" for sf in fits))
            return fv
    raise FormatError(f"no fixed-point format keeps the certified rounding error within "
                   f"{budget.quantization:g} pu in 63-bit intermediates")


def _lower(robot, inputs, stage, fits, budget, progress) -> Plan:
    """Choose the formats and build the plan of every servo, with its meta data."""
    tpp = robot.ticks_per_pu
    fv = _choose_formats(robot, inputs, stage, fits, budget, progress)
    _requantize(robot, inputs, stage, fits, fv, budget, progress)
    plan = _build(robot, inputs, stage, fits, fv)
    bounds = plan.rounding_bounds()
    for sf, o in zip(fits, plan.outputs):
        sf.bound_pu = bounds[o.preround] / tpp
    mults = output_multipliers(plan)
    plan.meta = {
        "robot": robot.name,
        "budget_pu": vars(budget),
        "method": {"fit": "Lawson near-minimax + exchange on a check set; per servo the variable set "
                          "and total degree with the fewest multipliers, then pruned",
                   "lowering": getattr(robot, "lowering", "mixed"),
                   "operand_bits": list(operand_bits(robot)) if operand_bits(robot) else None,
                   "seed": FIT_SEED, "fit_samples": FIT_SAMPLES, "check_samples": CHECK_SAMPLES,
                   "max_degree": MAX_DEGREE},
        "features": {**stage.meta(), "frac_bits": fv},
        "servos": [{"name": sf.name, "variables": sf.features.kind, "names": list(sf.features.names),
                    "term_set": "tensor" if sf.features.tensor else "total degree",
                    "powers": dict(zip(sf.features.names, sf.features.allowed)), "total_degree": sf.degree,
                    "terms": len(sf.poly), "multipliers": mults[sf.name], "accumulator_frac_bits": sf.frac,
                    "piecewise": sf.features.piecewise_record(),
                    "fit_error_pu": sf.fit_error_ticks / tpp, "certified_rounding_pu": sf.bound_pu,
                    "coefficients": [{"exponents": list(e), "value": c} for e, c in sf.poly.items()]}
                   for sf in fits],
    }
    return plan


def fit_robot(robot, progress=lambda msg: None, *, certified: bool = True) -> tuple[Plan, list[ServoFit]]:
    """Fit every servo of ``robot`` and return the evaluation plan and the fits.

    With ``certified`` (the default) the error over the continuous workspace box is then
    bounded rigorously (:func:`ikseries.fit.certify.certify`) and stored in
    ``plan.meta["certificate"]``. A servo whose certified total exceeds the tolerance is
    refitted with a 15 % tighter approximation budget; after ``CERTIFY_ATTEMPTS`` fits the
    plan is refused (:class:`FitError`).

    With ``fit.products = "dsp"`` every multiplication's operands fit one DSP block of
    ``hardware.dsp`` (:func:`operand_bits`; narrowed by the plan builder). The extra rounding
    may not fit the usual 10 % of the tolerance; then the whole fit is redone with the next
    of ``QUANTIZATION_SHARES`` (the approximation budget shrinks by as much).
    """
    bits = operand_bits(robot)
    if bits is None:
        return _fit_robot(robot, progress, certified, QUANTIZATION_SHARES[0])
    for share, bigger in zip(QUANTIZATION_SHARES, QUANTIZATION_SHARES[1:] + (None,)):
        try:
            return _fit_robot(robot, progress, certified, share)
        except FormatError as e:
            if bigger is None:
                raise FormatError(f"{e} ({share:.0%} of the tolerance) with every product fitting "
                                  f"{bits[0]} x {bits[1]} DSP operands (fit.products = \"dsp\", hardware.dsp = "
                                  f"{robot.dsp!r}); use fit.products = \"exact\", a wider DSP or a looser "
                                  f"tolerance") from None
            progress(f"{e} with products fitting {bits} DSP operands: refitting with "
                     f"{bigger:.0%} of the tolerance for rounding")
    raise AssertionError("unreachable")


def _fit_robot(robot, progress, certified: bool, quantization_share: float) -> tuple[Plan, list[ServoFit]]:
    tpp = robot.ticks_per_pu
    budget = Budget.split(robot.tolerance_pu, tpp, quantization_share)
    inputs = plan_inputs(robot)
    # cos/sin error e moves the tip by up to R_max * e; keep that to ~1 % of the budget
    rmax = max(abs(robot.inputs[0].min), abs(robot.inputs[0].max))
    stage = coordinate_stage(robot, trig_tol=min(1e-4, 2e-5 * 40.0 / max(rmax, 1e-9)),
                             table=getattr(robot, "lowering", "mixed") == "mixed")
    progress(stage.describe())
    fit_pts = workspace_samples(robot, *FIT_SAMPLES, FIT_SEED)
    check_pts = workspace_samples(robot, *CHECK_SAMPLES, FIT_SEED + 1, edges=True)
    targets = [robot.pulses_pu(*p) for p in (fit_pts, check_pts)]
    raw = {i.name: (fit_pts[k], check_pts[k]) for k, i in enumerate(robot.inputs)}
    feats: dict = {}
    approx = [budget.approximation * tpp] * len(robot.servos)
    fits: list = [None] * len(robot.servos)
    for _ in range(CERTIFY_ATTEMPTS):
        for k, name in enumerate(robot.servos):
            if fits[k] is not None:
                continue
            candidates = _feature_sets(robot, stage, k)
            for fs in candidates:
                if fs.kind not in feats:
                    feats[fs.kind] = [_features(robot, stage, fs.kind, p) for p in (fit_pts, check_pts)]
            sets = {fs.kind: tuple((f, t[k] * tpp) for f, t in zip(feats[fs.kind], targets))
                    for fs in candidates}
            progress(f"fitting {name}: candidates " + "; ".join(
                f"{fs.label()} ({', '.join(f'{v} {a}' for v, a in zip(fs.names, fs.allowed))})"
                for fs in candidates))
            fits[k] = _fit_servo(robot, inputs, stage, name, candidates, sets, raw, approx[k], progress)
        plan = _lower(robot, inputs, stage, fits, budget, progress)
        if not certified:
            return plan, fits
        progress("certifying the error bound over the continuous workspace")
        cert = certify(robot, plan)
        for line in cert.lines():
            progress("  " + line)
        rec = cert.to_json()    # without run times: the plan must be byte-identical on a rerun
        for c in rec["servos"]:
            c.pop("seconds", None)
        plan.meta["certificate"] = rec
        failed = [k for k, c in enumerate(cert.servos)
                  if not (c.converged and c.total_pu <= robot.tolerance_pu)]
        if not failed:
            return plan, fits
        for k in failed:
            approx[k] *= 0.85
            fits[k] = None
        progress(f"certified bound above the tolerance for {', '.join(robot.servos[k] for k in failed)}: "
                 "refitting with a 15 % tighter approximation budget")
    try:
        cert.check(robot.tolerance_pu)
    except CertificationError as e:
        raise FitError(f"fit refused: {e}") from None
    raise FitError("fit refused: certification failed")  # check() raises whenever a servo failed
