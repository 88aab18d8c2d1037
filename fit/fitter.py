"""Fit every servo of a robot and lower the result to an evaluation plan.

Pipeline: sample the workspace -> reference pulses (ticks) -> per servo, detect
unused variables and the theta symmetry, pick the lowest total degree whose
near-minimax fit meets the approximation budget -> choose the narrowest
fixed-point formats whose *certified* rounding bound meets the quantization
budget -> plan.

Error budget (pu): ``tolerance = approximation + quantization + output rounding
+ margin``, output rounding being half a PWM tick.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field

import numpy as np

from ..kinematics import UnreachableError
from .certify import CertificationError, certify
from .features import Normaliser, coordinate_stage
from .horner import horner, parity_split
from .plan import Plan, PlanBuilder, PlanInput, PlanOutput, bits_for
from .polyfit import fit_least_squares, lawson, total_degree_terms, vander

__all__ = ["FitError", "ServoFit", "FeatureSet", "fit_robot", "plan_inputs", "workspace_samples",
           "output_multipliers"]

MAX_DEGREE = 12
CERTIFY_ATTEMPTS = 3   # fits (the first + refits with tighter budgets) before refusing
PRUNE_REJECTS = 3
FIT_SEED = 20261124
FIT_SAMPLES = (30000, 3000)      # random interior points, points per face
CHECK_SAMPLES = (100000, 10000)  # + points per edge / 4


class FitError(RuntimeError):
    """No plan meets the robot's tolerance."""


@dataclass
class ServoFit:
    name: str
    features: "FeatureSet"   # the variables and their allowed powers
    degree: int
    poly: dict               # {exponents: float coefficient} over the features (ticks)
    fit_error_ticks: float   # max error on the fit and check samples (float coefficients)
    frac: int = 0            # accumulator / coefficient fractional bits
    bound_pu: float = 0.0    # certified rounding bound
    # fit data for the refit after quantization: (check set, working set + Lawson weights, budget)
    refit: tuple | None = field(default=None, repr=False, compare=False)


@dataclass
class Budget:
    tolerance: float
    rounding: float
    quantization: float
    approximation: float

    @classmethod
    def split(cls, tolerance: float, ticks_per_pu: float) -> "Budget":
        rounding = 0.5 / ticks_per_pu
        quant = 0.1 * tolerance
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

    def label(self) -> str:
        return f"{self.kind} {'/'.join(self.names)}" + (" tensor" if self.tensor else "")

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

    def __init__(self, robot, stage, b: PlanBuilder, fv: int):
        self.robot, self.stage, self.b, self.fv = robot, stage, b, fv
        self._kinds: dict = {}

    def __getitem__(self, kind: str) -> list:
        if "cartesian" not in self._kinds:
            self._kinds["cartesian"] = self.stage.build(self.b, self.fv, self.fv + 4)
        if kind not in self._kinds:
            if kind == "radial":
                self._kinds[kind] = self.stage.build_radial(self.b, self.fv)
            else:
                self._kinds[kind] = [nm.build(self.b, self.b.input_nodes[i.name], self.fv)
                                     for nm, i in zip(_input_norms(self.robot), self.robot.inputs)]
        return self._kinds[kind]


def _servo_nodes(b: PlanBuilder, fs: FeatureSet, poly: dict, feats: list[int], fv: int, frac: int) -> int:
    """Lower one servo polynomial by nested Horner; for the first even/odd variable v,
    ``E(..., v**2, ...) + v * O(..., v**2, ...)``."""
    k = next((j for j, a in enumerate(fs.allowed) if a in ("even", "odd")), None)
    if k is None:
        return horner(b, poly, feats, frac)
    v2 = b.mul(feats[k], feats[k], fv)
    even, odd = parity_split(poly, k)
    vars_ = feats[:k] + [v2] + feats[k + 1:]
    acc = horner(b, even, vars_, frac) if even else None
    if odd:
        o = b.mul(feats[k], horner(b, odd, vars_, frac), frac)
        acc = o if acc is None else b.add(acc, o)
    return acc


def _build(robot, inputs, stage, fits: list[ServoFit], fv: int) -> Plan:
    b = PlanBuilder(inputs)
    nodes = _Nodes(robot, stage, b, fv)
    lo, hi = robot.pulse_limits_ticks()
    outs = []
    for sf in fits:
        acc = _servo_nodes(b, sf.features, sf.poly, nodes[sf.features.kind], fv, sf.frac)
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
    sf = ServoFit("cost", fs, 0, {e: 1.0 + k / 4096 for k, e in enumerate(terms)}, 0.0, frac=16)
    plan = _build(robot, inputs, stage, [sf], 16)
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


def _fit_servo(robot, inputs, stage, name, candidates, sets, budget_ticks, progress) -> ServoFit:
    """The cheapest (fewest multipliers) polynomial over any candidate variable set whose
    near-minimax fit meets ``budget_ticks`` on the check set, then pruned.

    ``sets[kind]`` = (fit set, check set), each (features, target ticks). Per candidate the
    total degree rises until the fit meets the budget or the structure already costs
    more than the best plan found.
    """
    best = None
    for fs in candidates:
        fit_set, check_set = sets[fs.kind]
        for deg in range(1, MAX_DEGREE + 1):
            terms = fs.terms(deg)
            cost = _cost(robot, inputs, stage, fs, terms)
            if best is not None and cost >= best[0]:
                break
            a = vander(fit_set[0], terms)
            err = float(np.max(np.abs(a @ fit_least_squares(a, fit_set[1]) - fit_set[1])))
            if err > 8 * budget_ticks:
                continue
            c, err, state = _fit_terms(terms, fit_set, check_set, budget_ticks)
            progress(f"  {name}: {fs.label()}, {'degree per variable' if fs.tensor else 'degree'} {deg}, "
                     f"{len(terms)} terms, "
                     f"{cost} multipliers, max fit error {err:.4g} ticks")
            if err <= budget_ticks:
                best = (cost, ServoFit(name, fs, deg, dict(zip(terms, (float(v) for v in c))), err), state)
                break
    if best is None:
        raise FitError(f"servo {name}: no polynomial up to total degree {MAX_DEGREE} reaches the "
                       f"approximation budget of {budget_ticks:g} ticks")
    cost, sf, state = best
    return _prune(robot, inputs, stage, sf, cost, sets[sf.features.kind], state, budget_ticks, progress)


