"""Numeric IK of a chain: damped Newton (Levenberg-Marquardt with a small fixed damping),
continued from the home pose.

A target's solution is found by moving the goal in equal steps along the straight line in
goal space (tip coordinates, tool angle) from the home pose's goal to the target, correcting
with a few Newton steps at each and polishing at the end until the residual is at most
:data:`TOL_MM`. Between singular poses the solution moves continuously with the goal, so it
stays on the home pose's branch; the sign of the Jacobian's determinant (constant on a branch)
is watched along the way, and a path on which it changes is reported.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kinematics import format_point

__all__ = ["TOL_MM", "Solution", "newton", "continued", "determinant_sign"]

#: residual a solution must reach (mm; the tool angle's residual is counted as its arc at the
#: chain's reach)
TOL_MM = 1e-9
#: continuation step (share of the chain's reach) and the fewest steps
STEP_SHARE = 0.05
MIN_STEPS = 4
#: Newton iterations per intermediate step and for the final polish
STEP_ITERS = 4
FINAL_ITERS = 40
#: largest joint move of one Newton step (rad): keeps a far start from overshooting
MAX_STEP_RAD = 0.5
#: damping of the normal equations, relative to reach**2: negligible against any pose the
#: singularity check accepts, but it keeps a singular Jacobian solvable
DAMPING = 1e-12


def newton(chain, q, goal, iters):
    """Damped Newton on ``chain.system``: servo angles ``q`` (N, n, deg) moved towards goals
    ``goal`` (N, m); returns the new angles, the residual per target (mm, max norm) and the
    Jacobian at the last iterate evaluated. Only the targets not yet within a tenth of
    :data:`TOL_MM` are stepped and evaluated again (a converged target's angles, residual and
    Jacobian stay as they are)."""
    q = np.array(q, dtype=np.float64)
    goal = np.asarray(goal, dtype=np.float64)
    mu = DAMPING * chain.reach ** 2
    f, jac = chain.system(q, goal)
    res = np.max(np.abs(f), axis=1)
    live = np.flatnonzero(res > 0.1 * TOL_MM)
    for _ in range(iters):
        if not len(live):
            break
        rows = slice(None) if len(live) == len(q) else live      # no gathers while every target moves
        jl, fl = jac[rows], f[rows]
        jt = np.swapaxes(jl, 1, 2)
        step = -np.linalg.solve(jt @ jl + mu * np.eye(q.shape[1]), (jt @ fl[..., None]))[..., 0]
        big = np.max(np.abs(step), axis=1, keepdims=True)
        step = step * np.minimum(1.0, MAX_STEP_RAD / np.maximum(big, 1e-300))
        q[rows] += np.degrees(step)
        fl, jl = chain.system(q[rows], goal[rows])
        f[rows], jac[rows] = fl, jl
        res[rows] = np.max(np.abs(fl), axis=1)
        live = live[res[live] > 0.1 * TOL_MM]
    return q, res, jac


def determinant_sign(jac) -> np.ndarray:
    """Sign of det J per target (the branch indicator of a square system)."""
    return np.sign(np.linalg.det(jac))


@dataclass
class Solution:
    """Continued Newton solutions of N targets.

    ``angles`` (N, n) servo angles (deg); ``residual`` (N,) mm; ``crossed`` (N,) the share of
    the path at which the determinant's sign first left the home pose's (NaN if never) and
    ``crossed_at`` (N, m) the goal there."""
    chain: object
    angles: np.ndarray
    residual: np.ndarray
    crossed: np.ndarray
    crossed_at: np.ndarray

    def copy(self) -> "Solution":
        """The same solutions in arrays of their own."""
        return Solution(self.chain, self.angles.copy(), self.residual.copy(), self.crossed.copy(),
                        self.crossed_at.copy())

    @property
    def ok(self) -> np.ndarray:
        return (self.residual <= TOL_MM) & np.isnan(self.crossed)

    def checks(self):
        """(mask, reason) pairs for :func:`ikseries.reach.raise_first_unreachable`."""
        names = self.chain.goal_names
        return [(~(self.residual <= TOL_MM), lambda i: (
                    f"the Newton IK continued from the home pose {_pose(self.chain)} leaves the tip "
                    f"{self.residual[i]:.3g} mm from it (out of reach on the home pose's branch)")),
                (~np.isnan(self.crossed), lambda i: (
                    f"the path from the home pose {_pose(self.chain)} crosses a singular pose near "
                    f"{format_point(names, self.crossed_at[i])} ({self.crossed[i]:.0%} of the way; the "
                    f"Jacobian's determinant changes sign there), so the target is on another branch"))]


def _pose(chain) -> str:
    return "(" + ", ".join(f"{j.name}={j.home:g}" for j in chain.joints) + ") deg"


def continued(chain, goal) -> Solution:
    """Solve ``goal`` (m arrays of one shape) by continuation from ``chain.home``."""
    g = np.stack([np.ravel(np.asarray(v, dtype=np.float64)) for v in goal], 1)
    n_pts = len(g)
    home = np.array([chain.home], dtype=np.float64)
    start = chain.measure(home)[0]
    _, j0 = chain.system(home, start[None])
    sign0 = determinant_sign(j0)[0]
    scale = chain.row_scale
    dist = np.max(np.abs(g - start) * scale, initial=0.0)
    steps = max(MIN_STEPS, math.ceil(dist / (STEP_SHARE * chain.reach))) if np.isfinite(dist) else MIN_STEPS
    q = np.repeat(home, n_pts, axis=0)
    crossed = np.full(n_pts, np.nan)
    crossed_at = np.full(g.shape, np.nan)
    with np.errstate(invalid="ignore", over="ignore"):
        for k in range(1, steps + 1):
            t = k / steps
            gk = start + t * (g - start)
            q, res, jac = newton(chain, q, gk, STEP_ITERS if k < steps else FINAL_ITERS)
            flip = (determinant_sign(jac) != sign0) & (res < 1e-6 * chain.reach) & np.isnan(crossed)
            crossed[flip] = t
            crossed_at[flip] = gk[flip]
    return Solution(chain, q, res, crossed, crossed_at)
