"""Quadruped legs in the sagittal plane, after the "Arduino IK" quadruped notes.

Two geometries, both with the tip target ``(x, y)`` relative to the leg's pivot as in the
notes (``IKx``, ``IKy``):

- :class:`QuadrupedHind`: hip, knee and hock; the redundant third joint is fixed by the
  notes' condition that the hip-toe line bisects the shin. The notes find the split point
  by iteration; here it is the middle root of a cubic, in closed form.
- :class:`QuadrupedFore`: shoulder, elbow and wrist with the wrist kept straight.

The notes give no lengths and no joint limits; the values here are chosen for a small
hobby-servo quadruped and documented on each class. Their figures were lost, so the frame
is reconstructed from the formulas: see the class docstrings. The joint ranges are the
defaults of the ``joint_ranges`` field; ``zero_offsets`` and ``angle_directions`` turn the
angles into the servos' own (:mod:`ikseries.joints`), which ``ik``, ``angles`` and ``fk`` use.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Geometry
from .joints import JointConventions
from .kinematics import NUMPY_MATH, RAD2DEG
from .reach import raise_first_unreachable

__all__ = ["QuadrupedHind", "QuadrupedFore"]

_TWO_PI_3 = 2.0 * np.pi / 3.0


def _targets(x, y, pivot_height):
    """Broadcast (x, y) to float64; return them and the flat pivot-toe distance."""
    x, y = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, y)))
    return x, y, np.ravel(np.hypot(x, pivot_height - y))


def _checked_angles(geom, x, y, pivot_height, reachable, reach_message):
    """``geom.angles`` for toe targets (x, y), raising :class:`UnreachableError` for the first
    target (C order) whose pivot-toe distance fails ``reachable`` (message from
    ``reach_message(distance)``) or that needs a servo angle beyond ``geom.joint_ranges``."""
    x, y, lt = _targets(x, y, pivot_height)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = geom.angles(NUMPY_MATH, x, y)
        finite = np.logical_and.reduce([np.isfinite(np.ravel(v)) for v in a])
        out = ~(reachable(lt) & finite)
    raise_first_unreachable(geom.inputs, (x, y), [
        (out, lambda i: reach_message(lt[i])),
        *geom.range_checks(a)])
    return a


def _sagittal_tip(pivot_height, segments):
    """Tip (x, y) from (length, direction in rad from +x forward, counter-clockwise) pairs."""
    x = sum(length * np.cos(a) for length, a in segments)
    y = sum(length * np.sin(a) for length, a in segments)
    return x, pivot_height + y


@dataclass(frozen=True)
class QuadrupedHind(JointConventions, Geometry):
    """Hind leg: thigh, shin and foot; the hip-toe line bisects the shin (notes' rule).

    Inputs (mm), in the leg's vertical plane, origin on the ground below the hip axis:

    - ``x`` (``IKx``): toe position forward of the hip axis (forward positive);
    - ``y`` (``IKy``): toe height above the ground (up positive); the hip axis stands
      ``hip_height`` (``Hh``) above the ground, so the toe lies ``hip_height - y`` below it.
      A negative ``y`` lengthens the leg (as the notes do for the diagonal pair).

    Segments (notes' names): ``thigh`` ``Lp`` (hip to knee), ``shin`` ``Lk`` (knee to hock),
    ``foot`` ``Lh`` (hock to toe). The notes' rule: the hip-toe line (length ``Lt``)
    crosses the shin at its midpoint M. With ``La = |hip M|`` and ``Lb = Lt - La``, the
    opposite angles at M are equal, so by the cosine rule
    ``(La^2 + s^2 - thigh^2) / La = (Lb^2 + s^2 - foot^2) / Lb`` with ``s = shin / 2``
    (the notes' ``IKtest = 1``). With ``La = Lt/2 + w`` this is the depressed cubic
    ``w^3 + p w + q = 0``, ``p = s^2 - (thigh^2 + foot^2)/2 - Lt^2/4``,
    ``q = (thigh^2 - foot^2) Lt / 4``, whose middle root (trigonometric form) is the split
    point; ``w = 0`` when thigh == foot. This holds over the whole reach when the half
    shin is no longer than the thigh and the foot (then ``p < 0`` and the three roots are
    real and distinct; checked numerically over random proportions in the tests), so the
    class requires ``shin <= 2 min(thigh, foot)``.

    Joint angles (degrees, as in the notes):

    - ``s1`` hip ``angP = acos((La^2 + thigh^2 - s^2) / (2 La thigh)) + atan2(x, Hh - y)``:
      the thigh's angle from the downward vertical, forwards positive (knee forwards);
    - ``s2`` knee ``angK = 180 - acos((thigh^2 + s^2 - La^2) / (2 thigh s))``: knee bend,
      0 = straight, the shin turning backwards;
    - ``s3`` hock ``angH = 180 - acos((foot^2 + s^2 - Lb^2) / (2 foot s))``: hock bend,
      0 = straight, the foot turning forwards again.

    ``s2`` and ``s3`` depend only on ``Lt = hypot(x, Hh - y)`` and are even in ``x``;
    ``s1`` is that even part plus ``atan2(x, Hh - y)``, odd in ``x``.

    Chosen lengths (the notes give none): thigh 45, shin 50, foot 35 mm (130 mm straight),
    hip height 105 mm, a 9 g-servo-sized leg standing with knee and hock bent about 70
    and 80 deg. Reach: ``Lt`` in the open interval
    ``(|thigh - s| + |foot - s|, thigh + shin + foot)`` (folded .. straight; both ends singular).
    Assumed joint ranges (:attr:`joint_ranges`): hip -90..90 deg from the vertical, knee
    and hock bends 0..150 deg (beyond that the segments fold onto each other).

    Preset workspace (``quadruped-hind``): x -35..35 mm (a 70 mm stride), y -5..30 mm (30 mm
    toe lift, 5 mm lengthening); ``Lt`` 75..115.4 mm, joints within hip 1..56, knee 54..109,
    hock 59..120 deg. Servos: 1500 us at the standing pose (0, 0), 10 us/deg, 500..2500 us.
    """

    thigh: float = 45.0
    shin: float = 50.0
    foot: float = 35.0
    hip_height: float = 105.0

    coordinates = "cartesian"
    inputs = ("x", "y")
    input_units = ("mm", "mm")
    servos = ("s1", "s2", "s3")
    servo_names = ("hip", "knee", "hock")
    #: Inclusive joint ranges in degrees, per servo (assumed; see the class docstring).
    default_joint_ranges = ((-90.0, 90.0), (0.0, 150.0), (0.0, 150.0))

    def __post_init__(self):
        super().__post_init__()
        limit = 2.0 * min(self.thigh, self.foot)
        if not self.shin <= limit:
            raise ValueError(f"shin must be <= 2 * min(thigh, foot) = {limit:g} mm (the closed-form "
                             f"split point), not {self.shin!r}")

    def split(self, xp, x, y):
        """Hip-toe distance ``Lt`` and the split lengths ``La`` (hip side), ``Lb`` (toe side).

        Pure formula over ``xp`` (see :meth:`angles`).
        """
        s = 0.5 * self.shin
        h = self.hip_height - y
        lt2 = x * x + h * h
        lt = xp.sqrt(lt2)
        p = s * s - 0.5 * (self.thigh ** 2 + self.foot ** 2) - 0.25 * lt2
        q = 0.25 * (self.thigh ** 2 - self.foot ** 2) * lt
        m = xp.sqrt(-p / 3.0)
        # middle root of w^3 + p w + q = 0 (three real roots: p < 0, |q / (2 m^3)| < 1)
        w = 2.0 * m * xp.cos(xp.acos(-q / (2.0 * m ** 3)) / 3.0 - _TWO_PI_3)
        return lt, 0.5 * lt + w, 0.5 * lt - w

    def angles(self, xp, x, y):
        """Pure IK formula (no reachability checks) over the math namespace ``xp``.

        Uses only ``+ - * /``, integer powers, constants and ``xp.sqrt / atan2 / acos / cos``
        (the split point in closed form), so it also runs on interval numbers.

        Returns
        -------
        s1, s2, s3
            Hip, knee and hock servo angles in degrees (the angles of the class docstring under
            the joint conventions).
        """
        s, a, f = 0.5 * self.shin, self.thigh, self.foot
        _, la, lb = self.split(xp, x, y)
        hip = (xp.acos((la * la + a * a - s * s) / (2.0 * la * a))
               + xp.atan2(x, self.hip_height - y)) * RAD2DEG
        knee = 180.0 - xp.acos((a * a + s * s - la * la) / (2.0 * a * s)) * RAD2DEG
        hock = 180.0 - xp.acos((f * f + s * s - lb * lb) / (2.0 * f * s)) * RAD2DEG
        return self.servo_angles((hip, knee, hock))

    def reach(self):
        """Range ``(min, max)`` of the hip-toe distance in mm (folded .. straight)."""
        s = 0.5 * self.shin
        return abs(self.thigh - s) + abs(self.foot - s), self.thigh + self.shin + self.foot

    def ik(self, x, y):
        """Servo angles (s1, s2, s3) in degrees for toe targets (vectorised).

        Raises
        ------
        UnreachableError
            Naming the first target (C order) out of reach or needing a joint beyond
            :attr:`joint_ranges`.
        """
        lo, hi = self.reach()
        return _checked_angles(
            self, x, y, self.hip_height, lambda d: (d > lo) & (d < hi),
            lambda d: f"hip-toe distance {d:.6g} mm must be within ({lo:g}, {hi:g}) mm with the "
                      "shin bisected by the hip-toe line")

    def fk(self, s1, s2, s3):
        """Toe (x, y) in mm for servo angles in degrees (the inverse of :meth:`ik`)."""
        kinematic = self.kinematic_angles((s1, s2, s3))
        hip, knee, hock = (np.radians(np.asarray(v, dtype=np.float64)) for v in kinematic)
        thigh = hip - np.pi / 2          # direction from +x, counter-clockwise
        shin = thigh - knee              # the knee turns the shin backwards
        foot = shin + hock               # the hock turns the foot forwards
        return _sagittal_tip(self.hip_height, ((self.thigh, thigh), (self.shin, shin),
                                               (self.foot, foot)))


@dataclass(frozen=True)
class QuadrupedFore(JointConventions, Geometry):
    """Fore leg: upper arm, forearm and hand, the wrist kept straight (notes' rule).

    Inputs (mm) as for :class:`QuadrupedHind`, relative to the shoulder axis standing
    ``shoulder_height`` (``Hh``) above the ground: ``x`` (``IKx``) forward of the
    shoulder, ``y`` (``IKy``) toe height above the ground.

    Segments (notes' names): ``upper_arm`` ``Lp`` (shoulder to elbow), ``forearm`` ``Le``
    (elbow to wrist), ``hand`` ``Lw`` (wrist to toe). With the wrist straight the forearm
    and hand act as one link ``Le + Lw``; ``Lt = hypot(x, Hh - y)``.

    Joint angles (degrees, as in the notes):

    - ``s1`` shoulder ``angP = acos((Lp^2 + Lt^2 - (Le+Lw)^2) / (2 Lp Lt)) - atan2(x, Hh - y)``:
      the upper arm's angle from the downward vertical, backwards positive (elbow back);
    - ``s2`` elbow ``angE = 180 - acos((Lp^2 + (Le+Lw)^2 - Lt^2) / (2 Lp (Le+Lw)))``:
      elbow bend, 0 = straight, the forearm turning forwards;
    - ``s3`` wrist ``angW = 0`` (straight, depends on no input: a constant pulse).

    ``s2`` depends only on ``Lt`` (even in ``x``); ``s1`` is an even part minus the odd
    ``atan2(x, Hh - y)``. The notes' lifting mode (wrist broken, shoulder held) switches
    rules during the gait and is not modelled.

    Chosen lengths (the notes give none): upper arm 50, forearm 45, hand 25 mm, shoulder
    height 105 mm (the hind leg's hip height, so the body stands level), elbow bent about
    60 deg at rest. Assumed joint ranges (:attr:`joint_ranges`): shoulder -90..90 deg from
    the vertical, elbow bend 0..150 deg, wrist -90..90 deg.

    Preset workspace (``quadruped-fore``): as for the hind leg, x -35..35, y -5..30 mm;
    ``Lt`` 75..115.4 mm, joints within shoulder 1..83 and elbow 32..105 deg. Servos: 1500 us
    at the standing pose (0, 0), 10 us/deg, 500..2500 us.
    """

    upper_arm: float = 50.0
    forearm: float = 45.0
    hand: float = 25.0
    shoulder_height: float = 105.0

    coordinates = "cartesian"
    inputs = ("x", "y")
    input_units = ("mm", "mm")
    servos = ("s1", "s2", "s3")
    servo_names = ("shoulder", "elbow", "wrist")
    #: Inclusive joint ranges in degrees, per servo (assumed; see the class docstring).
    default_joint_ranges = ((-90.0, 90.0), (0.0, 150.0), (-90.0, 90.0))

    def angles(self, xp, x, y):
        """Pure IK formula (no reachability checks) over the math namespace ``xp``.

        Returns
        -------
        s1, s2, s3
            Shoulder, elbow and wrist servo angles in degrees (the angles of the class docstring
            under the joint conventions; the wrist is ``0 * Lt``, zero in the input's shape).
        """
        p, e = self.upper_arm, self.forearm + self.hand
        h = self.shoulder_height - y
        lt2 = x * x + h * h
        lt = xp.sqrt(lt2)
        shoulder = (xp.acos((p * p + lt2 - e * e) / (2.0 * p * lt)) - xp.atan2(x, h)) * RAD2DEG
        elbow = 180.0 - xp.acos((p * p + e * e - lt2) / (2.0 * p * e)) * RAD2DEG
        return self.servo_angles((shoulder, elbow, 0.0 * lt))

    def reach(self):
        """Range ``(min, max)`` of the shoulder-toe distance in mm (folded .. straight)."""
        p, e = self.upper_arm, self.forearm + self.hand
        return abs(p - e), p + e

    def ik(self, x, y):
        """Servo angles (s1, s2, s3) in degrees for toe targets (vectorised).

        Raises
        ------
        UnreachableError
            Naming the first target (C order) out of reach or needing a joint beyond
            :attr:`joint_ranges`.
        """
        lo, hi = self.reach()
        return _checked_angles(
            self, x, y, self.shoulder_height, lambda d: (d >= lo) & (d <= hi) & (d > 0),
            lambda d: f"shoulder-toe distance {d:.6g} mm must be within [{lo:g}, {hi:g}] mm")

    def fk(self, s1, s2, s3):
        """Toe (x, y) in mm for servo angles in degrees (the inverse of :meth:`ik`)."""
        kinematic = self.kinematic_angles((s1, s2, s3))
        sh, el, wr = (np.radians(np.asarray(v, dtype=np.float64)) for v in kinematic)
        upper = -np.pi / 2 - sh          # direction from +x, counter-clockwise
        fore = upper + el                # the elbow turns the forearm forwards
        hand = fore + wr                 # a wrist bend turns the hand the same way
        return _sagittal_tip(self.shoulder_height, ((self.upper_arm, upper), (self.forearm, fore),
                                                    (self.hand, hand)))
