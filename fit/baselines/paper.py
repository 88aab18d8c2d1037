"""The integer power series paper's procedure, as a baseline beside ikseries' own fit.

The paper (``/work/shared/seeds/000_*``) writes each servo pulse as
``S = sum C_ijk R**i theta**j Z**k`` over the raw cylindrical inputs (mm, degrees, mm)
and finds the coefficients in three interpolation steps, each "Cramer's rule" on as
many points as unknowns:

1. per circle (one R cylinder in one Z plane) a series in theta with 8 terms: even
   powers theta**0 .. theta**14 for servos symmetric in theta (S2, S3); for a servo
   antisymmetric in theta (S1) its value at theta = 0 plus 8 odd powers
   theta**1 .. theta**15 (the paper: "S1 contains only odd powers of theta");
2. per Z plane, a 4th-order series in R of each theta coefficient, through the five
   cylinders R = 0, 10, 20, 30, 40 mm;
3. a 4th-order series in Z of each of those, through the five planes Z = 0 .. 40 mm
   (a servo that does not depend on Z, like S1, skips this step);

then every coefficient is cut to 7 significant figures. For S2 that is the paper's
table of 8 x 5 x 5 = 200 coefficients, 35 of them zero (the R = 0 circle is a point,
so its theta coefficients beyond theta**0 vanish).

Deviations from the paper (see :func:`deviations`): the theta step is a near-minimax
fit on each circle (the even error ripple the paper sought by placing its eight points
by hand) or, optionally, interpolation at the eight Chebyshev points; the solves use
exact rational arithmetic instead of 15-digit floating point; the cylinders / planes
are five equispaced values over the robot's R and Z ranges (for the cylinder-leg preset
exactly the paper's grid).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from ..fitter import Budget, FitError
from ..ports import plan_inputs
from ..horner import horner
from ..plan import Plan, PlanBuilder, PlanOutput
from ..polyfit import fit_lawson

__all__ = [
    "R_ORDER",
    "SIG_FIGS",
    "THETA_FITS",
    "THETA_TERMS",
    "Z_ORDER",
    "PaperFit",
    "PaperGrid",
    "PaperServo",
    "cut_sig_figs",
    "deviations",
    "evaluate_servo",
    "fit_paper",
    "horner_multiplications",
    "input_scales",
    "paper_errors",
    "paper_grid",
    "paper_meta",
    "paper_plan",
    "scaled_poly",
    "theta_powers",
]

SIG_FIGS = 7        # significant figures kept in every final coefficient
THETA_TERMS = 8     # theta powers per circle (even: 0..14; odd: 1..15)
R_ORDER = 4         # order of the series in R per Z plane
Z_ORDER = 4         # order of the series in Z

THETA_FITS = ("minimax", "chebyshev")
THETA_SAMPLES = 2001     # theta samples per circle for the minimax fit (0 .. max |theta|)
LAWSON_ITERATIONS = 60

_THETA_DEVIATION = {
    "minimax": "theta step: on each circle the near-minimax 8-term series (Lawson's iteration on "
               f"{THETA_SAMPLES} theta samples), the even error ripple the paper places its 8 points by hand "
               "for (a minimax series interpolates at 8 points); not an exact 8-point solve",
    "chebyshev": "theta step: exact interpolation at the 8 positive Chebyshev points of the theta "
                 "range (a systematic choice, as the paper's future work asks) instead of points "
                 "placed by hand for an even error ripple",
}
_DEVIATIONS = (
    "arithmetic: exact rational solves instead of Excel's 15 significant figures",
    ("Z step: its order is not stated; the final table of 200 = 8 x 5 x 5 coefficients implies "
     "4th order through the five planes"),
    ("S1: odd theta powers theta**1..theta**15 (8 terms, as many as S2/S3) plus its value at "
     "theta = 0 as the theta**0 term; the paper gives neither S1's term count nor its offset"),
    "all servos keep 7 significant figures (the paper found 6 enough for S1 and S3)",
    "cutting to 7 significant figures rounds to nearest (the paper says 'truncated')",
)


def deviations(theta_fit: str) -> list[str]:
    """How this implementation departs from the paper, for the given theta step."""
    if theta_fit not in THETA_FITS:
        raise ValueError(f"theta_fit must be one of {THETA_FITS}, not {theta_fit!r}")
    return [_THETA_DEVIATION[theta_fit], *_DEVIATIONS]


# -- exact linear algebra ------------------------------------------------------------
def _solve_exact(a: list[list[Fraction]], rhs: list[Fraction]) -> list[Fraction]:
    """Solve the square system ``a x = rhs`` exactly (Gauss-Jordan with exact pivots)."""
    n = len(a)
    m = [list(row) + [v] for row, v in zip(a, rhs)]
    for col in range(n):
        piv = next((r for r in range(col, n) if m[r][col] != 0), None)
        if piv is None:
            raise ValueError(f"interpolation points must be distinct, not a singular system at column {col}")
        m[col], m[piv] = m[piv], m[col]
        p = m[col][col]
        m[col] = [v / p for v in m[col]]
        for r in range(n):
            if r != col and m[r][col] != 0:
                f = m[r][col]
                m[r] = [v - f * w for v, w in zip(m[r], m[col])]
    return [row[n] for row in m]


def _interpolate(nodes, powers, values) -> list[Fraction]:
    """Coefficients ``c`` with ``sum_m c[m] * x**powers[m] = value`` at every node (exact)."""
    xs = [Fraction(x) for x in nodes]
    a = [[x ** p for p in powers] for x in xs]
    return _solve_exact(a, [Fraction(v) for v in values])


def cut_sig_figs(value: float, digits: int = SIG_FIGS) -> float:
    """``value`` rounded to ``digits`` significant decimal figures (nearest, ties to even)."""
    if not isinstance(digits, int) or digits < 1:
        raise ValueError(f"digits must be a positive integer, not {digits!r}")
    return float(f"{float(value):.{digits - 1}e}")


# -- grid and structure -----------------------------------------------------------------


@dataclass(frozen=True)
class PaperGrid:
    """Where the reference kinematics is sampled (degrees, mm): on every circle the theta
    points (the interpolation nodes for ``"chebyshev"``, the samples of the minimax fit
    for ``"minimax"``), the R cylinders and the Z planes."""
    theta_fit: str
    theta_max: float          # the series serve theta in [-theta_max, theta_max]
    theta: tuple[float, ...]
    r: tuple[float, ...]
    z: tuple[float, ...]

    def dense_theta(self) -> np.ndarray:
        """:data:`THETA_SAMPLES` equispaced points of [0, theta_max]."""
        return np.linspace(0.0, self.theta_max, THETA_SAMPLES)


def paper_grid(robot, theta_fit: str = "minimax") -> PaperGrid:
    """The paper's grid for ``robot``: theta points, 5 cylinders and 5 planes over the
    R and Z ranges (the cylinder-leg preset: R, Z = 0, 10, 20, 30, 40 mm, as in the paper).

    ``"chebyshev"``: the positive half of the ``2 * THETA_TERMS`` Chebyshev nodes of
    ``[-t, t]``, ``t`` the largest ``|theta|`` (for an even or odd function, the even or
    odd series through them is the interpolant through all of those nodes);
    ``"minimax"``: :data:`THETA_SAMPLES` equispaced points of ``[0, t]``.
    """
    if theta_fit not in THETA_FITS:
        raise ValueError(f"theta_fit must be one of {THETA_FITS}, not {theta_fit!r}")
    r, th, z = _inputs(robot)
    tmax = max(abs(th.min), abs(th.max))
    if theta_fit == "chebyshev":
        n = 2 * THETA_TERMS
        theta = tuple(tmax * math.cos((2 * k - 1) * math.pi / (2 * n)) for k in range(1, THETA_TERMS + 1))
    else:
        theta = tuple(np.linspace(0.0, tmax, THETA_SAMPLES).tolist())
    return PaperGrid(theta_fit, float(tmax), theta, tuple(np.linspace(r.min, r.max, R_ORDER + 1).tolist()),
                     tuple(np.linspace(z.min, z.max, Z_ORDER + 1).tolist()))


def _inputs(robot):
    names = tuple(i.name for i in robot.workspace.inputs)
    if names != ("r", "theta", "z"):
        raise ValueError(f"robot inputs must be the cylindrical ('r', 'theta', 'z'), not {names!r}")
    return robot.workspace.inputs


def _theta_parity(robot, k: int, grid: PaperGrid) -> str:
    """"even" or "odd" symmetry of servo ``k`` in theta (from the reference kinematics)."""
    rr, tt, zz = (a.ravel() for a in np.meshgrid(grid.r, grid.theta, grid.z, indexing="ij"))
    f = lambda t: robot.pulses_pu(rr, t, zz)[k]
    p, m, p0 = f(tt), f(-tt), f(0 * tt)
    eps = 1e-9 * max(1.0, float(np.ptp(p)))
    if np.max(np.abs(p - m)) <= eps:
        return "even"
    if np.max(np.abs(p + m - 2 * p0)) <= eps:
        return "odd"
    name = robot.servos[k]
    raise ValueError(f"servo {name} must be even or odd in theta for the paper's series, not neither")


def _depends_on_z(robot, k: int, grid: PaperGrid) -> bool:
    rr, tt = (a.ravel() for a in np.meshgrid(grid.r, grid.theta, indexing="ij"))
    lo = robot.pulses_pu(rr, tt, np.full(rr.shape, grid.z[0]))[k]
    hi = robot.pulses_pu(rr, tt, np.full(rr.shape, grid.z[-1]))[k]
    return bool(np.max(np.abs(hi - lo)) > 1e-9 * max(1.0, float(np.ptp(lo))))


def theta_powers(parity: str) -> tuple[int, ...]:
    """Powers of theta in the paper's per-circle series (the odd one keeps theta**0 for
    the value at theta = 0)."""
    if parity == "even":
        return tuple(range(0, 2 * THETA_TERMS, 2))
    if parity == "odd":
        return (0,) + tuple(range(1, 2 * THETA_TERMS, 2))
    raise ValueError(f"parity must be 'even' or 'odd', not {parity!r}")


# -- the three steps ------------------------------------------------------------------------
def _circle_series(robot, k: int, parity: str, r: float, z: float, grid: PaperGrid
                   ) -> tuple[list[Fraction], float]:
    """Step 1: theta coefficients of servo ``k`` on the circle (r, z), in theta_powers order,
    and the series' max error on :meth:`PaperGrid.dense_theta` (pu, unrounded coefficients).

    A circle whose points all give the same pulse (R = 0: the circle is a point) has the
    constant series, exactly.
    """
    th = np.array(grid.theta)
    vals = robot.pulses_pu(np.full(th.shape, r), th, np.full(th.shape, z))[k]
    at0 = float(robot.pulses_pu(np.array([r]), np.array([0.0]), np.array([z]))[k][0])
    pows = theta_powers(parity)
    if np.ptp(vals) == 0 and vals[0] == at0:
        return [Fraction(at0)] + [Fraction(0)] * (len(pows) - 1), 0.0
    fixed = [] if parity == "even" else [Fraction(at0)]      # odd: theta**0 is the value at 0
    free = pows[len(fixed):]
    target = vals - (at0 if fixed else 0.0)
    if grid.theta_fit == "chebyshev":
        coef = _interpolate(grid.theta, free, target)
    else:
        t = th / grid.theta_max                               # normalised: well conditioned
        c, _ = fit_lawson(np.stack([t ** p for p in free], 1), target, LAWSON_ITERATIONS)
        coef = [Fraction(float(v)) / Fraction(grid.theta_max) ** p for v, p in zip(c, free)]
    coef = fixed + coef
    dense = grid.dense_theta()
    exact = robot.pulses_pu(np.full(dense.shape, r), dense, np.full(dense.shape, z))[k]
    series = sum(float(c) * dense ** p for c, p in zip(coef, pows))
    return coef, float(np.max(np.abs(series - exact)))


def _servo_coefficients(robot, k: int, parity: str, zdep: bool, grid: PaperGrid) -> tuple[dict, float]:
    """Exact coefficients {(i, j, k): C} of the three steps, and the worst circle's error of
    step 1 (pu)."""
    jpows = theta_powers(parity)
    planes = grid.z if zdep else grid.z[:1]
    ipows, kpows = tuple(range(R_ORDER + 1)), tuple(range(Z_ORDER + 1) if zdep else (0,))
    # per plane, per theta power: coefficients of the series in R (step 2)
    per_plane, worst = [], 0.0
    for z in planes:
        circles = []
        for r in grid.r:
            c, e = _circle_series(robot, k, parity, r, z, grid)
            circles.append(c)
            worst = max(worst, e)
        per_plane.append([_interpolate(grid.r, ipows, [c[m] for c in circles]) for m in range(len(jpows))])
    out = {}
    for m, j in enumerate(jpows):
        for i in ipows:
            data = [per_plane[p][m][i] for p in range(len(planes))]
            zc = _interpolate(planes, kpows, data) if zdep else data   # step 3
            for kk, c in zip(kpows, zc):
                out[(i, j, kk)] = c
    return out, worst


# -- the fit ----------------------------------------------------------------------------------
@dataclass
class PaperServo:
    """One servo's paper series: ``S = sum poly[(i, j, k)] * R**i * theta**j * Z**k`` (pu).

    ``terms`` is the paper's full coefficient table (zeros included); ``poly`` holds the
    non-zero coefficients, cut to :data:`SIG_FIGS` significant figures. ``allowed`` gives
    the powers per input (R, theta, Z), ``frac`` and ``bound_pu`` are set by
    :func:`paper_plan` (accumulator fractional bits, certified rounding bound).
    """
    name: str
    allowed: list
    terms: list
    poly: dict
    circle_error_pu: float      # worst circle's step-1 error (unrounded, on dense theta)
    unrounded: dict = field(default_factory=dict)   # the same coefficients before the cut (float64)
    frac: int = 0
    bound_pu: float = 0.0

    @property
    def degree(self) -> int:
        """Total degree of the series (raw powers of R, theta, Z)."""
        return max(sum(e) for e in self.poly)

    @property
    def multiplications(self) -> int:
        """Multiplications of the nested Horner evaluation (theta outermost, then R, Z)."""
        return horner_multiplications(self.poly, self.allowed[1])


@dataclass
class PaperFit:
    robot: str
    grid: PaperGrid
    servos: list = field(default_factory=list)

    def uncut(self) -> PaperFit:
        """The same fit with the coefficients before the cut to significant figures."""
        return PaperFit(self.robot, self.grid, [dataclasses.replace(s, poly=dict(s.unrounded))
                                                for s in self.servos])

    def counts(self) -> dict:
        """{servo: {"terms", "nonzero_terms", "multiplications"}}."""
        return {s.name: {"terms": len(s.terms), "nonzero_terms": len(s.poly),
                         "multiplications": s.multiplications} for s in self.servos}


def fit_paper(robot, theta_fit: str = "minimax") -> PaperFit:
    """The paper's series for every servo of ``robot`` (see the module docstring).

    ``theta_fit`` chooses step 1: ``"minimax"`` (default) is the near-minimax series on
    each circle, the even error ripple the paper places its eight points by hand for;
    ``"chebyshev"`` interpolates at the eight Chebyshev points (Cramer's rule, as the
    paper, at systematic points).
    """
    grid = paper_grid(robot, theta_fit)
    servos = []
    for k, name in enumerate(robot.servos):
        parity = _theta_parity(robot, k, grid)
        zdep = _depends_on_z(robot, k, grid)
        exact, circle_err = _servo_coefficients(robot, k, parity, zdep, grid)
        unrounded = {e: float(c) for e, c in exact.items() if c != 0}
        poly = {e: cut_sig_figs(c) for e, c in unrounded.items()}
        servos.append(PaperServo(name, ["any", parity, "any" if zdep else "none"], list(exact), poly,
                                 circle_err, unrounded))
    return PaperFit(robot.name, grid, servos)


# -- float evaluation ---------------------------------------------------------------------
def _theta_split(poly: dict, parity: str) -> tuple[dict, dict]:
    """``poly`` as E(theta**2, R, Z) + theta * O(theta**2, R, Z), exponents reordered to
    (theta**2 power, R power, Z power): the nesting of the paper's eq. (31)."""
    even, odd = {}, {}
    for (i, j, k), c in poly.items():
        (odd if j % 2 else even)[(j // 2, i, k)] = c
    if parity == "even" and odd:
        raise ValueError(f"an even series must have only even theta powers, not {sorted(odd)!r}")
    return even, odd


def _horner_float(poly: dict, xs: list) -> np.ndarray:
    """Nested Horner in float64 over ``xs`` (first variable outermost), like fit.horner."""
    if not xs:
        return np.float64(sum(poly.values()))
    groups: dict[int, dict] = {}
    for e, c in poly.items():
        groups.setdefault(e[0], {})[e[1:]] = c
    r = None
    for i in range(max(groups), -1, -1):
        if r is not None:
            r = r * xs[0]
        if i in groups:
            sub = _horner_float(groups[i], xs[1:])
            r = sub if r is None else r + sub
    return r


def evaluate_servo(servo: PaperServo, r, theta, z) -> np.ndarray:
    """The servo's series (pu) in float64 at real inputs (mm, degrees, mm)."""
    r, theta, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (r, theta, z)))
    even, odd = _theta_split(servo.poly, servo.allowed[1])
    xs = [theta * theta, r, z]
    out = _horner_float(even, xs) if even else np.zeros(r.shape)
    if odd:
        out = out + theta * _horner_float(odd, xs)
    return np.broadcast_to(out, r.shape)


