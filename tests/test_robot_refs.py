"""Sanity of the robot reference ports (tests/robot_refs): each source's own fixed points (its
init or neutral pose, its calibration points), FK round trips where the source has FK or the
geometry is closed-form, mirrored legs, and the firmware form against the exact one."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robot_refs import freenove, lynxmotion_phoenix as phoenix, mearm, phantomx, phoenix_code, spotmicro

LEGS = phoenix_code.LEGS


def _box_samples(box, n, seed=0, integer=False):
    rng = np.random.default_rng(seed)
    pts = [rng.uniform(*box[k], n) for k in ("x", "y", "z")]
    return [np.round(p).astype(int) for p in pts] if integer else pts


# -- the Phoenix code (both hexapods) ------------------------------------------------------

def test_phoenix_c_arithmetic():
    assert phoenix_code.cdiv(-7, 2) == -3 and phoenix_code.cdiv(7, -2) == -3 and phoenix_code.cdiv(7, 2) == 3
    assert phoenix_code.short(0x8000) == -0x8000 and phoenix_code.short(-1) == -1
    assert [phoenix_code.isqrt32(n) for n in (0, 1, 15, 16, 10 ** 8, 2 ** 32 - 1)] == [0, 1, 3, 4, 10 ** 4, 65535]
    # the tables' end points: acos(1) = 0, acos(0) = 255 * 616 / 10 = pi/2 (rad * 1e4), acos(-1) = pi
    assert phoenix_code.get_arc_cos(10000) == 0
    assert phoenix_code.get_arc_cos(0) == 15708
    assert phoenix_code.get_arc_cos(-10000) == 31416
    assert phoenix_code.get_sin_cos(300) == (5000 - 1, 8660)      # the 0.5 deg table: sin 30 = 4999
    assert phoenix_code.get_sin_cos(-900) == (-10000, 0)


@pytest.mark.parametrize("mod, cfg", [(phoenix, phoenix.PHOENIX), (phantomx, phantomx.PHANTOMX)])
def test_phoenix_fk_round_trip(mod, cfg):
    """leg_fk_exact(leg_ik_exact(p)) = p over each leg's walking box (where reachable)."""
    for leg in LEGS:
        x, y, z = _box_samples(mod.walking_box(leg), 500)
        angles = phoenix_code.leg_ik_exact(cfg, leg, x, y, z)
        ok = np.all(np.isfinite(angles), axis=0)
        assert ok.mean() > 0.9
        back = phoenix_code.leg_fk_exact(cfg, leg, *(a[ok] for a in angles))
        for got, want in zip(back, (x[ok], y[ok], z[ok])):
            np.testing.assert_allclose(got, want, atol=1e-9)


@pytest.mark.parametrize("mod, cfg", [(phoenix, phoenix.PHOENIX), (phantomx, phantomx.PHANTOMX)])
def test_phoenix_firmware_against_exact(mod, cfg):
    """The integer port tracks the float one to the tables' resolution (the source: 0.521 deg a
    look-up near cos = 1, Phoenix_Code.h:52; femur and tibia add two, the stretched knee the
    coarsest part): a sign or offset slip would be tens of degrees."""
    for leg in LEGS:
        x, y, z = _box_samples(mod.walking_box(leg), 300, seed=1, integer=True)
        ok = mod.within_limits(leg, x, y, z)
        exact = np.array(phoenix_code.leg_ik_exact(cfg, leg, x, y, z))[:, ok]
        firm = np.array([phoenix_code.leg_ik_firmware(cfg, leg, *p) for p in zip(x[ok], y[ok], z[ok])]).T / 10
        diff = np.abs(exact - firm)
        assert diff.max() < 5.0, (leg, diff.max(axis=1))
        assert np.median(diff) < 0.5, (leg, np.median(diff, axis=1))


