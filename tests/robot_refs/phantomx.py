"""PhantomX AX Mk2 hexapod (AX-12 servos): its Hex_Cfg.h numbers and AX-12 position formula.

Sources, KurtE/Phantom_Phoenix @ 17784a5a (2017-02-23):

- ``Hex_Cfg.h`` ("the Version 2 PhantomX robot"), cited as ``Hex_Cfg.h:LINE``; it defines the
  horn offsets and the tibia directions (lines 38-45) and leaves ``PHANTOMX_V2`` undefined
  (line 37 commented out), so LegIK's tibia uses 900, not 1450 (``_Phoenix_Code.h:1923-1926``);
- ``_Phoenix_Code.h``: the ``cXXInv`` defaults for coxa and femur (lines 90-127) and ``LegIK``
  (line 1800, the same as :mod:`robot_refs.phoenix_code`);
- ``_Phoenix_Driver_AX12.h``: angle -> AX-12 goal position, cited as ``AX12.h:LINE``;
- ``_Phoenix_Input_Commander.h``: travel, lift and body height, cited as ``Commander.h:LINE``.

AX-12 units: goal position 0..1023 over 300 deg, 512 at the centre, so 1 unit = 300/1024 deg
and 0.1 deg = 1024/3000 = 128/375 units (``cPwmMult``/``cPwmDiv``).
"""
from __future__ import annotations

import numpy as np

from . import phoenix_code
from .phoenix_code import (C4DEC, LEGS, PhoenixConfig, cdiv, check_angles, driver_angles, get_sin_cos,
                           leg_ik_exact, leg_ik_firmware)

# Hex_Cfg.h:288-291: cHexInitXZ 147, CHexInitXZCos60 104 ("COS(45) = .707"), CHexInitY 25
_INIT = ((104, 25, 104), (147, 25, 0), (104, 25, -104), (104, 25, 104), (147, 25, 0), (104, 25, -104))

PHANTOMX = PhoenixConfig(
    coxa=(52,) * 6, femur=(66,) * 6, tibia=(133,) * 6,        # Hex_Cfg.h:220-222 ("MEASURE THIS!!! Guessed")
    coxa_angle1=(-450, 0, 450, -450, 0, 450),                 # Hex_Cfg.h:257-262
    offset_x=(-60, -100, -60, 60, 100, 60),                   # Hex_Cfg.h:268-283
    offset_z=(120, 0, -120, 120, 0, -120),
    init_pos=_INIT,                                           # Hex_Cfg.h:304-326
    coxa_minmax=((-750, 750),) * 4 + ((-1000, 1000), (-750, 750)),   # Hex_Cfg.h:164-200 (LM wider)
    femur_minmax=((-1000, 1000),) * 6,                        # Hex_Cfg.h:166-202
    tibia_minmax=((-1020, 670),) * 6,                         # Hex_Cfg.h:168-204 (not mirrored)
    coxa_inv=(True,) * 3 + (False,) * 3,                      # _Phoenix_Code.h:90-107 defaults
    femur_inv=(True,) * 3 + (False,) * 3,                     # _Phoenix_Code.h:110-127 defaults
    tibia_inv=(False,) * 3 + (True,) * 3,                     # Hex_Cfg.h:40-45: reversed on the left
    femur_horn_offset1=-35,                                   # Hex_Cfg.h:38 "#define cFemurHornOffset1 -35"
    tibia_horn_offset1=463,                                   # Hex_Cfg.h:39 "#define cTibiaHornOffset1 463"
)

# AX12.h:21-23: cPwmMult 128, cPwmDiv 375, cPFConst 512 ("half of our 1024 range")
PWM_MULT, PWM_DIV, PF_CONST = 128, 375, 512
#: AX-12: 1024 positions over 300 deg (the 128/375 above is 1024/3000 per 0.1 deg)
AX_DEG_PER_UNIT = 300.0 / 1024.0

#: Hex_Cfg.h:295 "#define MAX_BODY_Y 150"; _Phoenix_Code.h:790 "LegLiftHeight = 50"
#: (Commander.h:400-403 toggles 80); Commander.h:420-421 TravelLength = -stick (signed char),
#: halved unless DoubleTravelOn (Commander.h:439-442): up to 64, a foot moves +-32
MAX_BODY_Y, LEG_LIFT_HEIGHT, HALF_TRAVEL = 150, 50, 32
#: Hex_Cfg.h:297-298 g_abHexIntXZ {cHexInitXZ, 144}, g_abHexMaxBodyY {20, MAX_BODY_Y}: above a
#: body height of 20 mm AdjustLegPositionsToBodyHeight (_Phoenix_Code.h:2184) moves the feet in
#: to 144 mm from the coxa
HEX_INIT_XZ, HEX_MAX_BODY_Y = (147, 144), (20, 150)