def paper_errors(robot, fit: PaperFit, points: dict | None = None, chunk: int = 200_000) -> dict:
    """Max |series - exact pulse| per servo (pu, float64) on port-integer ``points``
    (default :func:`ikseries.accuracy.verification_points`), with where it occurs."""
    from ...accuracy import verification_points
    points = verification_points(robot) if points is None else points
    n = len(next(iter(points.values())))
    worst = {s.name: {"max_error_pu": 0.0, "at": None} for s in fit.servos}
    for start in range(0, n, chunk):
        real = [points[i.name][start:start + chunk] * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]
        ref = robot.pulses_pu(*real)
        for k, s in enumerate(fit.servos):
            e = np.abs(evaluate_servo(s, *real) - ref[k])
            j = int(np.argmax(e))
            if e[j] > worst[s.name]["max_error_pu"]:
                worst[s.name] = {"max_error_pu": float(e[j]),
                                 "at": {i.name: float(real[q][j]) for q, i in enumerate(robot.workspace.inputs)}}
    return {"points": n, "servos": worst}


def horner_multiplications(poly: dict, parity: str) -> int:
    """Multiplications of the nested Horner evaluation of a paper series: theta**2 once,
    one per power step of each nested level and, for an odd series, theta * O."""
    even, odd = _theta_split(poly, parity)
    n = int(any(e[0] > 0 for p in (even, odd) for e in p))   # theta**2
    return n + _horner_count(even) + (_horner_count(odd) + 1 if odd else 0)