def test_phoenix_init_pose_centres_the_coxas():
    """Hex_Cfg.h puts each init foot on its coxa's mount line (cos/sin 60 of cHexInitXZ), so LegIK
    gives coxa angle 0 and the SSC-32 map its centre, "900*(1000/cPwmDiv)+cPFConst must always
    be 1500" (Phoenix_Driver_SSC32.h:313)."""
    assert phoenix.ssc32_pulse_firmware(0) == 1500
    assert phoenix.ssc32_pulse_exact(0) == pytest.approx(1500.17, abs=0.01)
    for i, leg in enumerate(LEGS):
        coxa, femur, tibia = phoenix.pulses_firmware(leg, *phoenix.PHOENIX.init_pos[i])
        assert coxa == 1500
        assert phoenix.within_limits(leg, *phoenix.PHOENIX.init_pos[i])
    # 10.09 us per degree: the source's "PWM/deg factor of 10,09"
    assert phoenix.ssc32_pulse_exact(1) - phoenix.ssc32_pulse_exact(0) == pytest.approx(10.09, abs=0.005)


@pytest.mark.parametrize("mod, centre", [(phoenix, 900 * 1000 / 991 + 592), (phantomx, 512.0)])
def test_phoenix_mirrored_legs(mod, centre):
    """A left leg at the same LegIK target as its right twin (X is outwards on both sides) gets
    the same angles, and every joint's Inv flag differs between the sides (right coxa, femur,
    tibia 1, 1, 1 and left 0, 0, 0 by default; the PhantomX tibias 0 right, 1 left): the
    pulses mirror about the centre, joint by joint."""
    exact = mod.pulses_exact if mod is phoenix else mod.positions_exact
    firmware = mod.pulses_firmware if mod is phoenix else mod.positions_firmware
    cfg = mod.PHOENIX if mod is phoenix else mod.PHANTOMX
    for right, left in (("RR", "LR"), ("RM", "LM"), ("RF", "LF")):
        x, y, z = _box_samples(mod.walking_box(right), 200, seed=2)
        ok = mod.within_limits(right, x, y, z) & mod.within_limits(left, x, y, z)
        for pr, pl in zip(exact(right, x[ok], y[ok], z[ok]), exact(left, x[ok], y[ok], z[ok])):
            np.testing.assert_allclose(pr + pl, 2 * centre, atol=1e-9)
        i = cfg.leg(right)
        fr, fl = firmware(right, *cfg.init_pos[i]), firmware(left, *cfg.init_pos[i])
        assert all(abs(a + b - 2 * centre) <= 1.5 for a, b in zip(fr, fl)), (fr, fl)


def test_phantomx_units_and_horn_offsets():
    """AX-12: 512 at 0 deg, 1024 units over 300 deg (128/375 per 0.1 deg); the horn offsets of
    Hex_Cfg.h:38-39 (-3.5 and +46.3 deg) shift the femur and tibia angles by exactly those."""
    assert phantomx.ax12_position_firmware(0) == 512
    assert phantomx.ax12_position_exact(150.0) == pytest.approx(1024.0)
    assert phantomx.ax12_position_exact(-150.0) == pytest.approx(0.0)
    cfg = phantomx.PHANTOMX
    # Hex_Cfg.h:40-45: the tibias turn the other way round from the Phoenix default
    assert cfg.tibia_inv == tuple(not v for v in phoenix.PHOENIX.tibia_inv)
    bare = phoenix_code.PhoenixConfig(**{**cfg.__dict__, "femur_horn_offset1": 0, "tibia_horn_offset1": 0})
    for leg in LEGS:
        p = cfg.init_pos[cfg.leg(leg)]
        with_off = phoenix_code.leg_ik_exact(cfg, leg, *p)
        without = phoenix_code.leg_ik_exact(bare, leg, *p)
        assert float(with_off[1] - without[1]) == pytest.approx(-3.5)
        assert float(with_off[2] - without[2]) == pytest.approx(-46.3)    # tibia = -(900 - A3 + 463)
        assert phantomx.positions_firmware(leg, *p)[0] == 512


