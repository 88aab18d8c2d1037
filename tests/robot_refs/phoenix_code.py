"""The Phoenix code's leg IK (shared by the Lynxmotion Phoenix and the PhantomX), ported.

Source: KurtE/Arduino_Phoenix_Parts @ 35eb0e1a (2018-11-21), ``Phoenix/Phoenix_Code.h``
(cited below as ``Phoenix_Code.h:LINE``). KurtE/Phantom_Phoenix @ 17784a5a carries the same
code as ``_Phoenix_Code.h`` (``LegIK`` at its line 1800, identical line for line but for
whitespace), so one port serves both robots; their constants live in
:mod:`robot_refs.lynxmotion_phoenix` and :mod:`robot_refs.phantomx`.

Two forms of the same formulas:

- :func:`leg_ik_firmware`: the firmware's own fixed-point arithmetic, integer for integer
  (C division truncating toward zero, the ``short`` casts, the 0.5-degree sine table and the
  three-part arc-cosine table). This is what the robot really sends; its table error (up to
  0.5 deg near cos = 1, ``Phoenix_Code.h:52``) is the firmware's, not the formula's.
- :func:`leg_ik_exact`: the same structure in float64 with the exact functions the tables
  approximate (``acos``, ``atan2``, ``hypot``, radians to degrees by 180/pi where the firmware
  uses 180/3.141). It is the reference for comparisons at a fraction of a pulse unit.

Frame of ``LegIK(IKFeetPosX, IKFeetPosY, IKFeetPosZ, leg)`` (``Phoenix_Code.h:1669``): mm from
the leg's coxa axis, body-aligned (not turned with the coxa mount): X outwards from the body
on both sides (the right legs' X is negated by the caller, ``Phoenix_Code.h:815-822``), Y
down (the foot below the coxa is positive Y), Z along the body (rear positive). Output
angles in 0.1 deg ("decimals = 1").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Phoenix.h:55-58
C1DEC, C2DEC, C4DEC, C6DEC = 10, 100, 10000, 1000000

# Phoenix_Code.h:58-68, "ArcCosinus Table ... in to 3 part": 0..0.9 in steps of 1/127,
# 0.9..0.99 in steps of 0.1/127, 0.99..1 in steps of 0.01/64; entries in units of
# (pi/2)/255 rad (see the 616 factor in GetArcCos)
GET_ACOS = (
    255, 254, 252, 251, 250, 249, 247, 246, 245, 243, 242, 241, 240, 238, 237, 236, 234, 233, 232, 231, 229, 228, 227, 225,
    224, 223, 221, 220, 219, 217, 216, 215, 214, 212, 211, 210, 208, 207, 206, 204, 203, 201, 200, 199, 197, 196, 195, 193,
    192, 190, 189, 188, 186, 185, 183, 182, 181, 179, 178, 176, 175, 173, 172, 170, 169, 167, 166, 164, 163, 161, 160, 158,
    157, 155, 154, 152, 150, 149, 147, 146, 144, 142, 141, 139, 137, 135, 134, 132, 130, 128, 127, 125, 123, 121, 119, 117,
    115, 113, 111, 109, 107, 105, 103, 101, 98, 96, 94, 92, 89, 87, 84, 81, 79, 76, 73, 73, 73, 72, 72, 72, 71, 71, 71, 70, 70,
    70, 70, 69, 69, 69, 68, 68, 68, 67, 67, 67, 66, 66, 66, 65, 65, 65, 64, 64, 64, 63, 63, 63, 62, 62, 62, 61, 61, 61, 60, 60, 59,
    59, 59, 58, 58, 58, 57, 57, 57, 56, 56, 55, 55, 55, 54, 54, 53, 53, 53, 52, 52, 51, 51, 51, 50, 50, 49, 49, 48, 48, 47, 47, 47,
    46, 46, 45, 45, 44, 44, 43, 43, 42, 42, 41, 41, 40, 40, 39, 39, 38, 37, 37, 36, 36, 35, 34, 34, 33, 33, 32, 31, 31, 30, 29, 28,
    28, 27, 26, 25, 24, 23, 23, 23, 23, 22, 22, 22, 22, 21, 21, 21, 21, 20, 20, 20, 19, 19, 19, 19, 18, 18, 18, 17, 17, 17, 17, 16,
    16, 16, 15, 15, 15, 14, 14, 13, 13, 13, 12, 12, 11, 11, 10, 10, 9, 9, 8, 7, 6, 6, 5, 3, 0)

# Phoenix_Code.h:71-82, "Sin table 90 deg, persision 0.5 deg [180 values]", sin * 10000
GET_SIN = (
    0, 87, 174, 261, 348, 436, 523, 610, 697, 784, 871, 958, 1045, 1132, 1218, 1305, 1391, 1478, 1564,
    1650, 1736, 1822, 1908, 1993, 2079, 2164, 2249, 2334, 2419, 2503, 2588, 2672, 2756, 2840, 2923, 3007,
    3090, 3173, 3255, 3338, 3420, 3502, 3583, 3665, 3746, 3826, 3907, 3987, 4067, 4146, 4226, 4305, 4383,
    4461, 4539, 4617, 4694, 4771, 4848, 4924, 4999, 5075, 5150, 5224, 5299, 5372, 5446, 5519, 5591, 5664,
    5735, 5807, 5877, 5948, 6018, 6087, 6156, 6225, 6293, 6360, 6427, 6494, 6560, 6626, 6691, 6755, 6819,
    6883, 6946, 7009, 7071, 7132, 7193, 7253, 7313, 7372, 7431, 7489, 7547, 7604, 7660, 7716, 7771, 7826,
    7880, 7933, 7986, 8038, 8090, 8141, 8191, 8241, 8290, 8338, 8386, 8433, 8480, 8526, 8571, 8616, 8660,
    8703, 8746, 8788, 8829, 8870, 8910, 8949, 8987, 9025, 9063, 9099, 9135, 9170, 9205, 9238, 9271, 9304,
    9335, 9366, 9396, 9426, 9455, 9483, 9510, 9537, 9563, 9588, 9612, 9636, 9659, 9681, 9702, 9723, 9743,
    9762, 9781, 9799, 9816, 9832, 9848, 9862, 9876, 9890, 9902, 9914, 9925, 9935, 9945, 9953, 9961, 9969,
    9975, 9981, 9986, 9990, 9993, 9996, 9998, 9999, 10000)

#: leg order of every per-leg table (Phoenix_Code.h:217-281): right rear, middle, front, then left
LEGS = ("RR", "RM", "RF", "LR", "LM", "LF")


@dataclass(frozen=True)
class PhoenixConfig:
    """A robot's ``Hex_Cfg.h`` numbers as the Phoenix code reads them (per leg, in :data:`LEGS`
    order; angles in 0.1 deg, lengths in mm)."""
    coxa: tuple[int, ...]
    femur: tuple[int, ...]
    tibia: tuple[int, ...]
    coxa_angle1: tuple[int, ...]        # cXXCoxaAngle1: the coxa's mount direction
    offset_x: tuple[int, ...]           # cXXOffsetX / Z: coxa axis from the body centre
    offset_z: tuple[int, ...]
    init_pos: tuple[tuple[int, int, int], ...]   # cXXInitPosX, Y, Z
    coxa_minmax: tuple[tuple[int, int], ...]     # cXXCoxaMin1, cXXCoxaMax1 (mechanical limits)
    femur_minmax: tuple[tuple[int, int], ...]
    tibia_minmax: tuple[tuple[int, int], ...]
    coxa_inv: tuple[bool, ...]          # cXXCoxaInv: the angle's sign flipped before the driver
    femur_inv: tuple[bool, ...]
    tibia_inv: tuple[bool, ...]
    femur_horn_offset1: int = 0         # cFemurHornOffset1 (Phoenix_Code.h:185-188: 0 if undefined)
    tibia_horn_offset1: int = 0         # cTibiaHornOffset1 (Phoenix_Code.h:196-199)

    def leg(self, name: str) -> int:
        if name not in LEGS:
            raise ValueError(f"leg must be one of {', '.join(LEGS)}, not {name!r}")
        return LEGS.index(name)


# -- C arithmetic -------------------------------------------------------------------------

def cdiv(a: int, b: int) -> int:
    """C's integer division (truncates toward zero; Python's // floors)."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