def _horner_count(poly: dict) -> int:
    if not poly or not next(iter(poly)):
        return 0
    groups: dict[int, dict] = {}
    for e, c in poly.items():
        groups.setdefault(e[0], {})[e[1:]] = c
    return max(groups) + sum(_horner_count(g) for g in groups.values())


# -- lowering to an evaluation plan -----------------------------------------------------------
MAX_FRAC = 40     # accumulator fractional bits tried by paper_plan


def _pow2_at_least(x: float) -> int:
    """Smallest k >= 0 with 2**k >= x."""
    return max(0, math.ceil(math.log2(x))) if x > 0 else 0


def input_scales(robot) -> dict:
    """Power-of-two scale ``k`` per input: the plan evaluates the series in ``v / 2**k``,
    which lies in [-1, 1]."""
    return {i.name: _pow2_at_least(max(abs(i.min), abs(i.max))) for i in _inputs(robot)}


def scaled_poly(servo: PaperServo, scales: dict, ticks_per_pu: float) -> dict:
    """The servo's series over the scaled inputs, in PWM ticks: ``C * ticks_per_pu *
    2**(i kr + j kt + k kz)`` (the power of two is exact; the tick factor rounds once)."""
    kr, kt, kz = (scales[n] for n in ("r", "theta", "z"))
    return {e: float(Fraction(c) * Fraction(ticks_per_pu) * Fraction(2) ** (e[0] * kr + e[1] * kt + e[2] * kz))
            for e, c in servo.poly.items()}