def test_phantomx_leg_positions_per_body_height():
    """AdjustLegPositions' stance at cHexInitXZ reproduces the Hex_Cfg.h init positions (to the
    source's rounding of 147 cos 45 = 103.9 to 104)."""
    for leg in LEGS:
        x0, _, z0 = phantomx.PHANTOMX.init_pos[phantomx.PHANTOMX.leg(leg)]
        x, z = phantomx.stance_xz(leg, 147)
        assert abs(x - x0) <= 1 and abs(z - z0) <= 1


# -- Freenove ------------------------------------------------------------------------------

def test_freenove_calibration_pose():
    """control.py's calibration pose (140, 0, 0) gives the angles its rounding IK returns there;
    the shipped point.txt (all 140 0 0) gives zero calibration angles, a moved point its own."""
    assert freenove.coordinate_to_angle_firmware(0, 140, 0) == (90, -67, 116)
    assert freenove.calibration_angles() == ((0, 0, 0),) * 6
    moved = ((140, 0, 0),) * 5 + ((150, 10, -5),)
    cal = freenove.calibration_angles(moved)
    want = np.subtract(freenove.coordinate_to_angle_firmware(5, 150, 10), (90, -67, 116))
    assert cal[5] == tuple(want) and cal[:5] == ((0, 0, 0),) * 5
    # servo angles at the calibration pose: right legs (90, 157, 116), left (90, 23, 64)
    assert tuple(float(v) for v in freenove.servo_angles(0, 90, -67, 116)) == (90, 157, 116)
    assert tuple(float(v) for v in freenove.servo_angles(3, 90, -67, 116)) == (90, 23, 64)
    assert freenove.pulse_us(90) == 1500.0 and freenove.pca9685_count(90) == 307


def test_freenove_standing_pose_is_the_same_for_every_leg():
    """body_points turned into each leg frame put every foot 140 mm out, on the coxa's line."""
    for leg in range(6):
        x, y, z = freenove.transform_coordinates(leg, *freenove.BODY_POINTS[leg], freenove.BODY_HEIGHT)
        assert x == pytest.approx(140.0, abs=0.25) and y == pytest.approx(0.0, abs=0.5) and z == -39


def test_freenove_fk_round_trip_and_rounding():
    x, y, z = _box_samples(freenove.walking_box(), 500, seed=3)
    a, b, c = freenove.coordinate_to_angle_exact(-z, x, y)
    back = freenove.angle_to_coordinate(a, b, c)
    for got, want in zip(back, (-z, x, y)):
        np.testing.assert_allclose(got, want, atol=1e-9)
    firm = np.array([freenove.coordinate_to_angle_firmware(-zz, xx, yy) for xx, yy, zz in zip(x, y, z)]).T
    diff = np.abs(np.array([a, b, c]) - firm)
    assert diff.max() < 1.5     # whole degrees, and the cosines rounded to 0.01 before acos/asin


def test_freenove_mirrored_legs():
    """Left legs mirror femur (90 +- b) and tibia (c vs 180 - c): right + left = 2 x 1500 us."""
    x, y, z = _box_samples(freenove.walking_box(), 200, seed=4)
    for right, left in ((0, 3), (1, 4), (2, 5)):
        r, l = freenove.pulses_exact(right, x, y, z), freenove.pulses_exact(left, x, y, z)
        np.testing.assert_allclose(r[0], l[0], atol=1e-9)
        np.testing.assert_allclose(r[1] + l[1], 3000.0, atol=1e-9)
        np.testing.assert_allclose(r[2] + l[2], 3000.0, atol=1e-9)


# -- SpotMicro -----------------------------------------------------------------------------

def test_spotmicro_centre_angles_give_centre_counts():
    """Each servo at its yaml center_angle_deg is commanded its center (306), and
    servo_max_angle_deg away its centre +- range/2 (direction-signed)."""
    for name, (_, center, rng, direction, center_deg) in spotmicro.SERVOS.items():
        ang = math.radians(center_deg)
        assert spotmicro.counts_exact(name, ang) == pytest.approx(center)
        up = spotmicro.counts_exact(name, ang + math.radians(spotmicro.SERVO_MAX_ANGLE_DEG))
        assert up == pytest.approx(center + direction * rng / 2)
        assert spotmicro.counts_exact(name, ang + 2) == up          # clipped at +1


