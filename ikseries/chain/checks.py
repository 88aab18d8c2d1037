"""The workspace check of a chain robot: singular poses, branch changes and second solutions.

:func:`check_box` samples the box on a grid (no proof: the certifier's Krawczyk enclosure
per cell, :mod:`ikseries.chain.enclose`, proves the IK there) and raises :class:`ChainBoxError`, one line naming the target, where

- the chain is near-singular: the smallest singular value of the row-scaled Jacobian (mm per
  rad; :attr:`Chain.row_scale`) is below :data:`SINGULAR_SHARE` of the chain's reach;
- a target is on another branch than the home pose (the continuation of ``chain.ik`` saw the
  Jacobian's determinant change sign on its way there: :mod:`ikseries.chain.solve`);
- Levenberg-Marquardt from seeds spread over the joint ranges finds a second solution inside
  the ranges (the ranges do not pick one solution).
"""
from __future__ import annotations

import itertools

import numpy as np

from ..kinematics import format_point
from ..joints import ANGLE_SLACK_DEG
from ..reach import ReachUnprovenError
from .solve import TOL_MM, newton

__all__ = ["ChainBoxError", "check_box", "home_error", "smallest_singular_values", "second_solutions",
           "SINGULAR_SHARE", "BOX_GRID", "SEED_POINTS", "MAX_SEED_PROBLEMS"]

#: smallest singular value of the Jacobian a pose needs, as a share of the chain's reach (mm/rad
#: per mm): below it a millimetre of tip motion can cost a joint more than 20 rad / reach (5 deg
#: at a 225 mm reach), too steep for the fit. The hexapod-leg and cylinder-leg presets' boxes
#: keep 11 % and 9.6 %.
SINGULAR_SHARE = 0.05
#: grid points per input of the singularity and branch check (as the closed forms' grid)
BOX_GRID = 9
#: seeds per joint of the second-solution search (at 1/6, 1/2 and 5/6 of each range)
SEED_POINTS = 3
#: at most this many (target, seed) problems: the search's target grid is coarsened to fit
MAX_SEED_PROBLEMS = 10_000
#: two solutions differ if a joint differs by more than this (deg)
DISTINCT_DEG = 1e-6
LM_ITERS = 60


class ChainBoxError(ReachUnprovenError):
    """The workspace box of a chain is not cleanly on one branch: a near-singular pose or a
    second solution inside the joint ranges."""


def smallest_singular_values(chain, q) -> np.ndarray:
    """Smallest singular value (mm per rad) of the row-scaled Jacobian at servo angles q (N, n)."""
    _, jac = chain.system(q, chain.measure(q))
    return np.linalg.svd(jac, compute_uv=False)[:, -1]


def _singular_message(chain, s: float) -> str:
    return (f"smallest singular value of the Jacobian {s:.3g} mm/rad, {s / chain.reach:.2%} of the chain's "
            f"reach {chain.reach:g} mm (at least {SINGULAR_SHARE:.0%} is needed)")


def home_error(chain) -> str | None:
    """A message if the home pose is near-singular (the continuation could not start), else None."""
    home = np.array([chain.home])
    s = float(smallest_singular_values(chain, home)[0])
    if s >= SINGULAR_SHARE * chain.reach:
        return None
    pose = ", ".join(f"{j.name}={j.home:g}" for j in chain.joints)
    return f"the home pose ({pose}) deg is near-singular: {_singular_message(chain, s)}; give the joints home angles off it"


def _grid(lo, hi, per_axis: int):
    axes = [np.linspace(a, b, per_axis) for a, b in zip(lo, hi)]
    return [g.ravel() for g in np.meshgrid(*axes, indexing="ij")]