def _servo_node(b, servo: PaperServo, scales: dict, tpp: float, frac: int) -> int:
    """Accumulator node of one servo: E(t**2, r, z) + t * O(t**2, r, z), nested Horner."""
    rn, tn, zn = (b.reinterpret(b.input_nodes[n], b.frac(b.input_nodes[n]) + scales[n])
                  for n in ("r", "theta", "z"))
    even, odd = _theta_split(scaled_poly(servo, scales, tpp), servo.allowed[1])
    xs = [b.mul(tn, tn), rn, zn]          # t**2 exact (no truncation)
    acc = horner(b, even, xs, frac) if even else None
    if odd:
        o = b.mul(tn, horner(b, odd, xs, frac), frac)
        acc = o if acc is None else b.add(acc, o)
    return acc


def _build_plan(robot, servos: list, scales: dict) -> Plan:
    b = PlanBuilder(plan_inputs(robot))
    limits = robot.pulse_limits_ticks()
    outs = []
    for s in servos:
        acc = _servo_node(b, s, scales, robot.ticks_per_pu, s.frac)
        outs.append(PlanOutput(s.name, b.clamp(b.round(acc, 0), *limits[s.name]), acc, "ticks", robot.ticks_per_pu))
    return b.build(outs)


def _bound_pu(robot, servo: PaperServo, scales: dict, frac: int) -> float:
    servo.frac = frac
    try:
        plan = _build_plan(robot, [servo], scales)
    except OverflowError:
        return math.inf
    return plan.rounding_bounds()[plan.outputs[0].preround] / robot.ticks_per_pu