def test_spotmicro_neutral_stance():
    """The neutral stance's foot is hip_link_length out from the shoulder, straight below the
    hip axis: ang1 = 0 on every leg, ikine's FK (ht0To4) gives the point back."""
    for leg in spotmicro.IS_LEG_12:
        p = spotmicro.body_to_leg(leg, spotmicro.neutral_stance(leg))
        assert p[0] == pytest.approx(-spotmicro.HIP_LINK) and p[1] == pytest.approx(-spotmicro.DEFAULT_STAND_HEIGHT)
        a = spotmicro.ikine(*p, spotmicro.IS_LEG_12[leg])
        assert float(a[0]) == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_allclose(spotmicro.ht0to4(*map(float, a))[:3, 3], p, atol=1e-12)


def test_spotmicro_fk_round_trip_and_mirror():
    stride = spotmicro.largest_stride()
    assert 0.0 < stride < spotmicro.touchdown_offset(spotmicro.MAX_FWD_VELOCITY)
    for leg in spotmicro.IS_LEG_12:
        box = spotmicro.walking_box(leg, stride)
        x, y, z = _box_samples(box, 100, seed=5)
        assert spotmicro.within_servo_range(leg, x, y, z).all()
        angs = spotmicro.ikine(x, y, z, spotmicro.IS_LEG_12[leg])
        for k in range(len(x)):
            np.testing.assert_allclose(spotmicro.ht0to4(*(float(a[k]) for a in angs))[:3, 3], (x[k], y[k], z[k]),
                                       atol=1e-12)
    # a left leg at the mirror image (z -> -z in its frame) turns the other way at shoulder and knee
    x, y, z = _box_samples(spotmicro.walking_box("RF", stride), 100, seed=6)
    r = spotmicro.ikine(x, y, z, True)
    l = spotmicro.ikine(x, y, -z, False)
    np.testing.assert_allclose(l[0], r[0], atol=1e-12)
    np.testing.assert_allclose(l[1], -r[1], atol=1e-12)
    np.testing.assert_allclose(l[2], -r[2], atol=1e-12)


def test_spotmicro_counts_firmware_truncates():
    assert spotmicro.counts_firmware("RF_1", math.radians(-5.4)) == 306
    v = float(spotmicro.counts_exact("RF_2", -0.5))
    assert spotmicro.counts_firmware("RF_2", -0.5) == math.trunc(v) and v != math.trunc(v)


# -- MeArm ---------------------------------------------------------------------------------

def test_mearm_calibration():
    """meArm.h's default calibration: gains -1.067, -1.067, +1.2 servo degrees per degree,
    zeros 97, 166, 90; each calibration point maps back to its servo degrees."""
    per_deg = {s: mearm.setup_servo(*mearm.CALIBRATION[s])[0] * math.pi / 180 for s in ("base", "shoulder", "elbow")}
    assert per_deg == pytest.approx({"base": -96 / 90, "shoulder": -96 / 90, "elbow": 108 / 90})
    zeros = [mearm.setup_servo(*mearm.CALIBRATION[s])[1] for s in ("base", "shoulder", "elbow")]
    assert zeros == pytest.approx([97.0, 166.0, 90.0])
    for s, (n_min, n_max, a_min, a_max) in mearm.CALIBRATION.items():
        assert mearm.angle2pwm(s, a_min) == n_min and mearm.angle2pwm(s, a_max) == n_max
    assert [mearm.servo_write_us(d) for d in (-5, 0, 90, 180, 200)] == [544, 544, 1472, 2400, 2400]


