"""Planar 3R arm with the tool orientation held constant: reference IK and FK (float64).

The arm moves in the (x, y) plane. Link 1 (length ``l1``) turns about the origin, link 2
(``l2``) about the elbow, link 3 (the tool, ``l3``) about the wrist; the tool keeps the
fixed orientation ``phi`` (degrees from +x), so the wrist is at
``(x - l3 cos phi, y - l3 sin phi)`` for a tool tip at ``(x, y)`` and the first two links
solve a 2R problem for the wrist.

Outputs are the **absolute** angles of link 1 and link 2 measured counter-clockwise from
the +x axis, in degrees in ``[0, 360)`` (link 3's absolute angle is ``phi``). Of the two
2R solutions the one with link 2 turned clockwise from link 1 is taken:
``s2 - s1`` lies in ``(-180, 0)`` modulo 360 (the elbow is to the left of the
shoulder-to-wrist line).

Lengths are the source's "units" (the preset calls them mm); angles are in degrees. The
servos see these angles under the joint conventions (:mod:`ikseries.joints`): ``ik`` gives
``direction * absolute angle + offset`` of the angle in ``[0, 360)``; ``joint_ranges`` has no
default (the joints are unchecked unless it is given).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import Geometry
from .joints import JointConventions
from .kinematics import NUMPY_MATH, RAD2DEG, UnreachableError, format_point
from .reach import raise_first_unreachable

__all__ = ["PlanarArm"]


@dataclass(frozen=True)
class PlanarArm(JointConventions, Geometry):
    """Planar 3R arm, tool tip target (x, y) at a fixed tool orientation ``phi``.

    With the wrist ``w = (xw, yw) = (x - l3 cos phi, y - l3 sin phi)``, ``d2 = |w|**2``,
    ``A = (l1**2 + d2 - l2**2) / 2`` and ``B = sqrt((d2 - (l1 - l2)**2) ((l1 + l2)**2 - d2)) / 2``,
    the elbow is ``E = (A w + B w_perp) / d2`` (``w_perp = (-yw, xw)``: link 1 is ``w`` turned
    counter-clockwise by the shoulder angle of the triangle) and link 2 is ``w - E``.
    Each absolute angle is ``180 + atan2(-v_y, -v_x)`` of its link vector ``v``: the direction
    in ``(0, 360]``, continuous everywhere except across the +x axis, so a workspace box in
    which no link points along +x has no wrap (the preset's box is chosen so).

    Parameters
    ----------
    l1, l2, l3 : float
        Link lengths (> 0).
    phi : float
        Tool orientation in degrees (any angle; the TOML may give it <= 0).
    """

    l1: float = 35.0
    l2: float = 30.0
    l3: float = 10.0
    phi: float = 90.0

    inputs = ("x", "y")
    input_units = ("mm", "mm")
    servos = ("s1", "s2")
    servo_names = ("link1", "link2")
    coordinates = "cartesian"
    #: Geometry fields that may be zero or negative (robot.py checks the others are > 0).
    signed_fields = ("phi",)

    # -- helpers -------------------------------------------------------------
    def wrist(self, x, y):
        """Wrist position ``(x - l3 cos phi, y - l3 sin phi)`` for the tool tip (x, y)."""
        ph = math.radians(self.phi)
        return x - self.l3 * math.cos(ph), y - self.l3 * math.sin(ph)

    def reach(self) -> tuple[float, float]:
        """Range ``(|l1 - l2|, l1 + l2)`` of the shoulder-to-wrist distance."""
        return abs(self.l1 - self.l2), self.l1 + self.l2

    # -- inverse kinematics --------------------------------------------------
    def angles(self, xp, x, y):
        """Pure IK formula (no reachability check, no wrap to [0, 360)) over the math namespace.

        Uses only ``+ - * /``, integer powers, constants and ``xp.sqrt`` / ``xp.atan2``, so it
        runs on float arrays (``kinematics.NUMPY_MATH``) and on interval numbers. Returns the
        servo angles of the absolute angles (s1, s2) in degrees in ``(0, 360]``; equal to
        :meth:`ik` wherever no link points exactly along +x.
        """
        return self.servo_angles(self.link_angles(xp, x, y))

    def link_angles(self, xp, x, y):
        """The absolute link angles (s1, s2) in ``(0, 360]`` of :meth:`angles`, before the joint
        conventions."""
        lo, hi = self.reach()
        xw, yw = self.wrist(x, y)
        d2 = xw * xw + yw * yw
        a = (self.l1 ** 2 - self.l2 ** 2 + d2) * 0.5
        b = xp.sqrt((d2 - lo * lo) * (hi * hi - d2)) * 0.5
        c = d2 - a  # (l2**2 - l1**2 + d2) / 2
        s1 = 180.0 + xp.atan2(-(a * yw + b * xw), -(a * xw - b * yw)) * RAD2DEG
        s2 = 180.0 + xp.atan2(-(c * yw - b * xw), -(c * xw + b * yw)) * RAD2DEG
        return s1, s2

    def ik(self, x, y):
        """Servo angles of the absolute link angles (s1, s2) in degrees in ``[0, 360)`` for
        tool tip (x, y).

        Raises
        ------
        UnreachableError
            Naming the first point whose wrist is outside the annulus ``|l1 - l2| <= d <= l1 + l2``
            (or at the shoulder), else the first needing a servo angle beyond ``joint_ranges``.
        """
        x, y = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, y)))
        lo, hi = self.reach()
        xw, yw = self.wrist(x, y)
        d2 = xw * xw + yw * yw  # the same expression as in link_angles(): its sqrt argument is >= 0 here
        bad = ~((d2 >= lo * lo) & (d2 <= hi * hi) & (d2 > 0))
        if np.any(bad):
            i = np.flatnonzero(np.ravel(bad))[0]
            raise UnreachableError(
                f"target {format_point(self.inputs, (np.ravel(x)[i], np.ravel(y)[i]))} is unreachable: "
                f"wrist distance from the shoulder {math.sqrt(np.ravel(d2)[i]):.6g} mm must be within "
                f"[{lo:g}, {hi:g}] mm and > 0")
        s1, s2 = self.link_angles(NUMPY_MATH, x, y)
        a = self.servo_angles((np.mod(s1, 360.0), np.mod(s2, 360.0)))
        raise_first_unreachable(self.inputs, (x, y), self.range_checks(a))
        return a

    # -- forward kinematics --------------------------------------------------
    def fk(self, s1, s2):
        """Tool tip (x, y) for servo angles s1, s2 in degrees (link 3 at ``phi``)."""
        a1, a2 = (np.radians(np.asarray(a, dtype=np.float64)) for a in self.kinematic_angles((s1, s2)))
        xw = self.l1 * np.cos(a1) + self.l2 * np.cos(a2)
        yw = self.l1 * np.sin(a1) + self.l2 * np.sin(a2)
        ph = math.radians(self.phi)
        return xw + self.l3 * math.cos(ph), yw + self.l3 * math.sin(ph)

    def rates(self, s1, s2, vx, vy):
        """Servo velocities and accelerations at servo angles (s1, s2) for a tip moving at
        constant velocity (vx, vy).

        With the tool orientation fixed the wrist moves like the tip, so
        ``J w = v`` and ``J a + c(w) = 0`` where, for the absolute link angles ``s1, s2``,
        ``J = [[-l1 sin s1, -l2 sin s2], [l1 cos s1, l2 cos s2]]`` (per radian) and
        ``c = -(l1 cos s1 w1^2 + l2 cos s2 w2^2, l1 sin s1 w1^2 + l2 sin s2 w2^2)``; each servo's
        rates are its link's times its ``angle_directions`` entry.

        Returns
        -------
        (w1, w2), (a1, a2)
            Velocities in deg per unit of time and accelerations in deg per unit of time
            squared (time in which the tip moves by (vx, vy)); singular where the links are
            collinear.
        """
        t1, t2 = (np.radians(np.asarray(a, dtype=np.float64)) for a in self.kinematic_angles((s1, s2)))
        l1, l2 = self.l1, self.l2
        det = l1 * l2 * np.sin(t2 - t1)  # det J
        w1 = (l2 * np.cos(t2) * vx + l2 * np.sin(t2) * vy) / det
        w2 = -(l1 * np.cos(t1) * vx + l1 * np.sin(t1) * vy) / det
        cx = -(l1 * np.cos(t1) * w1 ** 2 + l2 * np.cos(t2) * w2 ** 2)
        cy = -(l1 * np.sin(t1) * w1 ** 2 + l2 * np.sin(t2) * w2 ** 2)
        a1 = -(l2 * np.cos(t2) * cx + l2 * np.sin(t2) * cy) / det
        a2 = (l1 * np.cos(t1) * cx + l1 * np.sin(t1) * cy) / det
        d1, d2 = self.angle_directions
        return (d1 * w1 * RAD2DEG, d2 * w2 * RAD2DEG), (d1 * a1 * RAD2DEG, d2 * a2 * RAD2DEG)
