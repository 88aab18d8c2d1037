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
    exact feature values (computed on first use)."""

    def __init__(self, ctx: FitContext):
        robot = ctx.robot
        self.ctx = ctx
        self.points = (workspace_samples(robot, *FIT_SAMPLES, FIT_SEED),
                       workspace_samples(robot, *CHECK_SAMPLES, FIT_SEED + 1, edges=True))
        self.targets = [robot.pulses_pu(*p) for p in self.points]
        self.raw = {i.name: (self.points[0][k], self.points[1][k]) for k, i in enumerate(robot.workspace.inputs)}
        self._feats: dict = {}

    def sets(self, k: int, candidates) -> dict:
        """(fit set, check set) per variable kind of ``candidates`` for servo ``k``."""
        for fs in candidates:
            if fs.kind not in self._feats:
                self._feats[fs.kind] = [feature_values(self.ctx, fs.kind, p) for p in self.points]
        tpp = self.ctx.ticks_per_pu
        return {fs.kind: tuple((f, t[k] * tpp) for f, t in zip(self._feats[fs.kind], self.targets))
                for fs in candidates}


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
                          "and total degree with the fewest multipliers, then pruned",
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
    ``plan.meta["certificate"]``. A servo whose certified total exceeds the tolerance is
    refitted with a 15 % tighter approximation budget; after ``CERTIFY_ATTEMPTS`` fits the
    plan is refused (:class:`FitError`).

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
        return fit_servo(ctx, name, candidates[k], sets[k], samples.raw, approx[k], say)
    fits = list(fits)
    for k, f in zip(todo, servo_map(one, todo, jobs, progress)):
        fits[k] = f
    return fits


def _certificate(ctx: FitContext, plan: Plan, progress, jobs: int):
    progress("certifying the error bound over the continuous workspace")
    cert = certify(ctx.robot, plan, progress=progress, jobs=jobs)
    for line in cert.lines():
        progress("  " + line)
    rec = cert.to_json()    # without run times: the plan must be byte-identical on a rerun
    for c in rec["servos"]:
        c.pop("seconds", None)
    plan.meta["certificate"] = rec
    return cert


def _fit_attempts(ctx: FitContext, progress, certified: bool, jobs: int) -> FitResult:
    """Fit, lower and certify; refit the servos whose certified total misses the tolerance
    with a tighter approximation budget, up to ``CERTIFY_ATTEMPTS`` times."""
    robot = ctx.robot
    progress(ctx.stage.describe())
    samples = _Samples(ctx)
    approx = [ctx.budget.approximation * ctx.ticks_per_pu] * len(robot.servos)
    fits: list = [None] * len(robot.servos)
    for _ in range(CERTIFY_ATTEMPTS):
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
        for k in failed:
            approx[k] *= 0.85
            fits[k] = None
        progress(f"certified bound above the tolerance for {', '.join(robot.servos[k] for k in failed)}: "
                 "refitting with a 15 % tighter approximation budget")
    try:
        cert.check(robot.fit.tolerance_pu)
    except CertificationError as e:
        raise FitError(f"fit refused: {e}") from None
    raise FitError("fit refused: certification failed")  # check() raises whenever a servo failed
