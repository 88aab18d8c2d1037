"""Hexapod leg (coxa-femur-tibia) with a Cartesian tip target, after Wulandari et al.

Source: "Implementation of Inverse Kinematics for the Coordination Control of Six Legged
Robot" (coxa 15, femur 80, tibia 130 mm; 600-2400 us servos). Its equations survive only
in part, so the geometry is reconstructed here; see :class:`HexapodLeg` for what was
assumed and how the paper's own numbers check it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Geometry
from .joints import JointConventions
from .kinematics import NUMPY_MATH, RAD2DEG
from .reach import raise_first_unreachable

__all__ = ["HexapodLeg"]


@dataclass(frozen=True)
class HexapodLeg(JointConventions, Geometry):
    """3-DOF hexapod leg: coxa yaw, femur and tibia pitch; tip target (x, y, z) in mm.

    Frame and inputs (origin at the coxa joint, on the body underside):

    - ``x``: horizontal, outwards along the leg's rest direction (coxa angle 0);
    - ``y``: horizontal, perpendicular to ``x`` (the walking direction of a side leg);
    - ``z``: tip height above the ground, up positive. The body underside (coxa and femur
      axes) is ``body_height`` = 78 mm above the ground, so the tip lies
      ``Z_offset = body_height - z`` below the femur axis (paper eq. 5). ``z > 0`` lifts
      the foot, ``z < 0`` raises the body.

    Assumed mechanics (the paper's figures are lost): the coxa axis is vertical through
    the origin; the femur axis is horizontal, ``coxa`` mm out from it at the same height;
    the femur and tibia move in the vertical plane through the coxa axis; knee up.

    Joint angles (degrees, the paper's geometric angles). With
    ``rho = hypot(x, y) - coxa`` (plan distance of the tip from the femur axis),
    ``h = body_height - z`` and ``L = hypot(rho, h)`` (femur axis to tip):

    - ``s1`` coxa ``= atan2(y, x)`` (eq. 1): odd in ``y``, independent of ``z``;
    - ``s2`` femur ``= 90 - (A1 + A2)`` (eq. 6) with ``A1 = atan2(rho, h)`` (the tip line
      from the downward vertical) and ``A2 = acos((femur^2 + L^2 - tibia^2) / (2 femur L))``
      (femur to tip line): the femur's angle *below* the horizontal, so a raised femur is
      negative;
    - ``s3`` tibia ``= 90 - A3`` (eq. 7) with ``A3 = acos((femur^2 + tibia^2 - L^2) /
      (2 femur tibia))`` the knee's interior angle: 0 with the tibia at right angles to
      the femur, positive as the knee folds.

    ``s2`` and ``s3`` depend on (x, y) only through ``hypot(x, y)`` (even in ``y``), ``s3``
    only through ``L``.

    Joint ranges (paper, Table 1): coxa -90..90, femur -90..90, tibia 0..90 deg; targets
    needing a joint outside them are unreachable. These are the defaults of the
    ``joint_ranges`` field; ``zero_offsets`` and ``angle_directions`` (default 0 and +1) turn
    the angles above into the servos' own (:mod:`ikseries.joints`), which ``ik``, ``angles``
    and ``fk`` use.

    Reconstruction check: the paper zeroes its servos by subtracting 54.85 deg from the
    femur angle and 41.33 deg from the tibia angle at the standing pose. Both numbers are
    reproduced to 0.01 deg at (x, y, z) = (74, 0, 0) mm, i.e. the tip 59 mm out from the
    femur axis on the ground: ``s3 = 41.33`` from eq. 7 as above, and ``|s2| = 54.85``
    only if ``A1`` is taken as ``atan(L / Z_offset)`` with the femur-to-tip length ``L``
    (the paper's eq. 2 as printed). That mixes a slant length with a vertical one and is
    not the angle of the tip line; the true femur angle there is -40.53 deg, which is
    what this class computes (FK-consistent). The standing pose (74, 0, 0) is the neutral
    pose of the ``hexapod-leg`` preset, so the servo zeros sit where the paper puts them.

    Preset workspace (``hexapod-leg``): x 54..94, y -40..40, z -20..30 mm, a box around
    the standing pose: +-20 mm in and out, an 80 mm stride, 30 mm foot lift and 20 mm body
    raise. Over it the joints stay within coxa -36.5..36.5, femur -81.5..-19.6 and tibia
    17.0..69.4 deg, inside Table 1 with margin; the femur's -90 deg limit is what bounds
    the lift (40 mm of lift close to the body would need it). Calibration as in the paper:
    1500 us (3000 pu) at the standing pose, 10 us (20 pu) per degree, 600..2400 us.
    """

    coxa: float = 15.0
    femur: float = 80.0
    tibia: float = 130.0
    body_height: float = 78.0

    coordinates = "cartesian"
    inputs = ("x", "y", "z")
    input_units = ("mm", "mm", "mm")
    servos = ("s1", "s2", "s3")
    servo_names = ("coxa", "femur", "tibia")
    #: Inclusive joint ranges in degrees, per servo (paper, Table 1).
    default_joint_ranges = ((-90.0, 90.0), (-90.0, 90.0), (0.0, 90.0))

    # -- inverse kinematics ------------------------------------------------
    def angles(self, xp, x, y, z):
        """Pure IK formula (no reachability checks) over the math namespace ``xp``.

        Uses only ``+ - * /``, integer powers, constants and ``xp.sqrt / atan2 / acos``,
        so it also runs on interval numbers (see ``CylinderLeg.angles``).

        Returns
        -------
        s1, s2, s3
            Coxa, femur and tibia servo angles in degrees (the angles of the class docstring
            under the joint conventions).
        """
        f, t = self.femur, self.tibia
        rho = xp.sqrt(x * x + y * y) - self.coxa
        h = self.body_height - z
        d2 = rho * rho + h * h
        d = xp.sqrt(d2)
        s1 = xp.atan2(y, x) * RAD2DEG
        s2 = 90.0 - (xp.atan2(rho, h) + xp.acos((f * f + d2 - t * t) / (2 * f * d))) * RAD2DEG
        s3 = 90.0 - xp.acos((f * f + t * t - d2) / (2 * f * t)) * RAD2DEG
        return self.servo_angles((s1, s2, s3))

    def ik(self, x, y, z):
        """Servo angles (s1, s2, s3) in degrees for tip targets (vectorised).

        Raises
        ------
        UnreachableError
            Naming the first target (C order) out of the femur-tibia reach or needing a
            joint beyond :attr:`joint_ranges`.
        """
        x, y, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, y, z)))
        f, t = self.femur, self.tibia
        d = np.ravel(np.hypot(np.hypot(x, y) - self.coxa, self.body_height - z))
        with np.errstate(invalid="ignore", divide="ignore"):
            a = self.angles(NUMPY_MATH, x, y, z)
            finite = np.logical_and.reduce([np.isfinite(np.ravel(s)) for s in a])
            reach = ~((d >= abs(f - t)) & (d <= f + t) & (d > 0) & finite)
        raise_first_unreachable(self.inputs, (x, y, z), [
            (reach, lambda i: f"tip distance from the femur axis {d[i]:.6g} mm must be within "
                              f"[{abs(f - t):g}, {f + t:g}] mm"),
            *self.range_checks(a)])
        return a

    # -- forward kinematics ------------------------------------------------
    def fk(self, s1, s2, s3):
        """Tip (x, y, z) in mm for servo angles in degrees (the inverse of :meth:`ik`)."""
        kinematic = self.kinematic_angles((s1, s2, s3))
        a1, a2, a3 = (np.radians(np.asarray(a, dtype=np.float64)) for a in kinematic)
        # Leg plane: u outwards from the femur axis, v downwards. The femur points a2 below
        # the horizontal; the knee turns the tibia a further 90 deg + a3 downwards.
        knee = a2 + np.pi / 2 + a3
        u = self.femur * np.cos(a2) + self.tibia * np.cos(knee)
        v = self.femur * np.sin(a2) + self.tibia * np.sin(knee)
        rho = self.coxa + u
        return rho * np.cos(a1), rho * np.sin(a1), self.body_height - v
