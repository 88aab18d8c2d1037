"""Reference inverse and forward kinematics (float64); the servo calibration is :mod:`ikseries.calibration`.

Everything here is vectorised over numpy arrays and is the ground truth the
fitted integer series is measured against.

Angles are in degrees, lengths in millimetres, pulses in pulse units (pu).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from .geometry import CylindricalGeometry
from .joints import JointConventions

__all__ = ["UnreachableError", "CylinderLeg", "NUMPY_MATH", "RAD2DEG", "format_point"]

RAD2DEG = 180.0 / np.pi

#: The math namespace of the pure IK formulas (``Geometry.angles(xp, ...)``): float64 numpy.
#: An interval / derivative namespace with the same names (``sqrt, atan2, acos, asin, cos,
#: sin``) evaluates the same formula rigorously over a cell (see ``fit/certify.py``).
NUMPY_MATH = SimpleNamespace(sqrt=np.sqrt, atan2=np.arctan2, acos=np.arccos, asin=np.arcsin,
                             cos=np.cos, sin=np.sin)


class UnreachableError(ValueError):
    """A tip target that the leg cannot reach."""


def format_point(names, values):
    return "(" + ", ".join(f"{n}={float(v):g}" for n, v in zip(names, values)) + ")"


@dataclass(frozen=True)
class CylinderLeg(JointConventions, CylindricalGeometry):
    """3-DOF coxa-femur-tibia leg with a cylindrical tip target (R, theta, Z).

    The coxa (S1) axis is vertical through the origin. The tip's plan position
    is ``x = D + R cos(theta)``, ``y = R sin(theta)``; Z is depth below the Z
    datum (positive downwards), which lies ``z_datum`` below the femur (S2) axis.

    Joint angles: ``S1 = atan2(y, x)``; with ``u = hypot(x, y) - coxa`` and
    ``v = z_datum + Z``, ``d = hypot(u, v)``:
    ``S2 = acos((f^2 + d^2 - t^2) / (2 f d)) - atan2(v, u)`` (femur elevation,
    knee up) and ``S3 = 180 - acos((f^2 + t^2 - d^2) / (2 f t))`` (knee bend,
    0 = straight). ``ik``, ``angles`` and ``fk`` use these under the joint conventions
    (:mod:`ikseries.joints`: ``zero_offsets``, ``angle_directions``); the joints have no
    range unless ``joint_ranges`` gives one.
    """

    coxa: float = 30.0
    femur: float = 60.0
    tibia: float = 90.0
    neutral_distance: float = 100.0
    z_datum: float = 50.0

    coordinates = "cylindrical"
    inputs = ("r", "theta", "z")
    input_units = ("mm", "deg", "mm")
    servos = ("s1", "s2", "s3")
    servo_names = ("coxa", "femur", "tibia")
    cartesian_names = ("x", "y", "z")

    def workspace_error(self, name, lo, hi):
        """Message for a workspace range ``[lo, hi]`` of input ``name`` this leg cannot take, else None."""
        if name == "theta" and (lo < -180 or hi > 180):
            return f"workspace.theta must lie within [-180, 180] deg, not [{lo!r}, {hi!r}]"
        if name == "r" and lo < 0:
            return f"workspace.r.min must be >= 0 mm, not {lo!r}"
        return None

    # -- coordinate maps ---------------------------------------------------
    def to_cartesian(self, r, theta, z):
        """Cylindrical target -> plan position (x, y) and depth Z."""
        th = np.radians(np.asarray(theta, dtype=np.float64))
        r = np.asarray(r, dtype=np.float64)
        return (self.neutral_distance + r * np.cos(th), r * np.sin(th),
                np.asarray(z, dtype=np.float64) + 0.0 * r)

    def from_cartesian(self, x, y, z):
        """Plan position and depth -> cylindrical target (R, theta, Z)."""
        dx = np.asarray(x, dtype=np.float64) - self.neutral_distance
        y = np.asarray(y, dtype=np.float64)
        return np.hypot(dx, y), np.degrees(np.arctan2(y, dx)), np.asarray(z, dtype=np.float64)

    # -- inverse kinematics ------------------------------------------------
    def angles(self, xp, r, theta, z):
        """Pure IK formula (no reachability checks) over the math namespace ``xp``.

        Uses only ``+ - * /``, integer powers, constants and ``xp.sqrt / atan2 / acos /
        cos / sin``, so the same code runs on float arrays (``NUMPY_MATH``) and on
        interval-with-derivative numbers for the certified bound. Angles in degrees.
        """
        th = theta * (1.0 / RAD2DEG)
        x = self.neutral_distance + r * xp.cos(th)
        y = r * xp.sin(th)
        return self.angles_cartesian(xp, x, y, z)

    def angles_cartesian(self, xp, x, y, z):
        """Pure IK formula for the tip (x, y, Z); see :meth:`angles`."""
        f, t = self.femur, self.tibia
        u = xp.sqrt(x * x + y * y) - self.coxa
        v = self.z_datum + z
        d2 = u * u + v * v
        d = xp.sqrt(d2)
        s1 = xp.atan2(y, x) * RAD2DEG
        s2 = (xp.acos((f * f + d2 - t * t) / (2 * f * d)) - xp.atan2(v, u)) * RAD2DEG
        s3 = 180.0 - xp.acos((f * f + t * t - d2) / (2 * f * t)) * RAD2DEG
        return self.servo_angles((s1, s2, s3))

    def ik_cartesian(self, x, y, z):
        """Servo angles (S1, S2, S3) in degrees for tip (x, y, Z).

        Raises
        ------
        UnreachableError
            Naming the first point (C order) outside the reachable annulus of the femur-tibia
            pair or needing a joint beyond ``joint_ranges``.
        """
        from .reach import raise_first_unreachable   # reach imports this module
        x, y, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, y, z)))
        f, t = self.femur, self.tibia
        s1 = np.degrees(np.arctan2(y, x))
        u = np.hypot(x, y) - self.coxa
        v = self.z_datum + z
        d = np.hypot(u, v)
        c2 = (f * f + d * d - t * t) / (2 * f * np.where(d > 0, d, 1.0))
        c3 = (f * f + t * t - d * d) / (2 * f * t)
        bad = (d <= 0) | (np.abs(c2) > 1) | (np.abs(c3) > 1) | ~np.isfinite(d)
        with np.errstate(invalid="ignore"):
            s2 = np.degrees(np.arccos(c2) - np.arctan2(v, u))
            s3 = 180.0 - np.degrees(np.arccos(c3))
        a = self.servo_angles((s1, s2, s3))
        raise_first_unreachable(self.cartesian_names, (x, y, z), [
            (bad, lambda i: f"tip distance from the femur axis {np.ravel(d)[i]:.6g} mm must be within "
                            f"[{abs(f - t):g}, {f + t:g}] mm"),
            *self.range_checks(a)])
        return a

    def ik(self, r, theta, z):
        """Servo angles (S1, S2, S3) in degrees for the cylindrical target (R, theta, Z)."""
        try:
            return self.ik_cartesian(*self.to_cartesian(r, theta, z))
        except UnreachableError:
            r, theta, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (r, theta, z)))
            x, y, zz = self.to_cartesian(r, theta, z)
            for idx in np.ndindex(r.shape):
                try:
                    self.ik_cartesian(x[idx], y[idx], zz[idx])
                except UnreachableError as e:
                    pt = (r[idx], theta[idx], z[idx])
                    raise UnreachableError(
                        f"target {format_point(self.inputs, pt)} is unreachable: "
                        + str(e).split(": ", 1)[1]) from None
            raise

    # -- forward kinematics ------------------------------------------------
    def fk_cartesian(self, s1, s2, s3):
        """Tip (x, y, Z) for servo angles in degrees."""
        kinematic = self.kinematic_angles((s1, s2, s3))
        a1, a2, a3 = (np.radians(np.asarray(a, dtype=np.float64)) for a in kinematic)
        # In the leg plane: u outwards from the femur axis, v downwards.
        u = self.femur * np.cos(-a2) + self.tibia * np.cos(a3 - a2)
        v = self.femur * np.sin(-a2) + self.tibia * np.sin(a3 - a2)
        rho = u + self.coxa
        return rho * np.cos(a1), rho * np.sin(a1), v - self.z_datum

    def fk(self, s1, s2, s3):
        """Cylindrical tip target (R, theta, Z) for servo angles in degrees."""
        return self.from_cartesian(*self.fk_cartesian(s1, s2, s3))