def ax12_position_firmware(angle1: int) -> int:
    """AX12.h:535-537 ``(((long)(sAngle1)) * cPwmMult) / cPwmDiv + cPFConst``: AX-12 units."""
    return cdiv(angle1 * PWM_MULT, PWM_DIV) + PF_CONST


def ax12_position_exact(angle_deg):
    """The same map in float64: ``10 * angle * 128 / 375 + 512`` AX-12 units."""
    return 10.0 * np.asarray(angle_deg, dtype=np.float64) * PWM_MULT / PWM_DIV + PF_CONST


def positions_firmware(leg: str, x: int, y: int, z: int) -> tuple[int, int, int]:
    """(coxa, femur, tibia) AX-12 goal positions for a LegIK target, as the robot computes them."""
    angles = check_angles(PHANTOMX, leg, leg_ik_firmware(PHANTOMX, leg, x, y, z))
    return tuple(ax12_position_firmware(a) for a in driver_angles(PHANTOMX, leg, angles))


def positions_exact(leg: str, x, y, z):
    """(coxa, femur, tibia) AX-12 positions (float64, unclamped) from the exact LegIK."""
    i = PHANTOMX.leg(leg)
    angles = leg_ik_exact(PHANTOMX, leg, x, y, z)
    invs = (PHANTOMX.coxa_inv[i], PHANTOMX.femur_inv[i], PHANTOMX.tibia_inv[i])
    return tuple(ax12_position_exact(-a if inv else a) for a, inv in zip(angles, invs))


#: the hobby PWM servo the phantomx preset puts in the AX-12's place (its comments say why):
#: 500..2500 us over 180 deg, 1500 us at the AX-12's centre position (driver angle 0)
HOBBY_CENTRE_US, HOBBY_US_PER_DEG = 1500.0, 2000.0 / 180.0


def hobby_pulses_exact(leg: str, x, y, z):
    """(coxa, femur, tibia) pulse in us (float64, unclamped): :func:`positions_exact`'s driver
    angle, ``(position - 512) * 300/1024`` deg, on the hobby servo above."""
    return tuple(HOBBY_CENTRE_US + HOBBY_US_PER_DEG * (p - PF_CONST) * AX_DEG_PER_UNIT
                 for p in positions_exact(leg, x, y, z))


def within_limits(leg: str, x, y, z):
    """True where every exact angle lies inside the leg's Hex_Cfg.h min/max."""
    return phoenix_code.within_limits(PHANTOMX, leg, x, y, z)


def stance_xz(leg: str, xz_length: int) -> tuple[int, int]:
    """AdjustLegPositions (_Phoenix_Code.h:2075-2110): the foot's (X, Z) at ``xz_length`` from
    the coxa along its mount, ``LegPosX = cos4 * XZLength1 / c4DEC``, ``LegPosZ = -sin4 * ...``."""
    sin4, cos4 = get_sin_cos(PHANTOMX.coxa_angle1[PHANTOMX.leg(leg)])
    return cdiv(cos4 * xz_length, C4DEC), -cdiv(sin4 * xz_length, C4DEC)


def walking_box(leg: str) -> dict[str, tuple[float, float]]:
    """The LegIK target box of the default walk (as for the Phoenix): the stances at both
    HEX_INIT_XZ lengths +-32 mm in X and Z, Y from the init height lifted by LegLiftHeight to
    it lowered by MAX_BODY_Y."""
    y0 = PHANTOMX.init_pos[PHANTOMX.leg(leg)][1]
    xs, zs = zip(*(stance_xz(leg, xz) for xz in HEX_INIT_XZ))
    return {"x": (min(xs) - HALF_TRAVEL, max(xs) + HALF_TRAVEL), "y": (y0 - LEG_LIFT_HEIGHT, y0 + MAX_BODY_Y),
            "z": (min(zs) - HALF_TRAVEL, max(zs) + HALF_TRAVEL)}


__all__ = ["LEGS", "PHANTOMX", "AX_DEG_PER_UNIT", "MAX_BODY_Y", "LEG_LIFT_HEIGHT", "HALF_TRAVEL",
           "ax12_position_firmware", "ax12_position_exact", "positions_firmware", "positions_exact",
           "within_limits", "stance_xz", "walking_box", "HEX_INIT_XZ", "HEX_MAX_BODY_Y", "HOBBY_CENTRE_US",
           "HOBBY_US_PER_DEG", "hobby_pulses_exact"]
