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

import itertools
from dataclasses import dataclass

import numpy as np

from .features import CylinderFeatures
from .horner import horner, parity_split
from .plan import Plan, PlanBuilder, PlanInput, PlanOutput, bits_for
from .polyfit import fit_lawson, fit_least_squares, total_degree_terms, vander

__all__ = ["FitError", "ServoFit", "fit_robot", "plan_inputs", "workspace_samples"]

MAX_DEGREE = 12
FIT_SEED = 20261124
FIT_SAMPLES = (30000, 3000)      # random interior points, points per face
CHECK_SAMPLES = (100000, 10000)  # + points per edge / 4


class FitError(RuntimeError):
    """No plan meets the robot's tolerance."""


@dataclass
class ServoFit:
    name: str
    allowed: list            # per feature: any / even / odd / none
    degree: int
    poly: dict               # {exponents: float coefficient} over the features (ticks)
    fit_error_ticks: float   # max error on the fit and check samples (float coefficients)
    frac: int = 0            # accumulator / coefficient fractional bits
    bound_pu: float = 0.0    # certified rounding bound


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


def _structure(robot, k: int) -> tuple[list, bool]:
    """Which powers servo k needs, found numerically from the reference kinematics.

    Returns (allowed per feature, whether the y-free part is a constant). The
    theta symmetry of the cylindrical target becomes a parity in y: theta ->
    -theta keeps x and flips y. "even": f(x, -y, z) = f(x, y, z); "odd":
    f(x, y, z) + f(x, -y, z) = 2 f(x, 0, z).
    """
    rng = np.random.default_rng(FIT_SEED + k)
    r, th, z = robot.inputs
    n = 2000
    rr = r.min + (r.max - r.min) * rng.random(n)
    tt = th.min + (th.max - th.min) * rng.random(n)
    zz = z.min + (z.max - z.min) * rng.random(n)
    g = robot.geometry
    x, y, zc = g.to_cartesian(rr, tt, zz)
    f = lambda a, b, c: robot.calibration.pulses(g.ik_cartesian(a, b, c))[k]  # noqa: E731
    p0, pm, py0 = f(x, y, zc), f(x, -y, zc), f(x, 0 * y, zc)
    eps = 1e-9 * max(1.0, float(np.ptp(p0)))
    if np.max(np.abs(pm - p0)) < eps:
        ypar = "even"
    elif np.max(np.abs(p0 + pm - 2 * py0)) < eps:
        ypar = "odd"
    else:
        ypar = "any"
    zdep = np.max(np.abs(f(x, y, np.full(n, z.min)) - f(x, y, np.full(n, z.max)))) > eps
    y0_const = ypar == "odd" and np.ptp(py0) < eps
    return ["any", ypar, "any" if zdep else "none"], bool(y0_const)


def _terms(degree: int, allowed: list, y0_const: bool) -> list:
    terms = total_degree_terms(degree, allowed)
    if y0_const:
        terms = [e for e in terms if e[1] > 0 or sum(e) == 0]
    return terms


def _fit_servo(name, fit_set, check_set, allowed, y0_const, budget_ticks, progress) -> ServoFit:
    """Lowest total degree whose near-minimax fit meets ``budget_ticks`` on the check set.

    ``fit_set`` and ``check_set`` are (features, target ticks). Lawson's method runs on the
    fit set; the worst check points are then added to it (an exchange step) until the
    check set also meets the budget, for at most four Lawson rounds per degree.
    """
    pts, target = fit_set
    cpts, ctarget = check_set
    for deg in range(1, MAX_DEGREE + 1):
        terms = _terms(deg, allowed, y0_const)
        a = vander(pts, terms)
        c = fit_least_squares(a, target)
        err = float(np.max(np.abs(a @ c - target)))
        if err <= 8 * budget_ticks:
            ca = vander(cpts, terms)
            xa, xt = a, target
            for _ in range(4):
                c, err = fit_lawson(xa, xt, 30)
                cerr = np.abs(ca @ c - ctarget)
                err = max(err, float(cerr.max()))
                if err <= budget_ticks:
                    break
                worst = np.argsort(cerr)[-500:]
                xa, xt = np.concatenate([xa, ca[worst]]), np.concatenate([xt, ctarget[worst]])
        progress(f"  {name}: degree {deg}, {len(terms)} terms, max fit error {err:.4g} ticks")
        if err <= budget_ticks:
            return ServoFit(name, allowed, deg, dict(zip(terms, (float(v) for v in c))), err)
    raise FitError(f"servo {name}: no polynomial up to total degree {MAX_DEGREE} reaches the "
                   f"approximation budget of {budget_ticks:g} ticks")