def short(v: int) -> int:
    """A value stored in a 16-bit ``short`` (two's complement wrap)."""
    return ((v + 0x8000) & 0xFFFF) - 0x8000


# -- the firmware's functions, ported -----------------------------------------------------

def isqrt32(n: int) -> int:
    """Phoenix_Code.h:1544-1567, the bitwise integer square root (floor)."""
    root, remainder, place = 0, n, 0x40000000
    while place > remainder:
        place >>= 2
    while place:
        if remainder >= root + place:
            remainder = remainder - root - place
            root = root + (place << 1)
        root >>= 1
        place >>= 2
    return root


def get_arc_cos(cos4: int) -> int:
    """Phoenix_Code.h:1506-1542: arc cosine of ``cos4`` (cos * 10000) in rad * 10000."""
    cos4 = short(cos4)                         # "long GetArcCos(short cos4)"
    negative = cos4 < 0
    cos4 = min(abs(cos4), C4DEC)               # :1519 "cos4 = min(cos4,c4DEC)"
    if cos4 < 9000:                            # :1521-1524
        rad4 = cdiv(GET_ACOS[cdiv(cos4, 79)] * 616, C1DEC)   # "616=acos resolution (pi/2/255)"
    elif cos4 < 9900:                          # :1526-1529
        rad4 = cdiv(GET_ACOS[cdiv(cos4 - 9000, 8) + 114] * 616, C1DEC)
    else:                                      # :1531-1534
        rad4 = cdiv(GET_ACOS[cdiv(cos4 - 9900, 2) + 227] * 616, C1DEC)
    if negative:                               # :1538 "AngleRad4 = 31416 - AngleRad4"
        rad4 = 31416 - rad4
    return short(rad4)                         # AngleRad4 is a short (:441)