def _choose_frac(robot, servo: PaperServo, scales: dict, budget_pu: float) -> int:
    """Fewest accumulator fractional bits whose certified rounding bound is <= budget_pu."""
    fracs = [f for f in range(MAX_FRAC + 1) if _bound_pu(robot, servo, scales, f) <= budget_pu][:1]
    if not fracs:
        raise FitError(f"servo {servo.name}: no accumulator format up to {MAX_FRAC} fractional bits keeps "
                       f"the certified rounding bound within {budget_pu:g} pu in 63-bit intermediates")
    return fracs[0]


def paper_plan(robot, fit: PaperFit, progress=lambda msg: None) -> Plan:
    """Lower ``fit`` to an evaluation plan with ikseries' output stage (round to PWM ticks,
    clamp to the pulse limits), with the fewest accumulator bits per servo whose certified
    rounding bound meets the quantization share of ikseries' error budget.

    Sets ``frac`` and ``bound_pu`` of every servo of ``fit``.
    """
    if fit.robot != robot.name:
        raise ValueError(f"fit must be of robot {robot.name!r}, not of {fit.robot!r}")
    budget = Budget.split(robot.fit.tolerance_pu, robot.ticks_per_pu)
    scales = input_scales(robot)
    for s in fit.servos:
        s.frac = _choose_frac(robot, s, scales, budget.quantization)
    progress("paper plan: accumulators " + ", ".join(f"{s.name} {s.frac}" for s in fit.servos)
             + " fractional bits")
    plan = _build_plan(robot, fit.servos, scales)
    bounds = plan.rounding_bounds()
    for s, o in zip(fit.servos, plan.outputs):
        s.bound_pu = bounds[o.preround] / robot.ticks_per_pu
    plan.meta = paper_meta(robot, fit, scales, budget)
    return plan


