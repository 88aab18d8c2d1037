"""SpotMicro (mike4192/spotMicro, PCA9685 via i2cpwm_board): leg IK, body frames and servo map.

Sources:

- mike4192/spotMicro @ 2a34f5d3 (2021-03-20): ``spot_micro_motion_cmd/config/
  spot_micro_motion_cmd.yaml`` (``yaml:LINE``), ``spot_micro_motion_cmd/src/
  spot_micro_motion_cmd.cpp`` (``motion_cmd.cpp:LINE``), ``.../src/smfsm/spot_micro_walk.cpp``;
- mike4192/spot_micro_kinematics_cpp @ ef154d7c (2021-01-03, the submodule commit spotMicro
  pins): ``src/utils.cpp`` (``utils.cpp:LINE``) and ``src/spot_micro_kinematics.cpp``;
- the servo driver, ros-i2cpwmboard (bradanlane, gitlab; read from its GitHub mirror
  mentor-dyun/ros-i2cpwmboard @ 886bcb3e, 2020-10-04): ``src/i2cpwm_controller.cpp``
  (``i2cpwm.cpp:LINE``).

Units: metres and radians as the source; servo commands in PCA9685 counts (12 bit, at the
driver's default 50 Hz, i2cpwm.cpp:283 ``int _pwm_frequency = 50``: 20000/4096 us a count).

Frames: body frame x forward, y up, z right (spot_micro_kinematics.cpp:38-39); each leg's
frame (utils.cpp:72-116) is the body frame turned about y by +pi/2 (right legs) or -pi/2
(left legs) and moved to the shoulder at (+-body_length/2, 0, +-body_width/2). In a leg's
frame the foot of the neutral stance is at (-hip_link_length, -stand height, forward offset)
for the right legs and (-hip_link_length, -stand height, -forward offset) for the left.
"""
from __future__ import annotations

import math

import numpy as np

# yaml:5-9
HIP_LINK, UPPER_LEG, LOWER_LEG = 0.055, 0.1075, 0.130
BODY_WIDTH, BODY_LENGTH = 0.078, 0.186
# yaml:12-18
DEFAULT_STAND_HEIGHT, STAND_FRONT_X_OFFSET, STAND_BACK_X_OFFSET = 0.155, 0.015, -0.000
LIE_DOWN_HEIGHT, LIE_DOWN_FOOT_X_OFFSET = 0.083, 0.065
# yaml:22 "servo_max_angle_deg: 82.5"
SERVO_MAX_ANGLE_DEG = 82.5
#: yaml:23-34, name: (num, center, range, direction, center_angle_deg); _1 hip, _2 shoulder, _3 knee
SERVOS = {
    "RF_3": (1, 306, 372, 1, 88.2), "RF_2": (2, 306, 389, 1, -27.6), "RF_1": (3, 306, 396, -1, -5.4),
    "RB_3": (4, 306, 396, 1, 85.8), "RB_2": (5, 306, 396, 1, -35.4), "RB_1": (6, 306, 411, 1, -4.4),
    "LB_3": (7, 306, 390, 1, -73.9), "LB_2": (8, 306, 392, 1, 38.7), "LB_1": (9, 306, 374, -1, -0.4),
    "LF_3": (10, 306, 387, 1, -82.8), "LF_2": (11, 306, 397, 1, 38.6), "LF_1": (12, 306, 389, 1, -7.6),
}
#: yaml:45 z_clearance; yaml:47-48 alpha, beta; yaml:63-73 the 8-phase gait (the one enabled)
Z_CLEARANCE, ALPHA, BETA = 0.050, 0.5, 0.5
SWING_TIME, DT = 0.36, 0.02                        # yaml:69, yaml:100
FWD_BODY_BALANCE_SHIFT, BACK_BODY_BALANCE_SHIFT, SIDE_BODY_BALANCE_SHIFT = 0.035, 0.005, 0.015
MAX_FWD_VELOCITY, MAX_SIDE_VELOCITY, MAX_YAW_RATE = 0.4, 0.4, 0.35   # yaml:40-42
#: motion_cmd.cpp:30-33 (spot_micro_kinematics.cpp): right legs solve with is_leg_12 = true
IS_LEG_12 = {"RB": True, "RF": True, "LF": False, "LB": False}
#: PCA9685: 4096 counts a period at 50 Hz
US_PER_COUNT = 1e6 / 50 / 4096


