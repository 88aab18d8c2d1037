"""Freenove Big Hexapod (Raspberry Pi, two PCA9685): its leg IK, calibration and servo map.

Source: Freenove/Freenove_Big_Hexapod_Robot_Kit_for_Raspberry_Pi @ b7d228cc (2026-03-07):
``Code/Server/control.py`` (cited as ``control.py:LINE``) and ``Code/Server/servo.py``
(``servo.py:LINE``); ``Code/Server/point.txt`` holds the per-leg calibration points (all
``140 0 0`` as shipped). The older ``Code/Server/Control.py`` (deleted in 0744596, 2025-02-18)
has the same formulas under camelCase names (``coordinateToAngle`` at its line 58).

Frames. ``transform_coordinates`` (control.py:226-250) turns a body-frame foot point
(mm; x towards leg 2, y towards the midpoint of legs 1 and 6, z up: see ``body_points``,
control.py:26-27) into the leg frame: rotated by the leg's mount
angle (54, 0, -54, -126, 180, 126 deg for legs 1..6), minus the mount radius (94 or 85 mm)
along x, minus 14 mm in z. Leg frame: x outwards from the coxa, y sideways, z up.
``coordinate_to_angle(x, y, z)`` is called as ``coordinate_to_angle(-z_leg, x_leg, y_leg)``
(control.py:87-88): its own x is the depth below the coxa, y outwards, z sideways.

Two forms: :func:`coordinate_to_angle_firmware` rounds as the source does (the cosines to
2 decimals before asin/acos, the angles to whole degrees, control.py:58-60);
:func:`coordinate_to_angle_exact` is the same formula without the rounding, the reference
for sub-pulse comparisons.
"""
from __future__ import annotations

import math

import numpy as np

L1, L2, L3 = 33, 90, 110                # control.py:49 "def coordinate_to_angle(self, x, y, z, l1=33, l2=90, l3=110)"
#: control.py:228-250: the leg frames' mount angles (deg) and mount radii (mm), legs 1..6
MOUNT_ANGLE = (54, 0, -54, -126, 180, 126)
MOUNT_RADIUS = (94, 85, 94, 94, 85, 94)
MOUNT_DZ = 14                          # control.py:230 "points[0][2] - 14"
#: control.py:26-27 body_points, the standing feet in the body frame (body_height -25)
BODY_POINTS = ((137.1, 189.4), (225, 0), (137.1, -189.4), (-137.1, -189.4), (-225, 0), (-137.1, 189.4))
BODY_HEIGHT = -25                      # control.py:25 "self.body_height = -25"
CALIBRATION_POSE = (140, 0, 0)         # control.py:72 leg_positions during calibrate()
#: servo channels (coxa, femur, tibia) per leg, control.py:96-119 (16.. on the 0x40 board)
CHANNELS = ((15, 14, 13), (12, 11, 10), (9, 8, 31), (22, 23, 27), (19, 20, 21), (16, 17, 18))
#: control.py:142-144 move_position's x, y, z limits; control.py:331-332 run_gait's x, y limits;
#: control.py:329 "def run_gait(self, data, Z=40, F=64)": the swing lift Z
POSITION_XY, POSITION_Z, GAIT_XY, GAIT_LIFT = 40, 20, 35, 40


def _restrict(v, lo, hi):
    """control.py:252-258 restrict_value."""
    return np.clip(v, lo, hi)


def coordinate_to_angle_firmware(x: float, y: float, z: float) -> tuple[int, int, int]:
    """control.py:49-60 as written: (a, b, c) in whole degrees (Python's round, half to even)."""
    a = math.pi / 2 - math.atan2(z, y)
    x_3, x_4, x_5 = 0, L1 * math.sin(a), L1 * math.cos(a)
    l23 = math.sqrt((z - x_5) ** 2 + (y - x_4) ** 2 + (x - x_3) ** 2)
    w = float(_restrict((x - x_3) / l23, -1, 1))
    v = float(_restrict((L2 * L2 + l23 * l23 - L3 * L3) / (2 * L2 * l23), -1, 1))
    u = float(_restrict((L2 ** 2 + L3 ** 2 - l23 ** 2) / (2 * L3 * L2), -1, 1))
    b = math.asin(round(w, 2)) - math.acos(round(v, 2))
    c = math.pi - math.acos(round(u, 2))
    return round(math.degrees(a)), round(math.degrees(b)), round(math.degrees(c))


def coordinate_to_angle_exact(x, y, z):
    """control.py:49-60 without the rounding: (a, b, c) degrees, float64, numpy-broadcast."""
    x, y, z = (np.asarray(t, dtype=np.float64) for t in (x, y, z))
    a = math.pi / 2 - np.arctan2(z, y)
    x_4, x_5 = L1 * np.sin(a), L1 * np.cos(a)
    l23 = np.sqrt((z - x_5) ** 2 + (y - x_4) ** 2 + x ** 2)
    w = _restrict(x / l23, -1, 1)
    v = _restrict((L2 * L2 + l23 * l23 - L3 * L3) / (2 * L2 * l23), -1, 1)
    u = _restrict((L2 ** 2 + L3 ** 2 - l23 ** 2) / (2 * L3 * L2), -1, 1)
    b = np.arcsin(w) - np.arccos(v)
    c = math.pi - np.arccos(u)
    return np.degrees(a), np.degrees(b), np.degrees(c)