def test_mearm_fk_round_trip_and_path():
    """unsolve(solve(p)) = p along IKTest's path (every point the demo visits is reachable)."""
    for a, b in zip((mearm.HOME,) + mearm.IKTEST_PATH[:-1], mearm.IKTEST_PATH):
        for t in np.linspace(0.0, 1.0, 21):
            p = tuple(u + t * (v - u) for u, v in zip(a, b))
            angles = mearm.solve(*p)
            assert angles is not None, p
            assert mearm.unsolve(*angles) == pytest.approx(p, abs=1e-6)
            assert [float(v) for v in mearm.solve_exact(*p)] == pytest.approx(list(angles), abs=1e-9)
    assert mearm.solve(0.0, 300.0, 0.0) is None         # beyond L1 + L2 + L3


def test_mearm_firmware_against_exact_and_mirror():
    """goDirectlyTo's pulses: at most one servo degree (int(0.5 + ...)) and the map's integer
    step from the exact ones; a target mirrored in x mirrors the base about its zero."""
    for p in mearm.IKTEST_PATH:
        firm = mearm.pulses_firmware(*p)
        exact = [float(v) for v in mearm.pulses_exact(*p)]
        assert all(abs(f - e) <= 0.5 * 1856 / 180 + 1 for f, e in zip(firm, exact)), (firm, exact)
    x, y, z = 40.0, 150.0, 60.0
    r, l = mearm.pulses_exact(x, y, z), mearm.pulses_exact(-x, y, z)
    zero = mearm.pulse_us_exact(mearm.setup_servo(*mearm.CALIBRATION["base"])[1])
    assert float(r[0] + l[0]) == pytest.approx(2 * float(zero))
    assert float(r[1]) == pytest.approx(float(l[1])) and float(r[2]) == pytest.approx(float(l[2]))
    # the elbow servo follows the forearm's absolute angle: moving the shoulder alone at a fixed
    # forearm angle leaves the elbow's pulse unchanged (the linkage the MeArm is built with)
    a0, a1, a2 = mearm.solve(*mearm.HOME)
    assert mearm.angle2pwm("elbow", a2) == mearm.angle2pwm("elbow", mearm.solve(*mearm.unsolve(a0, a1 + 0.1, a2))[2])


# -- what ikseries' hexapod-leg expresses (docs/robots.md, last table) -----------------------

def test_hexapod_leg_expresses_one_leg():
    """One Phoenix / PhantomX / Freenove leg is hexapod-leg under the mapping docs/robots.md
    gives: the exact ports' servo angles and HexapodLeg.ik agree to 1e-9 deg over the boxes."""
    from ikseries.hexapod_leg import HexapodLeg
    wide = [[-180, 180]] * 3
    for mod, cfg, leg in ((phoenix, phoenix.PHOENIX, "RF"), (phantomx, phantomx.PHANTOMX, "LM")):
        i, bh = cfg.leg(leg), 200.0
        g = HexapodLeg(coxa=cfg.coxa[i], femur=cfg.femur[i], tibia=cfg.tibia[i], body_height=bh, joint_ranges=wide,
                       zero_offsets=[cfg.coxa_angle1[i] / 10, cfg.femur_horn_offset1 / 10, -cfg.tibia_horn_offset1 / 10],
                       angle_directions=[1, 1, -1])
        x, y, z = _box_samples(mod.walking_box(leg), 300, seed=8)
        ok = mod.within_limits(leg, x, y, z)
        want = np.array(phoenix_code.leg_ik_exact(cfg, leg, x[ok], y[ok], z[ok]))
        np.testing.assert_allclose(np.array(g.ik(x[ok], z[ok], bh - y[ok])), want, atol=1e-9)
    x, y, z = _box_samples(freenove.walking_box(), 300, seed=9)
    a, b, c = freenove.coordinate_to_angle_exact(-z, x, y)
    for dirs, want in (([-1, -1, 1], (a, 90 - b, c)), ([-1, 1, -1], (a, 90 + b, 180 - c))):
        g = HexapodLeg(coxa=freenove.L1, femur=freenove.L2, tibia=freenove.L3, body_height=100.0,
                       joint_ranges=[[-90, 270]] * 3, zero_offsets=[90, 90, 90], angle_directions=dirs)
        np.testing.assert_allclose(np.array(g.ik(x, y, 100.0 + z)), np.array(want), atol=1e-9)
