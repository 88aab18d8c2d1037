"""MeArm (v0.3-1.2 arm, Arduino Servo library): Nick Moriarty's IK and the servo calibration.

Sources:

- yorkhackspace/meArm @ eacdf199 (2017-09-12): ``ik.cpp`` (``solve``), ``fk.cpp`` (``unsolve``),
  ``config.h`` (L1, L2, L3), ``meArm.h`` (the default calibration), ``meArm.cpp``
  (``setup_servo``, ``angle2pwm``), ``examples/IKTest/IKTest.ino`` (the demonstrated path);
- arduino-libraries/Servo @ 3f163ecc (2026-02-27): ``src/Servo.h`` and ``src/avr/Servo.cpp``
  (``Servo::write``: degrees -> us).

MeArm/MeArm-Arduino @ a0760982 (2023-10-13, the maker's own library, for the MeArm v3.0) has
the same ``ik.cpp``/``fk.cpp`` but ``L3 = 22`` ("Correct to MeArm Version 3.0", its config.h:10,
the 68 commented out as "versions 0.3-1.2") and a base calibration of 180..0 for -pi/4..pi/4
(its MeArm.h:30): :data:`V3_L3` and :data:`V3_CALIBRATION`.

Frame (ik.cpp, Geometry.md): mm; origin above the base axis at the shoulder's height; y
forward, x to the right (the base angle is ``atan2(x, y)``: ``cart2polar(y, x, ...)``), z up.
Angles (rad): a0 base yaw, a1 the upper arm's elevation, a2 the forearm's ABSOLUTE elevation
(``a2 = C + a1 - PI``): the elbow servo drives the forearm through the linkage, so its angle
is the forearm's own angle from the horizontal, not the elbow's. The hand stays horizontal.
"""
from __future__ import annotations

import math

import numpy as np

PI = 3.14159265359                      # ik.cpp:30 (meArm.h:18 "pi")
L1, L2, L3 = 80.0, 80.0, 68.0           # config.h:7-9
V3_L3 = 22.0                            # MeArm-Arduino config.h:10

#: meArm.h:29-32 defaults: per servo (sweepMin, sweepMax, angleMin, angleMax): servo degrees
#: (Servo.write) at two angles (rad)
CALIBRATION = {"base": (145, 49, -PI / 4, PI / 4), "shoulder": (118, 22, PI / 4, 3 * PI / 4),
               "elbow": (144, 36, PI / 4, -PI / 4), "gripper": (75, 115, PI / 2, 0.0)}
V3_CALIBRATION = {**CALIBRATION, "base": (180, 0, -PI / 4, PI / 4), "gripper": (75, 180, PI / 2, 0.0)}
#: Servo.h:90-91: MIN_PULSE_WIDTH 544, MAX_PULSE_WIDTH 2400 (Servo.write's 0 and 180 deg)
MIN_PULSE_WIDTH, MAX_PULSE_WIDTH = 544, 2400
#: README / meArm.cpp:65 begin(): goDirectlyToCylinder(0, 100, 50) = (x, y, z) (0, 100, 50)
HOME = (0.0, 100.0, 50.0)
#: IKTest.ino: the path home -> (-80, 100, 140) -> (70, 200, 10) -> home
IKTEST_PATH = ((-80.0, 100.0, 140.0), (70.0, 200.0, 10.0), HOME)


def cart2polar(a, b):
    """ik.cpp:33-55: (r, theta) of (a, b), theta = acos(a/r) signed as b."""
    r = math.sqrt(a * a + b * b)
    if r == 0:
        return r, None                 # the source leaves theta unset
    c, s = min(max(a / r, -1), 1), min(max(b / r, -1), 1)
    theta = math.acos(c)
    return r, (-theta if s < 0 else theta)


def cosangle(opp, adj1, adj2):
    """ik.cpp:58-75: the angle between adj1 and adj2 opposite opp, or None (unreachable)."""
    den = 2 * adj1 * adj2
    if den == 0:
        return None
    c = (adj1 * adj1 + adj2 * adj2 - opp * opp) / den
    if c > 1 or c < -1:
        return None
    return math.acos(c)


def solve(x, y, z, l1=L1, l2=L2, l3=L3):
    """ik.cpp:78-102: (a0, a1, a2) rad, or None where ``solve`` returns false."""
    r, th0 = cart2polar(y, x)
    r -= l3                            # :85 "Account for the wrist length!"
    big_r, ang_p = cart2polar(r, z)
    b = cosangle(l2, l1, big_r)
    c = cosangle(big_r, l1, l2) if b is not None else None
    if b is None or c is None:
        return None
    a1 = ang_p + b
    return th0, a1, c + a1 - PI        # :97-99


