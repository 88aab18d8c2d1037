"""The ``chain`` geometry: a serial chain of revolute joints, its FK and its numeric IK."""
from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..geometry import Geometry
from ..kinematics import NUMPY_MATH, UnreachableError
from ..joints import joint_range_checks
from ..reach import raise_first_unreachable
from . import frames, solve

__all__ = ["Joint", "Tool", "Chain", "TARGETS", "DEG2RAD"]

DEG2RAD = math.pi / 180.0
#: geometry.target values: the tip coordinates a target gives (a subset of the base frame's
#: x, y, z), or "cylindrical": (r, theta, z) around the chain's neutral point
TARGETS = ("xyz", "xy", "xz", "yz", "cylindrical")
#: goal sets whose continued Newton solutions :meth:`Chain.solve` keeps (most recent first out last)
SOLVED_SETS = 4
_SOLVED: OrderedDict = OrderedDict()      # (chain, shape, SHA-256 of the goals) -> Solution
_SOLVED_LOCK = threading.Lock()           # the cache is the process's: threads share it


@dataclass(frozen=True)
class Joint:
    """One revolute joint: its frame is the previous joint's frame (the base frame for the
    first) moved by ``xyz`` (mm) and turned by ``rpy`` (deg, URDF roll-pitch-yaw); it turns
    by ``angle - zero_offset`` (deg) about the unit ``axis`` of its frame: ``zero_offset`` is the
    servo angle where the joint is at its frame's zero (the horn offset, as the closed forms'
    ``zero_offsets``: servo angle = kinematic angle + offset). ``range`` bounds
    the angle (deg, inclusive); ``home`` (deg, in range) is the pose the IK continues from."""
    name: str
    axis: tuple[float, float, float]
    range: tuple[float, float]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    zero_offset: float = 0.0
    home: float = 0.0

    def __post_init__(self):
        for f in ("axis", "range", "xyz", "rpy"):      # a record gives lists
            object.__setattr__(self, f, tuple(float(v) for v in getattr(self, f)))

    @property
    def origin_rotation(self):
        return frames.rpy_matrix(self.rpy)


@dataclass(frozen=True)
class Tool:
    """The constraint of a chain with one joint more than its target has coordinates: the sum
    of the named joints' rotations (angle - zero offset, deg) is ``angle`` — for joints turning
    about parallel axes, the tool's angle in their plane — or, with ``angle`` None, the
    target input ``phi``."""
    joints: tuple[str, ...]
    angle: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(self.joints))


def _as(cls, v):
    return v if isinstance(v, cls) or v is None else cls(**v)


