"""Fit every servo of a robot and lower the result to an evaluation plan.

Pipeline (one module per step, each a function of an explicit :class:`~.context.FitContext`
returning new immutable values): sample the workspace -> reference pulses (ticks) -> per servo,
the candidate variable sets and their symmetries (:mod:`.structure`) -> the cheapest polynomial
whose minimax fit meets the approximation budget (:mod:`.search`, :mod:`.minimax`) -> the narrowest
fixed-point formats whose *certified* rounding bound meets the quantization budget
(:mod:`.formats`) -> plan (:mod:`.lowering`) -> certified error over the continuous workspace
(:mod:`.certify`).

Error budget (pu): ``tolerance = approximation + quantization + output rounding
+ margin``, output rounding being half a PWM tick, quantization 10 % of the tolerance (more
when products must fit the DSP blocks, see :func:`fit_robot`).
"""
from __future__ import annotations

import dataclasses
import itertools
from typing import NamedTuple

import numpy as np

from .certify import CertificationError, UnboundedCellError, certify
from .context import Budget, FitContext, FitError, FormatError, operand_bits
from .cost import DEFAULT_COST_MODEL, CostModel
from .lowering import build_plan, output_multipliers
from .parallel import check_jobs, servo_map
from .plan import Plan
from .search import MAX_DEGREE, fit_servo
from .formats import choose_formats, requantize
from .structure import FIT_SEED, FeatureSet, ServoFit, feature_sets, feature_values

__all__ = ["FitError", "FormatError", "Budget", "FitResult", "ServoFit", "FeatureSet", "fit_robot",
           "workspace_samples", "output_multipliers", "operand_bits", "CERTIFY_ATTEMPTS", "QUANTIZATION_SHARES"]

CERTIFY_ATTEMPTS = 3   # fits (the first + refits with tighter budgets) before refusing
FIT_SAMPLES = (30000, 3000)      # random interior points, points per face
CHECK_SAMPLES = (100000, 10000)  # + points per edge / 4
#: on a refit, fit points added about each sampled counterexample of the certifier (a cell whose
#: centre errs by more than its target): this many random ones in a neighbourhood of each of
#: these widths (fractions of the workspace box per input)
MISS_POINTS = 32
MISS_SCALES = (1 / 256, 1 / 64, 1 / 16, 1 / 4)
#: the certifier's cell budget per servo is at least this many times its starting cells
CERTIFY_PER_START = 20
#: shares of the tolerance given to the certified rounding error, tried in turn: the first
#: always; the others when fit.products = "dsp" leaves no format within the smaller share
QUANTIZATION_SHARES = (0.10, 0.25, 0.40)


class FitResult(NamedTuple):
    """The evaluation plan of a robot and the fit of each servo it was lowered from."""
    plan: Plan
    servos: list


def workspace_samples(robot, n_random: int, n_face: int, seed: int, edges: bool = False
                      ) -> tuple[np.ndarray, ...]:
    """Random interior points, points on every face and (optionally) every edge of the
    workspace box (real values)."""
    rng = np.random.default_rng(seed)
    lo = np.array([i.min for i in robot.workspace.inputs])
    hi = np.array([i.max for i in robot.workspace.inputs])
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


