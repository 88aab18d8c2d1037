"""Divided differences (path mode): Newton interpolation of joint angles along a straight tool path.

The method (planar arm, tool orientation fixed): from ``n`` known poses (nodes) on a
straight tool path, each link angle is written as ``angle ~ P_x(x) + P_y(y)``, where
``P_x`` and ``P_y`` are Newton interpolating polynomials of degree ``n - 1`` (a cubic for
the usual four nodes) in x and in y.

Incidence factors (our precise reading of the source's term). For a path of direction
``(dx, dy)`` the shares of x and of y are

    w_x = |dx| / (|dx| + |dy|),    w_y = |dy| / (|dx| + |dy|)

(so ``w_x + w_y = 1``; a vertical path is all y, a horizontal one all x, ``y = x + c`` is
half and half). ``P_x`` interpolates ``w_x * angle`` at the nodes' x and ``P_y``
interpolates ``w_y * angle`` at the nodes' y, so the sum reproduces the angle at every
node. A polynomial whose weight is 0 is identically 0 (its nodes need not be distinct).

On the path itself x and y are affine in the path parameter, so ``P_x(x(t)) + P_y(y(t))``
is *the* degree ``n - 1`` interpolant of the angle in ``t`` whatever the weights are; the
weights only decide how the formula extends off the path (see the 2-D comparison in
:func:`path_report`).

Conventions follow numpy.polynomial: power-basis coefficients are listed lowest degree first.
Angles are in degrees, lengths in the arm's units, pulses in pu.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ...joints import geometry_record
from ...planar_arm import PlanarArm
from ..polyfit import fit_lawson, total_degree_terms, vander

__all__ = ["divided_differences", "newton_eval", "newton_derivatives", "newton_to_power", "incidence_weights",
           "nearest_turn", "PathInterpolant", "path_interpolant", "PathCase", "DEFAULT_CASES", "path_report",
           "run_divided_differences", "render_markdown"]


# -- Newton interpolation (pure functions) ------------------------------------------------------
def _nodes_values(nodes, values):
    x = np.asarray(nodes, dtype=np.float64)
    f = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or len(x) < 1:
        raise ValueError(f"nodes must be a non-empty 1-D sequence of numbers, not {nodes!r}")
    if f.shape != x.shape:
        raise ValueError(f"values must have one entry per node ({len(x)}), not {values!r}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(f))):
        raise ValueError(f"nodes and values must be finite, not {nodes!r} and {values!r}")
    if len(np.unique(x)) != len(x):
        raise ValueError(f"nodes must be distinct, not {nodes!r}")
    return x, f


def divided_differences(nodes, values) -> np.ndarray:
    """Newton coefficients ``c[k] = f[x_0, ..., x_k]`` of the interpolant of ``values`` at ``nodes``.

    The interpolating polynomial is
    ``c[0] + c[1] (x - x_0) + c[2] (x - x_0)(x - x_1) + ...``.

    Raises
    ------
    ValueError
        If the nodes are not distinct or the lengths differ.
    """
    x, c = _nodes_values(nodes, values)
    c = c.copy()
    for k in range(1, len(x)):
        c[k:] = (c[k:] - c[k - 1:-1]) / (x[k:] - x[:-k])
    return c


def newton_derivatives(nodes, coef, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value, first and second derivative of the Newton-form polynomial at ``x``.

    Nested (Horner) evaluation: ``p <- p (x - x_k) + c_k``, with ``p' <- p' (x - x_k) + p``
    and ``p'' <- p'' (x - x_k) + 2 p'`` updated first.
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    coef = np.asarray(coef, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    p = np.full(x.shape, coef[-1])
    dp = np.zeros(x.shape)
    d2p = np.zeros(x.shape)
    for k in range(len(coef) - 2, -1, -1):
        h = x - nodes[k]
        d2p = d2p * h + 2 * dp
        dp = dp * h + p
        p = p * h + coef[k]
    return p, dp, d2p


def newton_eval(nodes, coef, x) -> np.ndarray:
    """Value of the Newton-form polynomial ``coef`` on ``nodes`` at ``x``."""
    return newton_derivatives(nodes, coef, x)[0]


def newton_to_power(nodes, coef) -> np.ndarray:
    """Power-basis coefficients (lowest degree first) of the Newton-form polynomial."""
    nodes = np.asarray(nodes, dtype=np.float64)
    coef = np.asarray(coef, dtype=np.float64)
    p = np.array([coef[-1]])
    for k in range(len(coef) - 2, -1, -1):
        p = np.polynomial.polynomial.polymul(p, [-nodes[k], 1.0])
        p[0] += coef[k]
    return p


def incidence_weights(dx: float, dy: float) -> tuple[float, float]:
    """Shares ``(w_x, w_y) = (|dx|, |dy|) / (|dx| + |dy|)`` of x and y for a path direction.

    A vertical path (``dx == 0``) gives ``(0, 1)``: all y.
    """
    dx, dy = float(dx), float(dy)
    s = abs(dx) + abs(dy)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"path direction must be a finite non-zero vector, not {(dx, dy)!r}")
    return abs(dx) / s, abs(dy) / s


def nearest_turn(angle, reference):
    """``angle + 360 k`` (degrees) nearest to ``reference``: an angle on a chosen continuous branch."""
    angle = np.asarray(angle, dtype=np.float64)
    return reference + np.mod(angle - reference + 180.0, 360.0) - 180.0


# -- the path interpolant -----------------------------------------------------------------------
@dataclass(frozen=True)
class PathInterpolant:
    """``P_x(x) + P_y(y)``: Newton polynomials of the weighted angle in x and in y.

    ``x_nodes, cx`` (``y_nodes, cy``) are the nodes and Newton coefficients of ``P_x``
    (``P_y``); a part with weight 0 has empty coefficients and is identically 0.
    """

    x_nodes: tuple
    cx: tuple
    y_nodes: tuple
    cy: tuple
    wx: float
    wy: float

    def _parts(self, x, y):
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        zero = (np.zeros(x.shape),) * 3
        px = newton_derivatives(self.x_nodes, self.cx, x) if self.cx else zero
        py = newton_derivatives(self.y_nodes, self.cy, y) if self.cy else zero
        return px, py

    def __call__(self, x, y) -> np.ndarray:
        px, py = self._parts(x, y)
        return px[0] + py[0]

    def along(self, x, y, ux: float, uy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value and first and second derivatives w.r.t. ``t`` on the line ``(x, y) + t (ux, uy)``."""
        px, py = self._parts(x, y)
        return px[0] + py[0], px[1] * ux + py[1] * uy, px[2] * ux * ux + py[2] * uy * uy

    def power(self) -> tuple[list, list]:
        """Power-basis coefficients (lowest first) of ``P_x`` and of ``P_y`` ([] if weight 0)."""
        return ([float(c) for c in newton_to_power(self.x_nodes, self.cx)] if self.cx else [],
                [float(c) for c in newton_to_power(self.y_nodes, self.cy)] if self.cy else [])