def solve_exact(x, y, z, l1=L1, l2=L2, l3=L3):
    """:func:`solve` over numpy arrays (acos-based like the source, NaN where unreachable)."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    th0 = np.arctan2(x, y)             # acos(y/r) signed as x
    r = np.hypot(y, x) - l3
    big_r, ang_p = np.hypot(r, z), np.arctan2(z, r)
    with np.errstate(invalid="ignore", divide="ignore"):
        b = np.arccos((l1 * l1 + big_r * big_r - l2 * l2) / (2 * l1 * big_r))
        c = np.arccos((l1 * l1 + l2 * l2 - big_r * big_r) / (2 * l1 * l2))
    a1 = ang_p + b
    return th0, a1, c + a1 - PI


def unsolve(a0, a1, a2, l1=L1, l2=L2, l3=L3):
    """fk.cpp:36-51: (x, y, z) of the angles ("note x/y reversal")."""
    u = l1 * math.cos(a1) + l2 * math.cos(a2) + l3
    v = l1 * math.sin(a1) + l2 * math.sin(a2)
    return u * math.sin(a0), u * math.cos(a0), v


def setup_servo(n_min, n_max, a_min, a_max):
    """meArm.cpp:16-34: (gain, zero) with ``gain = n_range / a_range`` (servo deg per rad) and
    ``zero = n_min - gain * a_min``."""
    gain = (n_max - n_min) / (a_max - a_min)
    return gain, n_min - gain * a_min


def angle2pwm(servo: str, angle, calibration=CALIBRATION) -> int:
    """meArm.cpp:36-40 ``int(0.5f + zero + gain * angle)``: the servo degrees Servo.write gets."""
    gain, zero = setup_servo(*calibration[servo])
    return int(0.5 + zero + gain * angle)


def servo_degrees_exact(servo: str, angle, calibration=CALIBRATION):
    """``zero + gain * angle`` unrounded (float64)."""
    gain, zero = setup_servo(*calibration[servo])
    return zero + gain * np.asarray(angle, dtype=np.float64)


def arduino_map(x: int, in_min: int, in_max: int, out_min: int, out_max: int) -> int:
    """Arduino's ``long map(...)``: ``(x - in_min) * (out_max - out_min) / (in_max - in_min) + out_min``
    in integer (C) arithmetic."""
    num, den = (x - in_min) * (out_max - out_min), in_max - in_min
    q = abs(num) // abs(den)
    return (q if (num >= 0) == (den >= 0) else -q) + out_min


def servo_write_us(degrees: int) -> int:
    """avr/Servo.cpp:264-273 ``Servo::write``: degrees clamped to 0..180 and mapped to
    SERVO_MIN()..SERVO_MAX() = 544..2400 us (min/max trims 0)."""
    d = min(max(degrees, 0), 180)
    return arduino_map(d, 0, 180, MIN_PULSE_WIDTH, MAX_PULSE_WIDTH)


def pulse_us_exact(servo_deg):
    """The map of :func:`servo_write_us` without the integer steps."""
    return MIN_PULSE_WIDTH + (MAX_PULSE_WIDTH - MIN_PULSE_WIDTH) * np.asarray(servo_deg, dtype=np.float64) / 180.0


def pulses_firmware(x, y, z, calibration=CALIBRATION, l3=L3):
    """(base, shoulder, elbow) us of ``goDirectlyTo(x, y, z)`` (meArm.cpp:77-85), or None."""
    angles = solve(x, y, z, l3=l3)
    if angles is None:
        return None
    return tuple(servo_write_us(angle2pwm(s, a, calibration)) for s, a in zip(("base", "shoulder", "elbow"), angles))


def pulses_exact(x, y, z, calibration=CALIBRATION, l3=L3):
    """(base, shoulder, elbow) us (float64) with the exact IK and the unrounded maps."""
    angles = solve_exact(x, y, z, l3=l3)
    return tuple(pulse_us_exact(servo_degrees_exact(s, a, calibration))
                 for s, a in zip(("base", "shoulder", "elbow"), angles))


def workspace_box() -> dict[str, tuple[float, float]]:
    """The box spanned by IKTest's path (home and its two targets). Not every corner is
    reachable: the arm reaches 160 mm from the shoulder (:func:`solve` says where)."""
    pts = np.array(IKTEST_PATH)
    return {k: (float(pts[:, i].min()), float(pts[:, i].max())) for i, k in enumerate("xyz")}