class _Samples:
    """Fit and check points of one robot, their reference pulses and, per variable kind, their
    exact feature values (computed on first use); per servo, the points added to its fit set
    around the certifier's counterexamples (:meth:`add_misses`)."""

    def __init__(self, ctx: FitContext):
        robot = ctx.robot
        self.ctx = ctx
        self.points = (workspace_samples(robot, *FIT_SAMPLES, FIT_SEED),
                       workspace_samples(robot, *CHECK_SAMPLES, FIT_SEED + 1, edges=True))
        self.targets = [robot.pulses_pu(*p) for p in self.points]
        self._feats: dict = {}
        self.extra: dict = {}       # servo -> real points (one array per input) added to its fit set

    def raw(self, k: int) -> dict:
        """Per input port, its real values at servo ``k``'s fit and check rows."""
        fit = self._fit_points(k)
        return {i.name: (fit[j], self.points[1][j]) for j, i in enumerate(self.ctx.robot.workspace.inputs)}

    def _fit_points(self, k: int) -> tuple:
        if k not in self.extra:
            return self.points[0]
        return tuple(np.concatenate([a, b]) for a, b in zip(self.points[0], self.extra[k]))

    def sets(self, k: int, candidates) -> dict:
        """(fit set, check set) per variable kind of ``candidates`` for servo ``k``."""
        for fs in candidates:
            if fs.kind not in self._feats:
                self._feats[fs.kind] = [feature_values(self.ctx, fs.kind, p) for p in self.points]
        tpp = self.ctx.ticks_per_pu
        out = {}
        for fs in candidates:
            (f0, f1), (t0, t1) = self._feats[fs.kind], (t[k] for t in self.targets)
            if k in self.extra:
                f0 = np.concatenate([f0, feature_values(self.ctx, fs.kind, self.extra[k])])
                t0 = np.concatenate([t0, self.ctx.robot.pulses_pu(*self.extra[k])[k]])
            out[fs.kind] = ((f0, t0 * tpp), (f1, t1 * tpp))
        return out

    def add_misses(self, k: int, misses, seed: int) -> None:
        """Add to servo ``k``'s fit set ``MISS_POINTS`` random points about each counterexample
        cell (lo, hi, error) of the certifier at each of ``MISS_SCALES`` (its neighbourhood that
        fraction of the workspace box wide), within the box."""
        inputs = self.ctx.robot.workspace.inputs
        lo = np.array([i.min for i in inputs])
        hi = np.array([i.max for i in inputs])
        rng = np.random.default_rng(seed)
        pts = []
        for cell_lo, cell_hi, _ in misses:
            c = 0.5 * (np.array(cell_lo) + np.array(cell_hi))
            for scale in MISS_SCALES:
                u = rng.random((MISS_POINTS, len(lo))) - 0.5
                pts.append(np.clip(c + u * scale * (hi - lo), lo, hi))
        new = np.concatenate(pts)
        old = np.stack(self.extra[k], 1) if k in self.extra else new[:0]
        p = np.concatenate([old, new])
        self.extra[k] = tuple(p[:, j] for j in range(len(lo)))


def lower(ctx: FitContext, fits: list[ServoFit], progress) -> tuple[Plan, list[ServoFit]]:
    """Choose the formats and build the plan of every servo, with its meta data; returns the
    plan and the fits with their formats and certified rounding bounds."""
    tpp = ctx.ticks_per_pu
    fv, fits = choose_formats(ctx, fits, progress)
    fits = requantize(ctx, fits, fv, progress)
    plan = build_plan(ctx, fits, fv)
    bounds = plan.rounding_bounds()
    fits = [dataclasses.replace(sf, bound_pu=bounds[o.preround] / tpp) for sf, o in zip(fits, plan.outputs)]
    plan.meta = _plan_meta(ctx, fits, fv, output_multipliers(plan))
    return plan, fits


def _plan_meta(ctx: FitContext, fits: list[ServoFit], fv: int, mults: dict) -> dict:
    robot, tpp = ctx.robot, ctx.ticks_per_pu
    return {
        "robot": robot.name,
        "budget_pu": vars(ctx.budget),
        "method": {"fit": "discrete minimax (exchange on active points) over the fit and check samples; "
                          "per servo the variable set "
                          f"and total degree {ctx.cost_model.objective}, then pruned",
                   # the model only where it is not the default: default plans stay byte-identical
                   **({"cost_model": ctx.cost_model.record()} if ctx.cost_model != DEFAULT_COST_MODEL else {}),
                   "lowering": robot.fit.lowering,
                   "operand_bits": list(ctx.operand_bits) if ctx.operand_bits else None,
                   "seed": FIT_SEED, "fit_samples": FIT_SAMPLES, "check_samples": CHECK_SAMPLES,
                   "max_degree": MAX_DEGREE},
        "features": {**ctx.stage.meta(), "frac_bits": fv},
        "servos": [{"name": sf.name, "variables": sf.features.kind, "names": list(sf.features.names),
                    "term_set": "tensor" if sf.features.tensor else "total degree",
                    "powers": dict(zip(sf.features.names, sf.features.allowed)), "total_degree": sf.degree,
                    "terms": len(sf.poly), "multipliers": mults[sf.name], "accumulator_frac_bits": sf.frac,
                    "piecewise": sf.features.piecewise_record(),
                    "fit_error_pu": sf.fit_error_ticks / tpp, "certified_rounding_pu": sf.bound_pu,
                    "coefficients": [{"exponents": list(e), "value": c} for e, c in sf.poly.items()]}
                   for sf in fits],
    }