def _servo_nodes(b: PlanBuilder, sf: ServoFit, feats: list[int], fv: int) -> int:
    """Lower one servo polynomial: E(x, y^2, z) + y * O(x, y^2, z), nested Horner."""
    if sf.allowed[1] == "any":
        return horner(b, sf.poly, feats, sf.frac)
    y2 = b.mul(feats[1], feats[1], fv)
    even, odd = parity_split(sf.poly, 1)
    vars_ = [feats[0], y2, feats[2]]
    acc = horner(b, even, vars_, sf.frac) if even else None
    if odd:
        o = b.mul(feats[1], horner(b, odd, vars_, sf.frac), sf.frac)
        acc = o if acc is None else b.add(acc, o)
    return acc


def _build(robot, inputs, cf: CylinderFeatures, fits: list[ServoFit], fv: int) -> Plan:
    b = PlanBuilder(inputs)
    feats = cf.build(b, fv, fv + 4)
    lo, hi = robot.pulse_limits_ticks()
    outs = []
    for sf in fits:
        acc = _servo_nodes(b, sf, feats, fv)
        out = b.clamp(b.round(acc, 0), lo, hi)
        outs.append(PlanOutput(sf.name, out, acc, "ticks", robot.ticks_per_pu))
    return b.build(outs)


def _choose_formats(robot, inputs, cf, fits, budget: Budget, progress) -> int:
    """Narrowest feature precision ``fv`` and per-servo accumulator precision meeting the
    certified quantization budget. Sets ``ServoFit.frac``; returns ``fv``."""
    tpp = robot.ticks_per_pu

    def bound(sf, fv, frac):
        sf.frac = frac
        try:
            plan = _build(robot, inputs, cf, [sf], fv)
        except OverflowError:
            return np.inf
        return plan.rounding_bounds()[plan.outputs[0].preround] / tpp

    for fv in range(10, 40):
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


def fit_robot(robot, progress=lambda msg: None) -> tuple[Plan, list[ServoFit]]:
    """Fit every servo of ``robot`` and return the evaluation plan and the fits."""
    tpp = robot.ticks_per_pu
    budget = Budget.split(robot.tolerance_pu, tpp)
    inputs = plan_inputs(robot)
    # cos/sin error e moves the tip by up to R_max * e; keep that to ~1 % of the budget
    rmax = max(abs(robot.inputs[0].min), abs(robot.inputs[0].max))
    cf = CylinderFeatures.for_robot(robot, trig_tol=min(1e-4, 2e-5 * 40.0 / max(rmax, 1e-9)))
    progress(f"coordinate stage: cos/sin series of degree {2 * len(cf.trig.cos_coeffs) - 2} / "
             f"{2 * len(cf.trig.sin_coeffs) - 1}, max error {cf.trig.max_error:.2e}")
    fit_pts = workspace_samples(robot, *FIT_SAMPLES, FIT_SEED)
    check_pts = workspace_samples(robot, *CHECK_SAMPLES, FIT_SEED + 1, edges=True)
    sets = [(cf.exact(*p), robot.pulses_pu(*p)) for p in (fit_pts, check_pts)]
    fits = []
    for k, name in enumerate(robot.servos):
        allowed, y0c = _structure(robot, k)
        progress(f"fitting {name} (powers: x {allowed[0]}, y {allowed[1]}, z {allowed[2]})")
        fits.append(_fit_servo(name, *((p, v[k] * tpp) for p, v in sets), allowed, y0c,
                               budget.approximation * tpp, progress))
    fv = _choose_formats(robot, inputs, cf, fits, budget, progress)
    plan = _build(robot, inputs, cf, fits, fv)
    bounds = plan.rounding_bounds()
    for sf, o in zip(fits, plan.outputs):
        sf.bound_pu = bounds[o.preround] / tpp
    plan.meta = {
        "robot": robot.name,
        "budget_pu": vars(budget),
        "method": {"fit": "Lawson near-minimax + exchange on a check set, lowest total degree",
                   "seed": FIT_SEED, "fit_samples": FIT_SAMPLES, "check_samples": CHECK_SAMPLES,
                   "max_degree": MAX_DEGREE},
        "features": {"kind": "cylindrical->cartesian", "names": list(cf.names), "kx": cf.kx,
                     "z_center": cf.z_center, "kz": cf.kz, "frac_bits": fv,
                     "trig": {"kt": cf.trig.kt, "cos": list(cf.trig.cos_coeffs),
                              "sin": list(cf.trig.sin_coeffs), "max_error": cf.trig.max_error}},
        "servos": [{"name": sf.name, "powers": sf.allowed, "total_degree": sf.degree,
                    "terms": len(sf.poly), "accumulator_frac_bits": sf.frac,
                    "fit_error_pu": sf.fit_error_ticks / tpp, "certified_rounding_pu": sf.bound_pu,
                    "coefficients": [{"exponents": list(e), "value": c} for e, c in sf.poly.items()]}
                   for sf in fits],
    }
    return plan, fits