def path_interpolant(xs, ys, values) -> PathInterpolant:
    """The divided-differences formula through ``values`` at collinear nodes ``(xs, ys)``.

    The incidence weights come from the direction first node -> last node.

    Raises
    ------
    ValueError
        If the nodes are not on one straight line, or a part with non-zero weight has
        repeated nodes.
    """
    xs, ys, f = (np.asarray(a, dtype=np.float64) for a in (xs, ys, values))
    if not (xs.ndim == 1 and xs.shape == ys.shape == f.shape and len(xs) >= 2):
        raise ValueError(f"xs, ys and values must be 1-D of one length >= 2, not {xs.shape}, {ys.shape}, {f.shape}")
    dx, dy = xs[-1] - xs[0], ys[-1] - ys[0]
    wx, wy = incidence_weights(dx, dy)
    cross = np.abs((xs - xs[0]) * dy - (ys - ys[0]) * dx)
    if np.max(cross) > 1e-9 * (dx * dx + dy * dy):
        raise ValueError(f"nodes must lie on one straight path, not {list(zip(xs.tolist(), ys.tolist()))!r}")
    cx = tuple(float(c) for c in divided_differences(xs, wx * f)) if wx > 0 else ()
    cy = tuple(float(c) for c in divided_differences(ys, wy * f)) if wy > 0 else ()
    return PathInterpolant(tuple(xs.tolist()), cx, tuple(ys.tolist()), cy, wx, wy)