def ikine(x4, y4, z4, is_leg_12: bool, l1=HIP_LINK, l2=UPPER_LEG, l3=LOWER_LEG):
    """utils.cpp:173-216 ``ikine``: (ang1, ang2, ang3) rad of a foot at (x4, y4, z4) in the leg
    frame (float64 here where the source is float32; numpy-broadcast)."""
    x4, y4, z4 = (np.asarray(v, dtype=np.float64) for v in (x4, y4, z4))
    d = (x4 * x4 + y4 * y4 + z4 * z4 - l1 * l1 - l2 * l2 - l3 * l3) / (2 * l2 * l3)   # :188-189
    d = np.clip(d, -1.0, 1.0)                                                         # :194-198
    s = np.sqrt(1 - d * d)
    ang3 = np.arctan2(s, d) if is_leg_12 else np.arctan2(-s, d)                       # :200-204
    protected = np.maximum(x4 * x4 + y4 * y4 - l1 * l1, 0.0)                          # :207-208
    ang2 = np.arctan2(z4, np.sqrt(protected)) - np.arctan2(l3 * np.sin(ang3), l2 + l3 * np.cos(ang3))  # :210-211
    ang1 = np.arctan2(y4, x4) + np.arctan2(np.sqrt(protected), -l1)                   # :213
    return ang1, ang2, ang3


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def ht0to4(ang1, ang2, ang3, l1=HIP_LINK, l2=UPPER_LEG, l3=LOWER_LEG):
    """utils.cpp:119-170: the foot's homogeneous transform in the leg frame (scalar angles)."""
    t01 = _rot_z(ang1)
    t01[0, 3], t01[1, 3] = -l1 * math.cos(ang1), -l1 * math.sin(ang1)                 # :125-126
    t12 = np.array([[0, 0, -1, 0], [-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]])      # :135-139
    t23 = _rot_z(ang2)
    t23[0, 3], t23[1, 3] = l2 * math.cos(ang2), l2 * math.sin(ang2)                   # :151-152
    t34 = _rot_z(ang3)
    t34[0, 3], t34[1, 3] = l3 * math.cos(ang3), l3 * math.sin(ang3)                   # :157-160
    return t01 @ t12 @ t23 @ t34


def _rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def ht_leg(leg: str, body_length=BODY_LENGTH, body_width=BODY_WIDTH):
    """utils.cpp:72-116 htLegRightBack / RightFront / LeftFront / LeftBack."""
    front = 1.0 if leg[1] == "F" else -1.0
    right = 1.0 if leg[0] == "R" else -1.0
    t = _rot_y(right * math.pi / 2)
    t[:3, 3] = (front * body_length / 2, 0.0, right * body_width / 2)
    return t


def body_to_leg(leg: str, point, body_xyz=(0.0, DEFAULT_STAND_HEIGHT, 0.0)):
    """spot_micro_leg.cpp:38-56 with the body transform of spot_micro_kinematics.cpp:37-41
    (no body rotation): a foot in the world frame -> the leg frame ikine solves in."""
    ht = np.eye(4)
    ht[:3, 3] = body_xyz
    ht = ht @ ht_leg(leg)
    p = np.linalg.inv(ht) @ np.array([*point, 1.0])      # homogInverse, utils.cpp:35-69
    return tuple(p[:3])


def neutral_stance(leg: str):
    """motion_cmd.cpp:289-303 getNeutralStance: the foot in the world frame (y = 0, ground)."""
    front = leg[1] == "F"
    x = BODY_LENGTH / 2 + STAND_FRONT_X_OFFSET if front else -BODY_LENGTH / 2 + STAND_BACK_X_OFFSET
    z = BODY_WIDTH / 2 + HIP_LINK if leg[0] == "R" else -BODY_WIDTH / 2 - HIP_LINK
    return (x, 0.0, z)


def proportional(name: str, ang_rad):
    """motion_cmd.cpp:252-267: ``(cmd_ang_rad - center_ang_rad) / (servo_max_angle_deg*pi/180)``,
    clipped to [-1, 1] (the source warns and clips)."""
    center = SERVOS[name][4] * math.pi / 180.0
    return np.clip((np.asarray(ang_rad, dtype=np.float64) - center) / (SERVO_MAX_ANGLE_DEG * math.pi / 180.0),
                   -1.0, 1.0)


