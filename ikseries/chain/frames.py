"""Forward kinematics of a serial chain of revolute joints as pure formulas over a math namespace.

A pose is a rotation (3 x 3 nested lists) and a position (3-list) whose entries are floats
(constants) or values of a math namespace ``xp`` (``xp.cos``, ``xp.sin``): float64 arrays
under :data:`ikseries.kinematics.NUMPY_MATH`, intervals under ``ikseries.fit.interval.MATH``.
Products with a constant exact zero are skipped, so an axis along a frame axis costs no
arithmetic and an interval evaluation is not widened by terms that are exactly 0.

Joint angles here are the joints' rotations in radians (the servo angle plus the zero
offset, converted): :class:`ikseries.chain.Chain` does that conversion.
"""
from __future__ import annotations

import math

__all__ = ["rpy_matrix", "matrix_rpy", "forward", "jacobian", "hessian"]


def rpy_matrix(rpy_deg) -> list[list[float]]:
    """Rotation of URDF roll-pitch-yaw angles (deg): ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = (math.radians(float(a)) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr]]


def matrix_rpy(m) -> tuple[float, float, float]:
    """Roll-pitch-yaw angles (deg) of a rotation matrix (the inverse of :func:`rpy_matrix`)."""
    pitch = math.atan2(-m[2][0], math.hypot(m[0][0], m[1][0]))
    if math.hypot(m[0][0], m[1][0]) < 1e-12:        # gimbal lock: roll and yaw share one axis
        return 0.0, math.degrees(pitch), math.degrees(math.atan2(-m[0][1], m[1][1]))
    return (math.degrees(math.atan2(m[2][1], m[2][2])), math.degrees(pitch),
            math.degrees(math.atan2(m[1][0], m[0][0])))


def _zero(v) -> bool:
    return isinstance(v, float) and v == 0.0


def _dot(a, b):
    terms = [x * y for x, y in zip(a, b) if not (_zero(x) or _zero(y))]
    if not terms:
        return 0.0
    s = terms[0]
    for t in terms[1:]:
        s = s + t
    return s


def _matvec(m, v):
    return [_dot(row, v) for row in m]


def _matmul(a, b):
    cols = [[b[k][j] for k in range(3)] for j in range(3)]
    return [[_dot(row, c) for c in cols] for row in a]


def _add(a, b):
    return [x if _zero(y) else y if _zero(x) else x + y for x, y in zip(a, b)]


def _axis_rotation(xp, axis, angle):
    """Rotation by ``angle`` (rad, an xp value) about the unit ``axis`` (floats): Rodrigues."""
    c, s = xp.cos(angle), xp.sin(angle)
    v = 1.0 - c
    x, y, z = (float(a) for a in axis)

    def term(k_v, k_s, diag):
        parts = ([c] if diag else []) + ([v * k_v] if k_v else []) + ([s * k_s] if k_s else [])
        return _sum(parts) if parts else 0.0
    return [[term(x * x, 0.0, True), term(x * y, -z, False), term(x * z, y, False)],
            [term(y * x, z, False), term(y * y, 0.0, True), term(y * z, -x, False)],
            [term(z * x, -y, False), term(z * y, x, False), term(z * z, 0.0, True)]]


def _sum(parts):
    s = parts[0]
    for t in parts[1:]:
        s = s + t
    return s


def forward(xp, joints, tip, thetas):
    """Tip position, tip rotation and each joint's axis and origin in the base frame.

    Parameters
    ----------
    xp : namespace
        Math namespace with ``cos`` and ``sin``.
    joints : sequence
        Per joint: ``origin_rotation`` (3 x 3 floats), ``xyz`` (mm) relative to the previous
        joint's frame, and the unit ``axis`` in the joint's own frame.
    tip : sequence of 3 float
        Tip point (mm) in the last joint's frame.
    thetas : sequence
        Joint rotations in radians (xp values), one per joint.

    Returns
    -------
    tip_position, tip_rotation, axes, origins
        ``axes[i]`` and ``origins[i]``: joint ``i``'s axis and a point on it, base frame.
    """
    rot = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    pos = [0.0, 0.0, 0.0]
    axes, origins = [], []
    for j, th in zip(joints, thetas):
        pos = _add(pos, _matvec(rot, j.xyz))
        rot = _matmul(rot, j.origin_rotation)
        axes.append(_matvec(rot, j.axis))
        origins.append(pos)
        rot = _matmul(rot, _axis_rotation(xp, j.axis, th))
    return _add(pos, _matvec(rot, tip)), rot, axes, origins


def _cross(a, d):
    return [_dot([a[1], -a[2]], [d[2], d[1]]), _dot([a[2], -a[0]], [d[0], d[2]]), _dot([a[0], -a[1]], [d[1], d[0]])]


def jacobian(tip_position, axes, origins):
    """Columns ``axis_i x (tip - origin_i)`` (mm per rad) of the tip position's Jacobian."""
    return [_cross(a, [p if _zero(q) else p - q for p, q in zip(tip_position, o)]) for a, o in zip(axes, origins)]


def hessian(axes, columns, pairs):
    """Second derivatives (mm per rad**2) of the tip position, one 3-list per joint pair
    ``(j, k)`` of ``pairs`` (j <= k): ``axis_j x column_k``. Turning joint j <= k turns axis k,
    the tip and origin k about axis j, so it changes ``column_k = axis_k x (tip - origin_k)``
    by ``(axis_j x axis_k) x (tip - origin_k) + axis_k x (axis_j x (tip - origin_k))``, which
    is ``axis_j x column_k`` (the Jacobi identity)."""
    return [_cross(axes[j], columns[k]) for j, k in pairs]