# -- cases --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PathCase:
    """A straight tool path with its nodes and a 2-D comparison box.

    Parameters
    ----------
    name : str
    phi : float
        Tool orientation (deg) for this case; replaces the geometry's ``phi``.
    slope : float or None
        The path is ``y = slope * x + offset``; ``None``: the vertical path ``x = offset``.
    offset : float
    nodes : tuple of float
        x of the nodes (y for a vertical path); at least 2, distinct.
    box : ((x_min, x_max), (y_min, y_max))
        Workspace box of the 2-D comparison.
    """

    name: str
    phi: float
    slope: float | None
    offset: float
    nodes: tuple
    box: tuple

    def __post_init__(self):
        n = self.nodes
        if (not isinstance(n, tuple) or len(n) < 2 or not all(_is_real(v) for v in n)
                or len(set(n)) != len(n)):
            raise ValueError(f"PathCase.nodes must be a tuple of >= 2 distinct finite numbers, not {n!r}")
        for field in ("phi", "offset"):
            if not _is_real(getattr(self, field)):
                raise ValueError(f"PathCase.{field} must be a finite number, not {getattr(self, field)!r}")
        if self.slope is not None and not _is_real(self.slope):
            raise ValueError(f"PathCase.slope must be a finite number or None, not {self.slope!r}")
        b = self.box
        if not (isinstance(b, tuple) and len(b) == 2 and all(
                isinstance(r, tuple) and len(r) == 2 and all(_is_real(v) for v in r) and r[0] < r[1] for r in b)):
            raise ValueError(f"PathCase.box must be ((x_min, x_max), (y_min, y_max)) with min < max, not {b!r}")

    @property
    def line(self) -> str:
        if self.slope is None:
            return f"x = {self.offset:g}"
        m = {1.0: "", -1.0: "-"}.get(float(self.slope), f"{self.slope:g} ")
        return f"y = {m}x {'+' if self.offset >= 0 else '-'} {abs(self.offset):g}"

    def node_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of the nodes."""
        n = np.array(self.nodes, dtype=np.float64)
        if self.slope is None:
            return np.full_like(n, self.offset), n
        return n, self.slope * n + self.offset

    def direction(self) -> tuple[float, float]:
        """Unit vector (ux, uy) from the first node to the last."""
        x, y = self.node_points()
        dx, dy = x[-1] - x[0], y[-1] - y[0]
        h = math.hypot(dx, dy)
        return dx / h, dy / h

    def parameter(self, x, y):
        """Path parameter ``t``: signed arc length from the first node."""
        x0, y0 = (float(a[0]) for a in self.node_points())
        ux, uy = self.direction()
        return (np.asarray(x) - x0) * ux + (np.asarray(y) - y0) * uy

    def points(self, t) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) at path parameter(s) ``t``."""
        x0, y0 = (float(a[0]) for a in self.node_points())
        ux, uy = self.direction()
        t = np.asarray(t, dtype=np.float64)
        return x0 + t * ux, y0 + t * uy


