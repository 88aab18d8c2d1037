"""Lynxmotion Phoenix (3 DOF, SSC-32): its Hex_Cfg.h numbers and servo pulse formula, ported.

Sources, KurtE/Arduino_Phoenix_Parts @ 35eb0e1a (2018-11-21):

- ``Phoenix/Phoenix_PS2_SSC32/Hex_Cfg.h`` ("Project Lynxmotion Phoenix ... Phoenix with 3 DOF",
  SSC-32 and PS2), cited as ``Hex_Cfg.h:LINE``;
- ``Phoenix/Phoenix_Code.h``: the ``cXXInv`` defaults (lines 91-149, this config sets none)
  and ``LegIK`` (:mod:`robot_refs.phoenix_code`);
- ``Phoenix_Driver_SSC32/Phoenix_Driver_SSC32.h``: angle -> pulse, cited as ``SSC32.h:LINE``;
- ``Phoenix_Input_PS2/Phoenix_Input_PS2.h``: body height, travel and lift ranges, ``PS2.h:LINE``.
"""
from __future__ import annotations

import numpy as np

from . import phoenix_code
from .phoenix_code import (LEGS, PhoenixConfig, cdiv, check_angles, driver_angles, leg_ik_exact,
                           leg_ik_firmware)

_SIX = (0,) * 6
# Hex_Cfg.h:219-222: cHexInitXZ 105, CHexInitXZCos60 53, CHexInitXZSin60 91, CHexInitY 25
_INIT = ((53, 25, 91), (105, 25, 0), (53, 25, -91), (53, 25, 91), (105, 25, 0), (53, 25, -91))

PHOENIX = PhoenixConfig(
    coxa=(29,) * 6, femur=(76,) * 6, tibia=(106,) * 6,        # Hex_Cfg.h:158-160 (TH3-R legs)
    coxa_angle1=(-600, 0, 600, -600, 0, 600),                 # Hex_Cfg.h:196-201
    offset_x=(-43, -63, -43, 43, 63, 43),                     # Hex_Cfg.h:203-215
    offset_z=(82, 0, -82, 82, 0, -82),
    init_pos=_INIT,                                           # Hex_Cfg.h:224-246
    coxa_minmax=((-260, 740), (-530, 530), (-580, 740), (-740, 260), (-530, 530), (-740, 580)),  # :112-147
    femur_minmax=((-1010, 950),) * 3 + ((-950, 1010),) * 3,   # Hex_Cfg.h:114-150
    tibia_minmax=((-1060, 770),) * 3 + ((-770, 1060),) * 3,   # Hex_Cfg.h:116-152
    coxa_inv=(True,) * 3 + (False,) * 3,                      # Phoenix_Code.h:91-108 defaults
    femur_inv=(True,) * 3 + (False,) * 3,                     # Phoenix_Code.h:111-128
    tibia_inv=(True,) * 3 + (False,) * 3,                     # Phoenix_Code.h:131-148
)

# SSC32.h:312-313: "#define cPwmDiv 991", "#define cPFConst 592 ... 900*(1000/cPwmDiv)+cPFConst
# must always be 1500"; "A PWM/deg factor of 10,09 give cPwmDiv = 991 and cPFConst = 592"
PWM_DIV, PF_CONST = 991, 592

#: PS2.h:91-92 "#define MAX_BODY_Y 100"; Phoenix_Code.h:665 "LegLiftHeight = 50" (PS2.h:368
#: toggles 80); PS2.h:390-396 TravelLength = stick - 128, halved unless DoubleTravelOn
MAX_BODY_Y, LEG_LIFT_HEIGHT, HALF_TRAVEL = 100, 50, 32


def ssc32_pulse_firmware(angle1: int) -> int:
    """SSC32.h:330-332 ``((long)(sAngle1 + 900))*1000/cPwmDiv + cPFConst``: us, integer."""
    return cdiv((angle1 + 900) * 1000, PWM_DIV) + PF_CONST


def ssc32_pulse_exact(angle_deg):
    """The same map in float64: ``(10 * angle + 900) * 1000 / 991 + 592`` us."""
    return (10.0 * np.asarray(angle_deg, dtype=np.float64) + 900.0) * 1000.0 / PWM_DIV + PF_CONST


def pulses_firmware(leg: str, x: int, y: int, z: int) -> tuple[int, int, int]:
    """(coxa, femur, tibia) pulse in us for a LegIK target, as the robot computes it:
    LegIK, CheckAngles, the Inv flip, the SSC-32 driver."""
    angles = check_angles(PHOENIX, leg, leg_ik_firmware(PHOENIX, leg, x, y, z))
    return tuple(ssc32_pulse_firmware(a) for a in driver_angles(PHOENIX, leg, angles))


def pulses_exact(leg: str, x, y, z):
    """(coxa, femur, tibia) pulse in us (float64) from :func:`~robot_refs.phoenix_code.leg_ik_exact`
    with the Inv flip and the SSC-32 map; no clamping (:func:`within_limits` says where it would)."""
    i = PHOENIX.leg(leg)
    angles = leg_ik_exact(PHOENIX, leg, x, y, z)
    invs = (PHOENIX.coxa_inv[i], PHOENIX.femur_inv[i], PHOENIX.tibia_inv[i])
    return tuple(ssc32_pulse_exact(-a if inv else a) for a, inv in zip(angles, invs))


def within_limits(leg: str, x, y, z):
    """True where every exact angle lies inside the leg's Hex_Cfg.h min/max."""
    return phoenix_code.within_limits(PHOENIX, leg, x, y, z)


def walking_box(leg: str) -> dict[str, tuple[float, float]]:
    """The LegIK target box the default walk reaches (no body rotation): the init position
    +- half the travel in X and Z (the gait moves a foot over +-TravelLength/2, TravelLength =
    (stick - 128)/2 up to 64), Y from the init height lifted by LegLiftHeight to it lowered by
    the full body raise MAX_BODY_Y."""
    x0, y0, z0 = PHOENIX.init_pos[PHOENIX.leg(leg)]
    return {"x": (x0 - HALF_TRAVEL, x0 + HALF_TRAVEL), "y": (y0 - LEG_LIFT_HEIGHT, y0 + MAX_BODY_Y),
            "z": (z0 - HALF_TRAVEL, z0 + HALF_TRAVEL)}


__all__ = ["LEGS", "PHOENIX", "MAX_BODY_Y", "LEG_LIFT_HEIGHT", "HALF_TRAVEL", "ssc32_pulse_firmware",
           "ssc32_pulse_exact", "pulses_firmware", "pulses_exact", "within_limits", "walking_box"]