def levenberg_marquardt(chain, q, goal, iters: int = LM_ITERS):
    """Levenberg-Marquardt with a per-target damping (accepted steps divide it by 3, rejected
    ones double it), then a Newton polish; returns angles (deg) and residuals (mm)."""
    q = np.array(q, dtype=np.float64)
    f, jac = chain.system(q, goal)
    cost = np.sum(f * f, axis=1)
    lam = np.full(len(q), 1e-2 * chain.reach ** 2)
    eye = np.eye(q.shape[1])
    with np.errstate(invalid="ignore", over="ignore"):
        for _ in range(iters):
            # converged targets and those whose damping has grown hopeless drop out
            live = np.flatnonzero((cost > (0.1 * TOL_MM) ** 2) & (lam < 1e12 * chain.reach ** 2))
            if not len(live):
                break
            jl, fl = jac[live], f[live]
            jt = np.swapaxes(jl, 1, 2)
            step = -np.linalg.solve(jt @ jl + lam[live, None, None] * eye, jt @ fl[..., None])[..., 0]
            qn = q[live] + np.degrees(step)
            fn, jn = chain.system(qn, goal[live])
            cn = np.sum(fn * fn, axis=1)
            better = cn < cost[live]
            b = live[better]
            q[b], f[b], jac[b], cost[b] = qn[better], fn[better], jn[better], cn[better]
            lam[live] = np.where(better, lam[live] / 3.0, lam[live] * 2.0)
        return newton(chain, q, goal, 8)[:2]


def second_solutions(chain, coords, reference):
    """Per target (flat index), a solution inside the joint ranges other than ``reference``
    (N, n) found from seeds spread over the ranges, or None; returns (index, angles) of the
    first such target or None."""
    n = len(chain.joints)
    fr = (np.arange(SEED_POINTS) + 0.5) / SEED_POINTS
    seeds = np.array(list(itertools.product(*[lo + fr * (hi - lo) for lo, hi in chain.joint_ranges])))
    goal = np.stack(chain.goal(*coords), 1)
    n_t, n_s = len(goal), len(seeds)
    q, res = levenberg_marquardt(chain, np.tile(seeds, (n_t, 1)), np.repeat(goal, n_s, axis=0))
    lo, hi = (np.array(b) for b in zip(*chain.joint_ranges))
    inside = np.all((q >= lo - ANGLE_SLACK_DEG) & (q <= hi + ANGLE_SLACK_DEG), axis=1) & (res <= TOL_MM)
    other = np.any(np.abs(q - np.repeat(reference, n_s, axis=0)) > DISTINCT_DEG, axis=1)
    hit = np.flatnonzero(inside & other)
    if not len(hit):
        return None
    return int(hit[0] // n_s), q[hit[0]].reshape(n)


def check_box(chain, lo, hi) -> None:
    """Raise :class:`ChainBoxError` (or the ``UnreachableError`` of ``chain.ik``) for the first
    grid target of the box [lo, hi] that is unreachable or on another branch than the home pose
    (from ``chain.ik``), near-singular, or has a second solution inside the joint ranges."""
    names = chain.inputs
    grid = _grid(lo, hi, BOX_GRID)
    q = np.stack(chain.ik(*grid), 1)
    s = smallest_singular_values(chain, q)
    # the first target in grid order among the least values up to rounding: symmetric targets
    # (z = -c and +c) tie, and which of them an SVD puts an ulp lower depends on the CPU's kernels
    i = int(np.flatnonzero(s <= s.min() * (1.0 + 1e-9))[0])
    if s[i] < SINGULAR_SHARE * chain.reach:
        raise ChainBoxError(f"the chain is near-singular at target {format_point(names, [g[i] for g in grid])}: "
                            f"{_singular_message(chain, float(s[i]))}; keep the box off the singular poses")
    per_axis = max(2, int((MAX_SEED_PROBLEMS / SEED_POINTS ** len(chain.joints)) ** (1 / len(names))))
    coarse = _grid(lo, hi, min(per_axis, BOX_GRID))
    found = second_solutions(chain, coarse, np.stack(chain.ik(*coarse), 1))
    if found is not None:
        i, other = found
        ref = [float(a[i]) for a in chain.ik(*coarse)]
        raise ChainBoxError(f"a second solution inside the joint ranges at target "
                            f"{format_point(names, [g[i] for g in coarse])}: {format_point(chain.servo_names, other)} "
                            f"deg besides the home branch's {format_point(chain.servo_names, ref)} deg; "
                            f"narrow the joint ranges to exclude it")