def _is_real(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


#: The issue's three cases (arm 35/30/10). Boxes: around each path; the phi=90 box is the
#: smallest one holding the whole path.
DEFAULT_CASES = (
    PathCase("phi90-diagonal", 90.0, 1.0, 40.0, (-15.0, -5.0, 0.0, 10.0), ((-15.0, 10.0), (25.0, 50.0))),
    PathCase("phi45-falling", 45.0, -0.5, 40.0, (-10.0, 0.0, 10.0, 20.0), ((-10.0, 20.0), (30.0, 45.0))),
    PathCase("phi180-vertical", 180.0, None, -50.0, (-20.0, -10.0, 0.0, 15.0), ((-55.0, -45.0), (-20.0, 15.0))),
)


# -- the report ---------------------------------------------------------------------------------
def _branch(angles, reference, where):
    """Angles on the continuous branch nearest ``reference``; raises if they still jump (> 90 deg)."""
    a = nearest_turn(angles, reference)
    for axis in range(a.ndim):
        if a.shape[axis] > 1 and np.max(np.abs(np.diff(a, axis=axis))) > 90.0:
            raise ValueError(f"{where}: the angle is not continuous within 180 deg of {reference:.6g} deg")
    return a


def _at(i, t, x, y) -> dict:
    return {"t": float(t[i]), "x": float(x[i]), "y": float(y[i])}


def _minimax_1d(t, f, tc, degree) -> np.ndarray:
    """Near-minimax polynomial of ``degree`` in ``t`` fitted on (t, f), evaluated at ``tc``."""
    mid, half = (t.max() + t.min()) / 2, (t.max() - t.min()) / 2
    terms = total_degree_terms(degree, ["any"])
    c, _ = fit_lawson(vander(((t - mid) / half)[:, None], terms), f, 40)
    return vander(((tc - mid) / half)[:, None], terms) @ c


def _minimax_2d(pts, f, cpts, fc, box, degree):
    lo = np.array([r[0] for r in box])
    hi = np.array([r[1] for r in box])
    norm = lambda p: (p - (lo + hi) / 2) / ((hi - lo) / 2)  # noqa: E731
    terms = total_degree_terms(degree, ["any", "any"])
    c, _ = fit_lawson(vander(norm(pts), terms), f, 40)
    return float(np.max(np.abs(vander(norm(cpts), terms) @ c - fc))), len(terms)


def _workspace(geometry, case, interps, refs, k, pu, tolerance_pu, grid, max_degree):
    (x0, x1), (y0, y1) = case.box
    g1 = np.meshgrid(np.linspace(x0, x1, grid), np.linspace(y0, y1, grid), indexing="ij")
    m = 3 * grid - 2  # check grid: the fit grid plus two points inside each cell
    g2 = np.meshgrid(np.linspace(x0, x1, m), np.linspace(y0, y1, m), indexing="ij")
    where = f"case {case.name}: joint {geometry.servos[k]} over the box {case.box}"
    f1 = _branch(geometry.ik(*g1)[k], refs[k], where).ravel()
    f2 = _branch(geometry.ik(*g2)[k], refs[k], where)
    dd = np.abs(interps[k](*g2) - f2)
    i = int(np.argmax(dd))
    p1 = np.stack([a.ravel() for a in g1], 1)
    p2 = np.stack([a.ravel() for a in g2], 1)
    fits = {}
    for deg in range(1, max_degree + 1):
        e, nt = _minimax_2d(p1, f1, p2, f2.ravel(), case.box, deg)
        fits[deg] = {"degree": deg, "terms": nt, "max_error_deg": e, "max_error_pu": e * pu}
        if deg >= 3 and e * pu <= tolerance_pu:
            break
    best = fits[max(fits)]
    return {
        "box": [list(r) for r in case.box], "check_points": int(m * m),
        "divided_differences": {"max_error_deg": float(dd.ravel()[i]), "max_error_pu": float(dd.ravel()[i] * pu),
                                "at": {"x": float(g2[0].ravel()[i]), "y": float(g2[1].ravel()[i])}},
        "minimax_cubic": fits[3],
        "minimax_to_tolerance": {**best, "meets_tolerance": bool(best["max_error_pu"] <= tolerance_pu)},
    }


def _rates(ip, samples, nodes, u, dd, ex) -> dict:
    """Joint velocity and acceleration of the path formula: at the nodes, maxima and errors."""
    (tc, x, y), (ux, uy), (vel, acc) = samples, u, dd
    _, nvel, nacc = ip.along(*nodes, ux, uy)
    dv, da = np.abs(vel - ex[0]), np.abs(acc - ex[1])
    iv, ia = int(np.argmax(dv)), int(np.argmax(da))
    rates = {
        "unit": "deg per unit of t (arc length); per_x / per_y: deg per unit of x / y along the path",
        "at_nodes": {"t": [float(v) for v in nvel], "t2": [float(v) for v in nacc]},
        "max_abs": {"velocity_t": float(np.max(np.abs(vel))), "acceleration_t": float(np.max(np.abs(acc))),
                    "exact_velocity_t": float(np.max(np.abs(ex[0]))),
                    "exact_acceleration_t": float(np.max(np.abs(ex[1])))},
        "max_error": {"velocity_t": float(dv[iv]), "velocity_at": _at(iv, tc, x, y),
                      "acceleration_t": float(da[ia]), "acceleration_at": _at(ia, tc, x, y)},
    }
    if ux != 0:
        rates["at_nodes"]["per_x"] = [float(v / ux) for v in nvel]
        rates["at_nodes"]["per_x2"] = [float(v / ux ** 2) for v in nacc]
    if uy != 0:
        rates["at_nodes"]["per_y"] = [float(v / uy) for v in nvel]
        rates["at_nodes"]["per_y2"] = [float(v / uy ** 2) for v in nacc]
    return rates


def path_report(geometry: PlanarArm, case: PathCase, *, pu_per_degree: float = 20.0, tolerance_pu: float = 0.5,
                samples: int = 2001, grid: int = 41, max_degree: int = 10) -> dict:
    """Divided differences on one path: formula, accuracy, FK check, joint rates and comparisons.

    The geometry's ``phi`` is replaced by ``case.phi``. Angles are taken on the continuous
    branch nearest their value at the middle of the path (the [0, 360) output of
    :meth:`PlanarArm.ik` may wrap along a path; ``wraps_0_360`` says whether it does).

    Parameters
    ----------
    geometry : PlanarArm
    case : PathCase
    pu_per_degree : float
        Servo gain, for errors in pu (the robot's ``pu_per_degree``).
    tolerance_pu : float
        Target of the 2-D minimax fit: the lowest total degree (>= 3) within it is reported.
    samples : int
        Points along the path between the extreme nodes for the fit; errors are checked on
        ``4 * samples - 3`` points.
    grid : int
        Fit grid per side of the 2-D box (errors checked on ``3 * grid - 2`` per side).
    max_degree : int
        Highest total degree tried for the 2-D minimax fit.

    Returns
    -------
    dict
        JSON-ready: per joint the Newton and power coefficients, node residual, max angle
        error along the path (deg, pu, where), velocity / acceleration (per unit of path
        parameter ``t`` = arc length from the first node, and per unit of x / y) with their
        max error against the exact rates, the minimax cubic along the path, and the 2-D
        comparison; and the FK position error along the path (max and where).
    """
    if not isinstance(geometry, PlanarArm):
        raise TypeError(f"geometry must be a PlanarArm, not {geometry!r}")
    if not isinstance(case, PathCase):
        raise TypeError(f"case must be a PathCase, not {case!r}")
    for name, v, lo in (("samples", samples, 8), ("grid", grid, 4), ("max_degree", max_degree, 3)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, not {v!r}")
    g = dataclasses.replace(geometry, phi=float(case.phi))
    pu = float(pu_per_degree)
    path = _sample_path(g, case, samples)
    joints, dd_angles, mm_angles = {}, [], []
    for k, servo in enumerate(g.servos):
        joints[servo], dd, mm = _joint_report(g, case, path, k, pu, tolerance_pu, grid, max_degree)
        dd_angles.append(dd)
        mm_angles.append(mm)
    xn, yn = path.nodes
    return {
        "case": case.name, "phi_deg": float(case.phi), "path": case.line,
        "direction": list(path.direction), "incidence_weights": {"x": path.interps[0].wx, "y": path.interps[0].wy},
        "nodes": {"x": xn.tolist(), "y": yn.tolist(), "t": path.tn.tolist()},
        "check_samples": int(len(path.tc)), "pu_per_degree": pu,
        "joints": joints,
        "fk": _fk_errors(g, path, dd_angles, mm_angles),
    }


@dataclass(frozen=True)
class _SampledPath:
    """One case's path sampled for :func:`path_report`: the nodes (points and parameter ``tn``)
    and the per-joint interpolants through their angles, the fit samples ``t`` and the check
    samples ``tc`` (points ``x``, ``y``) with the exact angles (``raw``: as the IK gives them;
    ``exact``: on the continuous branch nearest ``refs``, the angles at the middle) and rates."""
    nodes: tuple
    tn: np.ndarray
    direction: tuple
    t: np.ndarray
    tc: np.ndarray
    x: np.ndarray
    y: np.ndarray
    raw: tuple
    refs: list
    exact: list
    node_angles: list
    interps: list
    exact_rates: tuple
    fit_exact: list


def _sample_path(g: PlanarArm, case: PathCase, samples: int) -> _SampledPath:
    """``case``'s path for ``g`` with ``samples`` fit samples between its extreme nodes."""
    xn, yn = case.node_points()
    tn = case.parameter(xn, yn)
    ux, uy = case.direction()
    t_lo, t_hi = float(tn.min()), float(tn.max())
    t = np.linspace(t_lo, t_hi, samples)
    tc = np.linspace(t_lo, t_hi, 4 * samples - 3)
    x, y = case.points(tc)
    raw = g.ik(x, y)
    refs = [float(a) for a in g.ik(*case.points((t_lo + t_hi) / 2))]
    exact = [_branch(a, r, f"case {case.name}: joint {s} along the path") for a, r, s in zip(raw, refs, g.servos)]
    node_angles = [nearest_turn(a, r) for a, r in zip(g.ik(xn, yn), refs)]
    interps = [path_interpolant(xn, yn, a) for a in node_angles]
    ex_rates = g.rates(*exact, ux, uy)
    fit_exact = [nearest_turn(a, r) for a, r in zip(g.ik(*case.points(t)), refs)]
    return _SampledPath((xn, yn), tn, (ux, uy), t, tc, x, y, raw, refs, exact, node_angles, interps, ex_rates,
                        fit_exact)


def _joint_report(g, case, path: _SampledPath, k, pu, tolerance_pu, grid, max_degree) -> tuple:
    """Joint ``k``'s record for :func:`path_report`, its divided-differences angles along the
    check samples and those of its minimax cubic along the path."""
    (xn, yn), (ux, uy), tc, x, y = path.nodes, path.direction, path.tc, path.x, path.y
    ip = path.interps[k]
    val, vel, acc = ip.along(x, y, ux, uy)
    err = np.abs(val - path.exact[k])
    i = int(np.argmax(err))
    mm = _minimax_1d(path.t, path.fit_exact[k], tc, len(path.tn) - 1)
    mm_err = np.abs(mm - path.exact[k])
    j = int(np.argmax(mm_err))
    nv = ip(xn, yn)
    px, py = ip.power()
    ex_vel, ex_acc = path.exact_rates
    record = {
        "node_angles_deg": [float(v) for v in path.node_angles[k]],
        "node_residual_deg": float(np.max(np.abs(nv - path.node_angles[k]))),
        "wraps_0_360": bool(np.any(np.abs(np.diff(path.raw[k])) > 180.0)),
        "newton_x": list(ip.cx), "newton_y": list(ip.cy), "power_x": px, "power_y": py,
        "power_t": [float(c) for c in newton_to_power(path.tn, divided_differences(path.tn, path.node_angles[k]))],
        "max_error_deg": float(err[i]), "max_error_pu": float(err[i] * pu), "at": _at(i, tc, x, y),
        "rates": _rates(ip, (tc, x, y), (xn, yn), (ux, uy), (vel, acc), (ex_vel[k], ex_acc[k])),
        "minimax_path": {"max_error_deg": float(mm_err[j]), "max_error_pu": float(mm_err[j] * pu),
                         "at": _at(j, tc, x, y)},
        "workspace": _workspace(g, case, path.interps, path.refs, k, pu, tolerance_pu, grid, max_degree),
    }
    return record, val, mm


def _fk_errors(g, path: _SampledPath, dd_angles, mm_angles) -> dict:
    """Tip position error along the path of the divided-differences and minimax angles."""
    tc, x, y = path.tc, path.x, path.y
    fx, fy = g.fk(*dd_angles)
    pos = np.hypot(fx - x, fy - y)
    i = int(np.argmax(pos))
    mx, my = g.fk(*mm_angles)
    mpos = np.hypot(mx - x, my - y)
    j = int(np.argmax(mpos))
    return {"max_position_error": float(pos[i]), "at": _at(i, tc, x, y),
            "minimax_path_max_position_error": float(mpos[j]), "minimax_path_at": _at(j, tc, x, y)}


def run_divided_differences(geometry: PlanarArm, cases=DEFAULT_CASES, *, pu_per_degree: float = 20.0,
                            tolerance_pu: float = 0.5, samples: int = 2001, grid: int = 41,
                            max_degree: int = 10) -> dict:
    """:func:`path_report` for each case: the JSON record of ``ikseries fit --method divided-differences``.

    Keyword arguments are those of :func:`path_report`; the geometry's ``phi`` is replaced
    by each case's.
    """
    if not isinstance(geometry, PlanarArm):
        raise TypeError(f"geometry must be a PlanarArm, not {geometry!r}")
    kw = dict(pu_per_degree=pu_per_degree, tolerance_pu=tolerance_pu, samples=samples, grid=grid,
              max_degree=max_degree)
    return {
        "method": "divided-differences",
        "geometry": geometry_record(geometry),
        "pu_per_degree": float(pu_per_degree), "tolerance_pu": float(tolerance_pu),
        "cases": [path_report(geometry, c, **kw) for c in cases],
    }


def _xy(at: dict) -> str:
    return f"({at['x']:.4g}, {at['y']:.4g})"


def render_markdown(result: dict) -> str:
    """Markdown tables of a :func:`run_divided_differences` result (errors in deg and pu)."""
    g = result["geometry"]
    out = [f"# Divided differences (path mode): planar arm l = {g['l1']:g}, {g['l2']:g}, {g['l3']:g}",
           "",
           f"Errors against the reference IK, in deg and pu ({result['pu_per_degree']:g} pu/deg); "
           "*along path*: dense samples between the extreme nodes; *box*: the case's 2-D box. "
           "Minimax: Lawson near-minimax fit (a cubic in the path parameter; over the box a 2-D polynomial of "
           "total degree 3, 10 terms, against the divided-differences formula's 7 free coefficients, and the "
           "lowest total degree within the tolerance). Rate errors: against the exact joint rates.",
           ""]
    for c in result["cases"]:
        w, fk = c["incidence_weights"], c["fk"]
        nodes = c["nodes"]["x"] if w["x"] else c["nodes"]["y"]
        out += [f"## {c['case']}: phi = {c['phi_deg']:g} deg, {c['path']}, nodes {nodes}",
                "",
                (f"Incidence weights w_x = {w['x']:.4g}, w_y = {w['y']:.4g}. FK position error along the path: "
                 f"divided differences {fk['max_position_error']:.3g} at {_xy(fk['at'])}, "
                 f"minimax cubic {fk['minimax_path_max_position_error']:.3g} at {_xy(fk['minimax_path_at'])}."),
                "",
                "| joint | node residual (deg) | DD along path (deg / pu) at | minimax cubic along path (deg / pu) "
                "| max velocity error (deg/t) | max acceleration error (deg/t²) | DD over box (deg / pu) "
                "| 2-D minimax cubic (deg / pu) | 2-D minimax to tolerance |",
                "|---|---|---|---|---|---|---|---|---|"]
        for s, j in c["joints"].items():
            ws = j["workspace"]
            dd, m3, mt = ws["divided_differences"], ws["minimax_cubic"], ws["minimax_to_tolerance"]
            me, ma = j["rates"]["max_error"], j["rates"]["max_abs"]
            wrap = " (wraps 0/360)" if j["wraps_0_360"] else ""
            mp = j["minimax_path"]
            out.append(
                f"| {s}{wrap} | {j['node_residual_deg']:.1e} | {j['max_error_deg']:.4f} / {j['max_error_pu']:.2f} "
                f"at {_xy(j['at'])} | {mp['max_error_deg']:.4f} / {mp['max_error_pu']:.2f} "
                f"| {me['velocity_t']:.3g} (exact max {ma['exact_velocity_t']:.3g}) | {me['acceleration_t']:.3g} "
                f"(exact max {ma['exact_acceleration_t']:.3g}) "
                f"| {dd['max_error_deg']:.3g} / {dd['max_error_pu']:.3g} "
                f"| {m3['max_error_deg']:.3g} / {m3['max_error_pu']:.3g} "
                f"| degree {mt['degree']} ({mt['terms']} terms): {mt['max_error_pu']:.3g} pu"
                f"{'' if mt['meets_tolerance'] else ' (not met)'} |")
        out += ["", "Joint rates of the cubic at the nodes (t: arc length from the first node; "
                "per x / per y: along the path, per unit of x / y):", "",
                "| joint | d/dt (deg/unit) | d²/dt² (deg/unit²) | d/dx | d/dy |", "|---|---|---|---|---|"]
        for s, j in c["joints"].items():
            n = j["rates"]["at_nodes"]
            fmt = lambda v: ", ".join(f"{x:.4g}" for x in v) if v else "—"  # noqa: E731
            out.append(f"| {s} | {fmt(n['t'])} | {fmt(n['t2'])} | {fmt(n.get('per_x'))} | {fmt(n.get('per_y'))} |")
        out.append("")
    return "\n".join(out)