def counts_exact(name: str, ang_rad):
    """i2cpwm.cpp:593 before its int conversion: ``direction * (range / 2 * value) + center``."""
    _, center, rng, direction, _ = SERVOS[name]
    return direction * (rng / 2.0 * proportional(name, ang_rad)) + center


def counts_firmware(name: str, ang_rad) -> int:
    """i2cpwm.cpp:593 ``int pos = ...``: C's float -> int conversion truncates toward zero."""
    return int(math.trunc(float(counts_exact(name, ang_rad))))


def leg_counts_exact(leg: str, x4, y4, z4):
    """(hip _1, shoulder _2, knee _3) PCA9685 counts (float64) of a foot in the leg frame."""
    angs = ikine(x4, y4, z4, IS_LEG_12[leg])
    return tuple(counts_exact(f"{leg}_{k}", a) for k, a in zip((1, 2, 3), angs))


def stance_ticks_8_phase() -> int:
    """motion_cmd.cpp:380-386: swing_ticks = round(swing_time / dt), stance_ticks = 7 * swing_ticks."""
    return 7 * round(SWING_TIME / DT)


def touchdown_offset(speed: float) -> float:
    """spot_micro_walk.cpp:268: the swing foot lands ``alpha * stance_ticks * dt * speed`` m
    ahead of its neutral stance."""
    return ALPHA * stance_ticks_8_phase() * DT * speed


def walking_box(leg: str, stride: float) -> dict[str, tuple[float, float]]:
    """The leg-frame foot box of the 8-phase walk at stand height with a stride of +-``stride``
    m about the neutral stance (the source's own bound, max_fwd_velocity 0.4 m/s, lands the foot
    :func:`touchdown_offset` (0.4) = 0.504 m ahead, beyond the leg's reach; the caller picks the
    stride): forward from the stance -stride - fwd shift .. +stride + back shift, sideways by
    the side balance shift, height from the ground to z_clearance."""
    x0, y0, z0 = body_to_leg(leg, neutral_stance(leg))
    sign = 1.0 if leg[0] == "R" else -1.0        # the left leg frames' z points backwards
    fwd = sorted((z0 + sign * (-stride - FWD_BODY_BALANCE_SHIFT), z0 + sign * (stride + BACK_BODY_BALANCE_SHIFT)))
    side = (x0 - SIDE_BODY_BALANCE_SHIFT, x0 + SIDE_BODY_BALANCE_SHIFT)
    return {"x": (float(side[0]), float(side[1])), "y": (float(y0), float(y0 + Z_CLEARANCE)),
            "z": (float(fwd[0]), float(fwd[1]))}


def within_servo_range(leg: str, x4, y4, z4):
    """True where all three servo commands of the leg stay within +-servo_max_angle_deg of their
    centre angles (the source clips, motion_cmd.cpp:258-267) and the foot is reachable (|D| <= 1)."""
    x4, y4, z4 = (np.asarray(v, dtype=np.float64) for v in (x4, y4, z4))
    d = (x4 * x4 + y4 * y4 + z4 * z4 - HIP_LINK ** 2 - UPPER_LEG ** 2 - LOWER_LEG ** 2) / (2 * UPPER_LEG * LOWER_LEG)
    ok = np.abs(d) <= 1.0
    for k, a in zip((1, 2, 3), ikine(x4, y4, z4, IS_LEG_12[leg])):
        center = SERVOS[f"{leg}_{k}"][4] * math.pi / 180.0
        ok &= np.abs(a - center) <= SERVO_MAX_ANGLE_DEG * math.pi / 180.0
    return ok


def largest_stride(step: float = 0.005, n: int = 9) -> float:
    """The largest multiple of ``step`` m for which every leg's :func:`walking_box` lies within
    its servos' ranges (checked on an n x n x n grid)."""
    k = 0
    while True:
        trial = (k + 1) * step
        for leg in IS_LEG_12:
            box = walking_box(leg, trial)
            g = np.meshgrid(*(np.linspace(*box[a], n) for a in ("x", "y", "z")), indexing="ij")
            if not within_servo_range(leg, *g).all():
                return k * step
        k += 1