def get_atan2(atan_x: int, atan_y: int) -> tuple[int, int]:
    """Phoenix_Code.h:1576-1586: ``(Atan4, XYhyp2)``: the angle of (x, y) from the x axis,
    rad * 10000, signed as y; and the hypotenuse * 100."""
    xy_hyp2 = isqrt32(atan_x * atan_x * C4DEC + atan_y * atan_y * C4DEC)      # :1578
    rad4 = get_arc_cos(cdiv(atan_x * C6DEC, xy_hyp2))                          # :1579
    return (-rad4 if atan_y < 0 else rad4), xy_hyp2                           # :1581-1584


def get_sin_cos(angle_deg1: int) -> tuple[int, int]:
    """Phoenix_Code.h:1462-1499: ``(sin4, cos4)`` of an angle in 0.1 deg (for BodyFK)."""
    a = abs(angle_deg1)
    a = 3600 - (a - 3600 * (a // 3600)) if angle_deg1 < 0 else a - 3600 * (a // 3600)
    if 0 <= a <= 900:
        return GET_SIN[a // 5], GET_SIN[(900 - a) // 5]
    if a <= 1800:
        return GET_SIN[(900 - (a - 900)) // 5], -GET_SIN[(a - 900) // 5]
    if a <= 2700:
        return -GET_SIN[(a - 1800) // 5], -GET_SIN[(2700 - a) // 5]
    return -GET_SIN[(3600 - a) // 5], GET_SIN[(a - 2700) // 5]


def leg_ik_firmware(cfg: PhoenixConfig, leg: str, x: int, y: int, z: int) -> tuple[int, int, int]:
    """``LegIK`` (Phoenix_Code.h:1669-1837, 3 DOF, not upside down, not ``PHANTOMX_V2``):
    (coxa, femur, tibia) angles in 0.1 deg, before ``CheckAngles`` and the ``Inv`` flips."""
    i = cfg.leg(leg)
    x, y, z = short(int(x)), short(int(y)), short(int(z))
    f, t = cfg.femur[i], cfg.tibia[i]
    atan4, xy_hyp2 = get_atan2(x, z)                                           # :1693
    coxa1 = cdiv(atan4 * 180, 3141) + cfg.coxa_angle1[i]                        # :1694
    feet_xz = short(cdiv(xy_hyp2, C2DEC))                                      # :1697
    ika14, iksw2 = get_atan2(y, feet_xz - cfg.coxa[i])                          # :1735-1738
    temp1 = (f * f - t * t) * C4DEC + iksw2 * iksw2                            # :1741
    temp2 = 2 * f * C2DEC * iksw2                                              # :1742
    ika24 = get_arc_cos(cdiv(temp1, cdiv(temp2, C4DEC)))                        # :1743-1744
    femur1 = cdiv(-(ika14 + ika24) * 180, 3141) + 900 + cfg.femur_horn_offset1  # :1768
    temp1 = (f * f + t * t) * C4DEC - iksw2 * iksw2                            # :1772
    temp2 = 2 * f * t                                                          # :1773
    rad4 = get_arc_cos(cdiv(temp1, temp2))                                      # :1774
    tibia1 = -(900 - cdiv(rad4 * 180, 3141) + cfg.tibia_horn_offset1)           # :1795
    return short(coxa1), short(femur1), short(tibia1)


def check_angles(cfg: PhoenixConfig, leg: str, angles1):
    """``CheckAngles`` (Phoenix_Code.h:1842-1896): each angle clamped to its leg's min/max."""
    i = cfg.leg(leg)
    bounds = (cfg.coxa_minmax[i], cfg.femur_minmax[i], cfg.tibia_minmax[i])
    return tuple(min(max(a, lo), hi) for a, (lo, hi) in zip(angles1, bounds))


def driver_angles(cfg: PhoenixConfig, leg: str, angles1):
    """The angles handed to the servo driver (Phoenix_Code.h:1001-1004: ``cXXInv ? -a : a``)."""
    i = cfg.leg(leg)
    invs = (cfg.coxa_inv[i], cfg.femur_inv[i], cfg.tibia_inv[i])
    return tuple(-a if inv else a for a, inv in zip(angles1, invs))


# -- the same formulas in float64 ----------------------------------------------------------

def leg_ik_exact(cfg: PhoenixConfig, leg: str, x, y, z):
    """:func:`leg_ik_firmware` with exact functions: (coxa, femur, tibia) in degrees (float64,
    numpy-broadcast), before the limits and the ``Inv`` flips. NaN where unreachable."""
    i = cfg.leg(leg)
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    f, t = float(cfg.femur[i]), float(cfg.tibia[i])
    deg = 180.0 / math.pi
    coxa = np.arctan2(z, x) * deg + cfg.coxa_angle1[i] / 10.0                  # :1693-1694
    feet_xz = np.hypot(x, z)                                                   # :1697
    ika1 = np.arctan2(feet_xz - cfg.coxa[i], y)                                # :1735, acos(y/sw) signed
    sw = np.hypot(y, feet_xz - cfg.coxa[i])                                    # :1738
    with np.errstate(invalid="ignore"):
        ika2 = np.arccos((f * f - t * t + sw * sw) / (2 * f * sw))             # :1741-1744
        a3 = np.arccos((f * f + t * t - sw * sw) / (2 * f * t))                # :1772-1774
    femur = -(ika1 + ika2) * deg + 90.0 + cfg.femur_horn_offset1 / 10.0         # :1768
    tibia = -(90.0 - a3 * deg + cfg.tibia_horn_offset1 / 10.0)                 # :1795
    return coxa, femur, tibia


def leg_fk_exact(cfg: PhoenixConfig, leg: str, coxa, femur, tibia):
    """Inverse of :func:`leg_ik_exact` (angles in degrees as it returns them) -> (x, y, z) mm.
    The firmware has no FK; this is the geometry LegIK solves, for the round-trip tests."""
    i = cfg.leg(leg)
    rad = math.pi / 180.0
    yaw = (np.asarray(coxa, dtype=np.float64) - cfg.coxa_angle1[i] / 10.0) * rad
    # femur = 90 - (A1 + A2) + horn: the femur's direction from the downward vertical is A1 + A2
    fdir = (90.0 - (np.asarray(femur, dtype=np.float64) - cfg.femur_horn_offset1 / 10.0)) * rad
    a3 = (90.0 + np.asarray(tibia, dtype=np.float64) + cfg.tibia_horn_offset1 / 10.0) * rad
    # knee interior angle a3: the tibia turns back from the femur direction by pi - a3
    tdir = fdir - (math.pi - a3)
    rho = cfg.coxa[i] + cfg.femur[i] * np.sin(fdir) + cfg.tibia[i] * np.sin(tdir)
    down = cfg.femur[i] * np.cos(fdir) + cfg.tibia[i] * np.cos(tdir)
    return rho * np.cos(yaw), down, rho * np.sin(yaw)


def legik_target(cfg: PhoenixConfig, leg: str, xb, yb, zb, body_height: float):
    """LegIK's target (X, Y, Z) of a point in the presets' body frame (x forward, y left, z up,
    origin on the ground; the coxas ``body_height`` above it). LegIK's frame is body-aligned at
    the coxa, X out on both sides (the caller negates a right leg's, Phoenix_Code.h:815-822),
    Y down, Z rear; the body's is X left, Z rear (Hex_Cfg.h cXXOffsetX/Z), so x = -Z, y = X,
    z = body_height - Y."""
    i = cfg.leg(leg)
    x_out = np.asarray(yb, dtype=np.float64) - cfg.offset_x[i]
    return (x_out if leg[0] == "L" else -x_out), body_height - np.asarray(zb, dtype=np.float64), \
        -np.asarray(xb, dtype=np.float64) - cfg.offset_z[i]


def within_limits(cfg: PhoenixConfig, leg: str, x, y, z):
    """True where every exact angle of ``leg`` lies inside its Hex_Cfg.h min/max (the firmware's
    CheckAngles clamps instead; nothing is clamped here)."""
    i = cfg.leg(leg)
    bounds = (cfg.coxa_minmax[i], cfg.femur_minmax[i], cfg.tibia_minmax[i])
    ok = np.ones(np.broadcast(np.asarray(x), np.asarray(y), np.asarray(z)).shape, dtype=bool)
    for a, (lo, hi) in zip(leg_ik_exact(cfg, leg, x, y, z), bounds):
        ok &= (a >= lo / 10.0) & (a <= hi / 10.0)
    return ok