def paper_meta(robot, fit: PaperFit, scales: dict, budget) -> dict:
    """The plan's description of the paper method, its grid and every coefficient."""
    g = fit.grid
    return {
        "robot": robot.name,
        "budget_pu": vars(budget),
        "method": {"name": "paper", "fit": "integer power series paper: per-circle theta series, "
                   "4th-order R series per Z plane, 4th-order Z series, 7 significant figures",
                   "theta_fit": g.theta_fit, "theta_terms": THETA_TERMS, "r_order": R_ORDER,
                   "z_order": Z_ORDER, "significant_figures": SIG_FIGS,
                   "r_cylinders": list(g.r), "z_planes": list(g.z), "theta_max": g.theta_max,
                   "theta_points": len(g.theta), "deviations": deviations(g.theta_fit)},
        "features": {"kind": "scaled cylindrical inputs v / 2**k", "names": ["r", "theta", "z"],
                     "scales": scales, "frac_bits": None},
        "servos": [{"name": s.name, "powers": dict(zip(("r", "theta", "z"), s.allowed)),
                    "total_degree": s.degree, "terms": len(s.terms), "nonzero_terms": len(s.poly),
                    "multiplications": s.multiplications, "accumulator_frac_bits": s.frac,
                    "circle_error_pu": s.circle_error_pu, "certified_rounding_pu": s.bound_pu,
                    "coefficients": [{"exponents": list(e), "value": c} for e, c in s.poly.items()]}
                   for s in fit.servos],
    }