def _prune(robot, inputs, stage, sf: ServoFit, cost: int, data, state, budget_ticks, progress) -> ServoFit:
    """Drop terms while the refitted polynomial still meets the budget.

    Only removals that save a multiplier are tried (in a nested Horner scheme most
    inner coefficients cost an add, not a multiply), least important first
    (|coefficient| x largest |monomial| on the check set); stops after
    ``PRUNE_REJECTS`` refused removals in a row. Each trial refit is warm-started from
    the current fit's working set and Lawson weights (one exchange round).
    """
    fit_set, check_set = data
    terms = list(sf.poly)
    coef = np.array([sf.poly[e] for e in terms])
    rejected: set = set()
    misses = 0
    while misses < PRUNE_REJECTS:
        scale = np.abs(vander(check_set[0], terms)).max(axis=0)
        order = np.argsort(np.abs(coef) * scale, kind="stable")
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
        c, err, st = _fit_terms(rest, fit_set, check_set, budget_ticks, rounds=1, warm=state, iterations=12)
        if err <= budget_ticks:
            terms, coef, cost, misses, state = rest, c, c2, 0, st
            sf = ServoFit(sf.name, sf.features, sf.degree, dict(zip(terms, (float(v) for v in c))), err)
        else:
            rejected.add(t)
            misses += 1
    progress(f"  {sf.name}: pruned to {len(terms)} terms, {cost} multipliers, "
             f"max fit error {sf.fit_error_ticks:.4g} ticks")
    sf.refit = (check_set, state, budget_ticks)
    return sf


def _round_and_refit(sf: ServoFit, frac: int):
    """Coefficients on the grid 2**-frac, rounded one at a time (highest degree first) while
    the rest are refitted (weighted least squares with the fit's final Lawson weights on its
    working set) to absorb each rounding; plain rounding instead if that is better on the
    check set (the refit is a heuristic for the maximum error). Returns (poly, max error on
    the check set) or None without fit data."""
    if sf.refit is None:
        return None
    (cpts, ctarget), (xp, xt, w), _ = sf.refit
    terms = sorted(sf.poly, key=lambda e: (-sum(e), e))
    a = vander(xp, terms)
    coef = np.array([sf.poly[e] for e in terms])
    fixed = np.zeros(len(terms), dtype=bool)
    grid = 2.0 ** frac
    for k in range(len(terms)):
        coef[k] = np.round(coef[k] * grid) / grid
        fixed[k] = True
        free = ~fixed
        if free.any():
            rhs = xt - a[:, fixed] @ coef[fixed]
            coef[free] = fit_least_squares(a[:, free], rhs, w)
    ca = vander(cpts, terms)
    err = float(np.max(np.abs(ca @ coef - ctarget)))
    naive = np.array([np.round(sf.poly[e] * grid) / grid for e in terms])
    naive_err = float(np.max(np.abs(ca @ naive - ctarget)))
    if naive_err < err:          # the refit is a heuristic: never worse than plain rounding
        coef, err = naive, naive_err
    return {e: float(c) for e, c in zip(terms, coef)}, err


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
    raise FitError(f"no fixed-point format keeps the certified rounding error within "
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
                   "seed": FIT_SEED, "fit_samples": FIT_SAMPLES, "check_samples": CHECK_SAMPLES,
                   "max_degree": MAX_DEGREE},
        "features": {**stage.meta(), "frac_bits": fv},
        "servos": [{"name": sf.name, "variables": sf.features.kind, "names": list(sf.features.names),
                    "term_set": "tensor" if sf.features.tensor else "total degree",
                    "powers": dict(zip(sf.features.names, sf.features.allowed)), "total_degree": sf.degree,
                    "terms": len(sf.poly), "multipliers": mults[sf.name], "accumulator_frac_bits": sf.frac,
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
    """
    tpp = robot.ticks_per_pu
    budget = Budget.split(robot.tolerance_pu, tpp)
    inputs = plan_inputs(robot)
    # cos/sin error e moves the tip by up to R_max * e; keep that to ~1 % of the budget
    rmax = max(abs(robot.inputs[0].min), abs(robot.inputs[0].max))
    stage = coordinate_stage(robot, trig_tol=min(1e-4, 2e-5 * 40.0 / max(rmax, 1e-9)))
    progress(stage.describe())
    fit_pts = workspace_samples(robot, *FIT_SAMPLES, FIT_SEED)
    check_pts = workspace_samples(robot, *CHECK_SAMPLES, FIT_SEED + 1, edges=True)
    targets = [robot.pulses_pu(*p) for p in (fit_pts, check_pts)]
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
            fits[k] = _fit_servo(robot, inputs, stage, name, candidates, sets, approx[k], progress)
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