def fit_robot(robot, progress=lambda msg: None, *, certified: bool = True,
              cost_model: CostModel = DEFAULT_COST_MODEL, jobs: int = 1) -> FitResult:
    """Fit every servo of ``robot`` and return the evaluation plan and the fits.

    Per servo the structure of least ``cost_model`` cost (:mod:`ikseries.fit.cost`; the
    architecture's, :meth:`ikseries.hdl.architectures.Architecture.cost_model`) that meets the
    approximation budget is kept.

    With ``certified`` (the default) the error over the continuous workspace box is then
    bounded rigorously (:func:`ikseries.fit.certify.certify`) and stored in
    ``plan.meta["certificate"]`` (the certifier's cell budget at least ``CERTIFY_PER_START``
    times its starting cells). A servo whose certified total exceeds the tolerance is refitted:
    where the certifier sampled an error above its target (counterexamples: the fit samples
    missed a region, e.g. a sliver of a feature cell at the workspace's rim), with fit points
    about them (:meth:`_Samples.add_misses`), else with a 15 % tighter approximation budget;
    after ``CERTIFY_ATTEMPTS`` fits the plan is refused (:class:`FitError`).

    With ``fit.products = "dsp"`` every multiplication's operands fit one DSP block of
    ``hardware.dsp`` (:func:`operand_bits`; narrowed by the plan builder). The extra rounding
    may not fit the usual 10 % of the tolerance; then the whole fit is redone with the next
    of ``QUANTIZATION_SHARES`` (the approximation budget shrinks by as much).

    A cell of the workspace over which the reference has no enclosure once the certifier's
    cell budget is spent (:class:`~ikseries.fit.certify.UnboundedCellError`: e.g. a chain's IK
    near a singular pose) refuses the fit at once, naming the cell: no refit can help.

    ``jobs`` > 1 fits and certifies the servos in that many processes at a time
    (:func:`~.parallel.servo_map`); the plan is the same whatever ``jobs``.
    """
    check_jobs(jobs)
    robot = robot.fitted    # a mirrored leg's margin reserved
    bits = operand_bits(robot)
    if bits is None:
        return _fit_attempts(FitContext.for_robot(robot, QUANTIZATION_SHARES[0], cost_model), progress, certified, jobs)
    for share, bigger in zip(QUANTIZATION_SHARES, QUANTIZATION_SHARES[1:] + (None,)):
        try:
            return _fit_attempts(FitContext.for_robot(robot, share, cost_model), progress, certified, jobs)
        except FormatError as e:
            if bigger is None:
                raise FormatError(f"{e} ({share:.0%} of the tolerance) with every product fitting "
                                  f"{bits[0]} x {bits[1]} DSP operands (fit.products = \"dsp\", hardware.dsp = "
                                  f"{robot.hardware.dsp!r}); use fit.products = \"exact\", a wider DSP or a looser "
                                  f"tolerance") from None
            progress(f"{e} with products fitting {bits} DSP operands: refitting with "
                     f"{bigger:.0%} of the tolerance for rounding")
    raise AssertionError("unreachable")


