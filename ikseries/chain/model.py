"""The ``chain`` geometry: a serial chain of revolute joints, its FK and its numeric IK."""
from __future__ import annotations

import math
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
    (:mod:`ikseries.chain.checks`). ``kinematics(xp, *servo_angles)`` and ``jacobian`` are
    pure formulas over a math namespace, for an interval enclosure of the IK.
    """

    joints: tuple[Joint, ...]
    tip: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target: str = "xyz"
    neutral: tuple[float, float, float] | None = None
    tool: Tool | None = None

    coordinates = "cartesian"
    #: ``angles`` runs on float64 only: the certifier cannot evaluate it on intervals
    numeric_ik = True

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
        th = [(a - j.zero_offset) * DEG2RAD for a, j in zip(angles, self.joints)]
        tip, _, axes, origins = frames.forward(xp, self.joints, self.tip, th)
        return tip, frames.jacobian(tip, axes, origins)

    def goal(self, *coords):
        """The solved quantities of targets: the fixed tip coordinates (mm) and, with a tool
        constraint, its angle (deg), as float arrays of one shape."""
        coords = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in coords))
        if self.target == "cylindrical":
            r, th, z = coords[:3]
            nx, ny, nz = self.neutral
            t = np.radians(th)
            pos = [nx + r * np.cos(t), ny + r * np.sin(t), nz + z]
        else:
            pos = list(coords[:len(self.target)])
        if self.tool is not None:
            pos.append(coords[-1] if self.tool_input else np.full(coords[0].shape, self.tool.angle))
        return pos

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

    def measure(self, q_deg) -> np.ndarray:
        """The solved quantities (N, m) of servo angles ``q_deg`` (N, n): the fixed tip
        coordinates (mm) and the tool angle (deg)."""
        tip, _ = self.kinematics(NUMPY_MATH, *q_deg.T)
        out = [np.broadcast_to(tip[k], q_deg.shape[:1]) for k in self.tip_axes]
        if self.tool is not None:
            offsets = np.array([j.zero_offset for j in self.joints])
            out.append((q_deg - offsets) @ self._tool_mask())
        return np.stack(out, 1)

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
        """The continued Newton solution of targets (no range check); see :func:`solve.continued`."""
        return solve.continued(self, self.goal(*coords))

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
        """The reference IK as :meth:`ik` without its checks (NaN where it fails) under
        ``NUMPY_MATH``. A numeric IK is no formula: over any other namespace (intervals) this
        raises, since enclosing it needs an interval Newton step per cell."""
        if xp is not NUMPY_MATH:
            raise TypeError("a chain geometry's IK is numeric (Newton), not a formula: it can be evaluated "
                            "on float64 arrays only, not over the math namespace "
                            f"{getattr(xp, '__name__', type(xp).__name__)} (an interval enclosure "
                            "needs an interval Newton step per cell)")
        coords = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in coords))
        sol = self.solve(*coords)
        q = np.where(sol.ok[:, None], sol.angles, np.nan)
        return tuple(a.reshape(coords[0].shape) for a in q.T)

    def check_box(self, lo, hi) -> None:
        """The workspace check of a robot description (:func:`ikseries.chain.checks.check_box`)."""
        from .checks import check_box
        check_box(self, lo, hi)