@dataclass(frozen=True)
class Chain(Geometry):
    """A serial chain of revolute joints from the base to the tip, with a numeric reference IK.

    The target frame is the base frame (the first joint's ``xyz``/``rpy`` place that joint in
    it). ``target`` names the tip coordinates a target gives (:data:`TARGETS`); with
    "cylindrical" the inputs are ``(r, theta, z)`` around ``neutral`` (mm): ``x = nx + r
    cos(theta)``, ``y = ny + r sin(theta)``, ``z = nz + z``. A ``tool`` constraint takes the
    extra degree of a chain with one joint more than target coordinates.

    ``fk`` is exact (homogeneous transforms in float64). ``ik`` is damped Newton continued
    along the straight line in target space from the home pose's tip to each target, so every
    solution is on the home pose's branch (:mod:`ikseries.chain.solve`); it raises
    :class:`UnreachableError` for a target it cannot reach on that branch or whose joint
    leaves its range. ``check_box`` is the workspace check of a robot description
    (:mod:`ikseries.chain.checks`). ``kinematics``, ``measure_rows``, ``derivatives`` and
    ``goal_rows`` are pure formulas over a math namespace, for the interval enclosure of the IK
    that ``angles`` gives the certifier (:mod:`ikseries.chain.enclose`).
    """

    joints: tuple[Joint, ...]
    tip: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target: str = "xyz"
    neutral: tuple[float, float, float] | None = None
    tool: Tool | None = None

    coordinates = "cartesian"

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(_as(Joint, j) for j in self.joints))
        object.__setattr__(self, "tip", tuple(float(v) for v in self.tip))
        object.__setattr__(self, "tool", _as(Tool, self.tool))
        if self.neutral is not None:
            object.__setattr__(self, "neutral", tuple(float(v) for v in self.neutral))
        if len(self.goal_names) != len(self.joints):     # the parser says so first, naming the fields
            raise ValueError(f"joints: a chain needs one joint per solved quantity {self.goal_names}, "
                             f"not {len(self.joints)}")

    # -- the interface's names --------------------------------------------------------------
    @property
    def tip_axes(self) -> tuple[int, ...]:
        """Base-frame axes (0 x, 1 y, 2 z) of the tip coordinates a target fixes."""
        return (0, 1, 2) if self.target == "cylindrical" else tuple("xyz".index(c) for c in self.target)

    @property
    def tool_input(self) -> bool:
        return self.tool is not None and self.tool.angle is None

    @property
    def inputs(self) -> tuple[str, ...]:
        names = ("r", "theta", "z") if self.target == "cylindrical" else tuple(self.target)
        return names + (("phi",) if self.tool_input else ())

    @property
    def input_units(self) -> tuple[str, ...]:
        return tuple("deg" if n in ("theta", "phi") else "mm" for n in self.inputs)

    @property
    def servos(self) -> tuple[str, ...]:
        return tuple(f"s{i + 1}" for i in range(len(self.joints)))

    @property
    def servo_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def joint_ranges(self) -> tuple[tuple[float, float], ...]:
        return tuple(j.range for j in self.joints)

    @property
    def home(self) -> tuple[float, ...]:
        return tuple(j.home for j in self.joints)

    @property
    def reach(self) -> float:
        """Sum of the link lengths (mm): the scale of the singularity check and of the
        tool-angle residual."""
        return sum(math.hypot(*j.xyz) for j in self.joints[1:]) + math.hypot(*self.tip) or 1.0

    # -- pure formulas ------------------------------------------------------------------------
    def kinematics(self, xp, *angles):
        """Tip position (base frame, mm) and Jacobian columns (mm per rad, one per joint) of
        servo angles (deg, xp values), as formulas over the math namespace ``xp``."""
        tip, _, axes, origins = frames.forward(xp, self.joints, self.tip, self._thetas(angles))
        return tip, frames.jacobian(tip, axes, origins)

    def goal_rows(self, xp, *coords):
        """The solved quantities of targets as formulas over the math namespace ``xp``: the
        fixed tip coordinates (mm) and, with a tool constraint, its angle (deg; a float where
        it is fixed)."""
        if self.target == "cylindrical":
            r, th, z = coords[:3]
            nx, ny, nz = self.neutral
            t = th * DEG2RAD
            pos = [nx + r * xp.cos(t), ny + r * xp.sin(t), nz + z]
        else:
            pos = list(coords[:len(self.target)])
        if self.tool is not None:
            pos.append(coords[-1] if self.tool_input else self.tool.angle)
        return pos

    def goal(self, *coords):
        """:meth:`goal_rows` of float targets, as float arrays of one shape."""
        coords = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in coords))
        return [np.broadcast_to(np.asarray(v, dtype=np.float64), coords[0].shape)
                for v in self.goal_rows(NUMPY_MATH, *coords)]

    @property
    def goal_names(self) -> tuple[str, ...]:
        """Names of the solved quantities: the fixed tip coordinates and the tool angle."""
        return tuple("xyz"[k] for k in self.tip_axes) + (("phi",) if self.tool is not None else ())

    @property
    def row_scale(self) -> np.ndarray:
        """Per solved quantity, mm per unit: 1 for a tip coordinate, the arc of one degree at
        :attr:`reach` for the tool angle (so that every residual row is in mm)."""
        return np.array([1.0] * len(self.tip_axes) + ([DEG2RAD * self.reach] if self.tool is not None else []))

    def _tool_mask(self) -> np.ndarray:
        names = self.tool.joints if self.tool is not None else ()
        return np.array([j.name in names for j in self.joints], dtype=np.float64)

    def _thetas(self, angles):
        return [(a - j.zero_offset) * DEG2RAD for a, j in zip(angles, self.joints)]

    def _tool_angle(self, angles):
        return sum(a - j.zero_offset for a, j in zip(angles, self.joints) if j.name in self.tool.joints)

    def measure_rows(self, xp, *angles):
        """The solved quantities of servo angles (deg, xp values) as formulas over ``xp``: the
        fixed tip coordinates (mm) and the tool angle (deg)."""
        tip = frames.forward(xp, self.joints, self.tip, self._thetas(angles))[0]
        rows = [tip[k] for k in self.tip_axes]
        if self.tool is not None:
            rows.append(self._tool_angle(angles))
        return rows

    def derivatives(self, xp, *angles):
        """:meth:`measure_rows`, their Jacobian (rows x joints, per deg) and their second
        derivatives (rows x joint pairs in the order of ``numpy.triu_indices``, per deg**2) as
        formulas over ``xp`` (the tool angle's are 1 for its joints and 0)."""
        tip, _, axes, origins = frames.forward(xp, self.joints, self.tip, self._thetas(angles))
        cols = frames.jacobian(tip, axes, origins)
        n = len(self.joints)
        pairs = list(zip(*(a.tolist() for a in np.triu_indices(n))))
        hess = frames.hessian(axes, cols, pairs)
        d2 = DEG2RAD * DEG2RAD
        rows = [tip[k] for k in self.tip_axes]
        jac = [[c[k] * DEG2RAD for c in cols] for k in self.tip_axes]
        second = [[h[k] * d2 for h in hess] for k in self.tip_axes]
        if self.tool is not None:
            rows.append(self._tool_angle(angles))
            jac.append([float(j.name in self.tool.joints) for j in self.joints])
            second.append([0.0] * len(pairs))
        return rows, jac, second

    def measure(self, q_deg) -> np.ndarray:
        """:meth:`measure_rows` (N, m) of servo angles ``q_deg`` (N, n)."""
        return np.stack([np.broadcast_to(v, q_deg.shape[:1]) for v in self.measure_rows(NUMPY_MATH, *q_deg.T)], 1)

    def system(self, q_deg, goal):
        """Residual (N, m, mm; see :attr:`row_scale`) and Jacobian (N, m, n, mm per rad) of
        the goals ``goal`` (N, m) at servo angles ``q_deg`` (N, n)."""
        tip, cols = self.kinematics(NUMPY_MATH, *q_deg.T)
        shape = q_deg.shape[:1]
        rows = [np.broadcast_to(tip[k], shape) for k in self.tip_axes]
        jac = [np.stack([np.broadcast_to(c[k], shape) for c in cols], 1) for k in self.tip_axes]
        if self.tool is not None:
            offsets = np.array([j.zero_offset for j in self.joints])
            rows.append((q_deg - offsets) @ self._tool_mask())
            jac.append(np.broadcast_to(self._tool_mask() * self.row_scale[-1] / DEG2RAD, q_deg.shape))
        scale = self.row_scale
        return (np.stack(rows, 1) - goal) * scale, np.stack(jac, 1)

    # -- the Geometry interface ---------------------------------------------------------------
    def fk(self, *angles):
        """Target coordinates (in the order of :attr:`inputs`) of servo angles (deg)."""
        a = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in angles))
        tip, _ = self.kinematics(NUMPY_MATH, *a)
        tip = [np.broadcast_to(t, a[0].shape).astype(np.float64) for t in tip]
        if self.target == "cylindrical":
            nx, ny, nz = self.neutral
            out = [np.hypot(tip[0] - nx, tip[1] - ny), np.degrees(np.arctan2(tip[1] - ny, tip[0] - nx)),
                   tip[2] - nz]
        else:
            out = [tip[k] for k in self.tip_axes]
        if self.tool_input:
            out.append(sum(a[i] - j.zero_offset for i, j in enumerate(self.joints) if j.name in self.tool.joints))
        return tuple(out)

    def solve(self, *coords) -> solve.Solution:
        """The continued Newton solution of targets (no range check); see :func:`solve.continued`.

        The solutions of the last few goal sets are kept (:data:`SOLVED_SETS`): a fit asks for
        the IK of its sample sets more than once (the reference pulses, then the features of
        every candidate variable set), and each answer is a copy of the one solve."""
        goal = self.goal(*coords)
        key = (self, np.shape(goal), hashlib.sha256(np.ascontiguousarray(goal).tobytes()).digest())
        with _SOLVED_LOCK:
            hit = _SOLVED.get(key)
            if hit is not None:
                _SOLVED.move_to_end(key)
                return hit.copy()
        sol = solve.continued(self, goal)
        with _SOLVED_LOCK:
            _SOLVED[key] = sol
            while len(_SOLVED) > SOLVED_SETS:
                _SOLVED.popitem(last=False)
        return sol.copy()

    def ik(self, *coords):
        """Servo angles (deg) per joint for target arrays, on the home pose's branch.

        Raises
        ------
        UnreachableError
            Naming the first target (C order) the continuation does not reach to 1e-9 mm, or
            whose path from the home pose crosses a singular pose, or whose joint leaves its range.
        """
        coords = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in coords))
        sol = self.solve(*coords)
        angles = [a.reshape(coords[0].shape) for a in sol.angles.T]
        raise_first_unreachable(self.inputs, coords, [
            *sol.checks(), *joint_range_checks(angles, self.servo_names, self.joint_ranges, "geometry.joints[{k}].range")])
        return tuple(angles)

    def angles(self, xp, *coords):
        """The reference IK: under ``NUMPY_MATH`` as :meth:`ik` without its checks (NaN where it
        fails); under the certifier's namespaces ``ikseries.fit.interval.MATH`` and
        ``ikseries.fit.centred.MATH`` a proven enclosure over the cells of the input numbers,
        with derivatives (a Krawczyk step per cell, :mod:`ikseries.chain.enclose`)."""
        from ..fit import centred as cn
        from ..fit import interval as ia
        if xp is ia.MATH or xp is cn.MATH:
            from .enclose import enclosed_angles
            return enclosed_angles(self, xp, coords)
        if xp is not NUMPY_MATH:
            raise TypeError("a chain geometry's IK is numeric (Newton): it is evaluated on float64 arrays "
                            "(NUMPY_MATH) or enclosed over intervals (ikseries.fit.interval.MATH, "
                            "ikseries.fit.centred.MATH), not over the math namespace "
                            f"{getattr(xp, '__name__', type(xp).__name__)}")
        coords = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in coords))
        sol = self.solve(*coords)
        q = np.where(sol.ok[:, None], sol.angles, np.nan)
        return tuple(a.reshape(coords[0].shape) for a in q.T)

    def check_box(self, lo, hi) -> None:
        """The workspace check of a robot description (:func:`ikseries.chain.checks.check_box`)."""
        from .checks import check_box
        check_box(self, lo, hi)