def _fit_servos(ctx: FitContext, samples: _Samples, fits: list, approx: list, progress, jobs: int) -> list:
    """``fits`` with every missing (None) servo fitted to its approximation budget (ticks), the
    servos in up to ``jobs`` processes (:func:`~.parallel.servo_map`)."""
    todo = [k for k, f in enumerate(fits) if f is None]
    candidates = {k: feature_sets(ctx, k) for k in todo}
    sets = {k: samples.sets(k, candidates[k]) for k in todo}      # before any fork: computed once

    def one(k, say):
        name = ctx.robot.servos[k]
        say(f"fitting {name}: candidates " + "; ".join(
            f"{fs.label()} ({', '.join(f'{v} {a}' for v, a in zip(fs.names, fs.allowed))})"
            for fs in candidates[k]))
        return fit_servo(ctx, name, candidates[k], sets[k], samples.raw(k), approx[k], say)
    fits = list(fits)
    for k, f in zip(todo, servo_map(one, todo, jobs, progress)):
        fits[k] = f
    return fits


def _certificate(ctx: FitContext, plan: Plan, progress, jobs: int):
    progress("certifying the error bound over the continuous workspace")
    cert = certify(ctx.robot, plan, progress=progress, jobs=jobs, per_start=CERTIFY_PER_START)
    for line in cert.lines():
        progress("  " + line)
    rec = cert.to_json()    # without run times (the plan must be byte-identical on a rerun) and
    for c in rec["servos"]:  # counterexamples (for a refit)
        c.pop("seconds", None)
        c.pop("misses", None)
    plan.meta["certificate"] = rec
    return cert


def _refit(ctx: FitContext, samples: _Samples, cert, failed: list, approx: list, fits: list, attempt: int,
           progress) -> None:
    """Mark the ``failed`` servos for a refit: one whose certification found counterexamples
    (a sampled error above its target: the fit samples missed a region) gets fit points about
    them, at the same budget; the others a 15 % tighter approximation budget."""
    for k in failed:
        fits[k] = None
        misses = cert.servos[k].misses
        if misses:
            samples.add_misses(k, misses, FIT_SEED + 2 + attempt)
            progress(f"{ctx.robot.servos[k]}: sampled error {max(m[2] for m in misses):.4f} pu above the "
                     f"target in {len(misses)} regions: refitting with "
                     f"{len(misses) * MISS_POINTS * len(MISS_SCALES)} fit points about them")
        else:
            approx[k] *= 0.85
            progress(f"{ctx.robot.servos[k]}: certified bound above the tolerance: refitting with a 15 % "
                     f"tighter approximation budget")


def _fit_attempts(ctx: FitContext, progress, certified: bool, jobs: int) -> FitResult:
    """Fit, lower and certify; refit the servos whose certified total misses the tolerance
    with a tighter approximation budget, up to ``CERTIFY_ATTEMPTS`` times."""
    robot = ctx.robot
    progress(ctx.stage.describe())
    samples = _Samples(ctx)
    approx = [ctx.budget.approximation * ctx.ticks_per_pu] * len(robot.servos)
    fits: list = [None] * len(robot.servos)
    for attempt in range(CERTIFY_ATTEMPTS):
        fits = _fit_servos(ctx, samples, fits, approx, progress, jobs)
        plan, fits = lower(ctx, fits, progress)
        if not certified:
            return FitResult(plan, fits)
        try:
            cert = _certificate(ctx, plan, progress, jobs)
        except UnboundedCellError as e:
            raise FitError(f"fit refused: {e}") from None
        failed = [k for k, c in enumerate(cert.servos)
                  if not (c.converged and c.total_pu <= robot.fit.tolerance_pu)]
        if not failed:
            return FitResult(plan, fits)
        _refit(ctx, samples, cert, failed, approx, fits, attempt, progress)
    try:
        cert.check(robot.fit.tolerance_pu)
    except CertificationError as e:
        raise FitError(f"fit refused: {e}") from None
    raise FitError("fit refused: certification failed")  # check() raises whenever a servo failed