def angle_to_coordinate(a, b, c):
    """control.py:62-69 (the source's FK, without its final round): (x, y, z) of the IK's frame."""
    a, b, c = (np.radians(np.asarray(t, dtype=np.float64)) for t in (a, b, c))
    x = L3 * np.sin(b + c) + L2 * np.sin(b)
    y = L3 * np.sin(a) * np.cos(b + c) + L2 * np.sin(a) * np.cos(b) + L1 * np.sin(a)
    z = L3 * np.cos(a) * np.cos(b + c) + L2 * np.cos(a) * np.cos(b) + L1 * np.cos(a)
    return x, y, z


def transform_coordinates(leg: int, bx, by, bz):
    """control.py:226-250 for leg ``leg`` (0..5 = the source's legs 1..6): body point -> leg frame."""
    t = MOUNT_ANGLE[leg] / 180 * math.pi
    return (bx * math.cos(t) + by * math.sin(t) - MOUNT_RADIUS[leg],
            -bx * math.sin(t) + by * math.cos(t), bz - MOUNT_DZ)


def from_preset_body(xb, yb, zb, body_height: float):
    """The source's body frame (x towards leg 2, i.e. right, y forward, z up; its leg frames'
    origins, the coxas, at z = 14: control.py:230 ``points[0][2] - 14``) of a point in the
    presets' body frame (x forward, y left, z up, origin on the ground; the coxas
    ``body_height`` above it)."""
    xb, yb, zb = (np.asarray(v, dtype=np.float64) for v in (xb, yb, zb))
    return -yb, xb, zb - body_height + MOUNT_DZ


def calibration_angles(points=(CALIBRATION_POSE,) * 6):
    """control.py:71-82 calibrate(): per leg, the angles at its point.txt point minus those at
    (140, 0, 0), in whole degrees (both through the rounding IK)."""
    ref = coordinate_to_angle_firmware(-CALIBRATION_POSE[2], CALIBRATION_POSE[0], CALIBRATION_POSE[1])
    out = []
    for p in points:
        got = coordinate_to_angle_firmware(-p[2], p[0], p[1])
        out.append(tuple(g - r for g, r in zip(got, ref)))
    return tuple(out)


def servo_angles(leg: int, a, b, c, cal=(0, 0, 0)):
    """control.py:89-95: the servo angles (coxa, femur, tibia) of IK angles a, b, c for leg
    0..5, with its calibration angles; legs 1-3 (right) and 4-6 (left) mirror femur and tibia."""
    if leg < 3:
        return (_restrict(a + cal[0], 0, 180), _restrict(90 - (b + cal[1]), 0, 180), _restrict(c + cal[2], 0, 180))
    return (_restrict(a + cal[0], 0, 180), _restrict(90 + b + cal[1], 0, 180),
            _restrict(180 - (c + cal[2]), 0, 180))


def pulse_us(angle):
    """servo.py:27 ``map_value(angle, 0, 180, 500, 2500)``: the pulse in us (before the PCA9685)."""
    return (2500 - 500) * (np.asarray(angle, dtype=np.float64) - 0) / (180 - 0) + 500


def pca9685_count(angle) -> int:
    """servo.py:27-29: ``int(map_value(us, 0, 20000, 0, 4095))``, the 12-bit on-count at 50 Hz."""
    return int((4095 - 0) * (float(pulse_us(angle)) - 0) / (20000 - 0) + 0)


def pulses_firmware(leg: int, x: float, y: float, z: float, cal=(0, 0, 0)):
    """(coxa, femur, tibia) pulse in us of a leg-frame target as the robot computes it
    (rounding IK, calibration, mirroring, 0..180 clamp; before the PCA9685's truncation)."""
    angles = servo_angles(leg, *coordinate_to_angle_firmware(-z, x, y), cal)
    return tuple(float(pulse_us(s)) for s in angles)


def pulses_exact(leg: int, x, y, z, cal=(0.0, 0.0, 0.0)):
    """(coxa, femur, tibia) pulse in us (float64) of a leg-frame target, exact IK, unclamped."""
    a, b, c = coordinate_to_angle_exact(-np.asarray(z, dtype=np.float64), x, y)
    if leg < 3:
        s = (a + cal[0], 90 - (b + cal[1]), c + cal[2])
    else:
        s = (a + cal[0], 90 + b + cal[1], 180 - (c + cal[2]))
    return tuple(pulse_us(v) for v in s)


def walking_box() -> dict[str, tuple[float, float]]:
    """The leg-frame target box of the tripod walk (the same for every leg after
    transform_coordinates): the stance foot at (140, 0) (body_points turned into each leg frame:
    233.8 - 94 = 225 - 85 = 140) +- GAIT_XY in x and y (run_gait's stride moves a foot over
    +-x, +-y), z from the lowest body (move_position: -30 - 20) - 14 to the highest (-30 + 20)
    - 14 plus the swing lift GAIT_LIFT."""
    r = transform_coordinates(1, BODY_POINTS[1][0], BODY_POINTS[1][1], 0.0)[0]
    return {"x": (r - GAIT_XY, r + GAIT_XY), "y": (-GAIT_XY, GAIT_XY),
            "z": (-30 - POSITION_Z - MOUNT_DZ, -30 + POSITION_Z - MOUNT_DZ + GAIT_LIFT)}
