"""Bodies: [body] parsing and its messages, body <-> leg frames, the phoenix preset against the
Phoenix firmware's own IK, left legs as mirrored right legs (reference, golden model, Amaranth
simulation of RobotCore), the channel table's hardware and what a trim or limit change regenerates."""
from __future__ import annotations

import dataclasses
import re
import tomllib

import numpy as np
import pytest

from helpers import shared_fit
from robot_refs import lynxmotion_phoenix as phoenix, phoenix_code
from robot_refs.phoenix_code import LEGS
from ikseries.body import BodyLeg, body_to_leg, body_to_mount, leg_to_body, mirror, mount_to_body
from ikseries.channels import body_pulses_pu, channel_calibration, channel_pulses_pu, channel_records, channel_table
from ikseries.fit.channels import ChannelTable, TableChannel
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.hdl.export import robot_verilog
from ikseries.hdl.shared import TABLE_LATENCY, RobotCore
from ikseries.robot import RobotError, load_preset, parse_robot, preset_text, robot_from_record, robot_record
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_robot
from ikseries.sim.targets import corner_targets, random_targets

#: tests/robot_refs' Phoenix frame: LegIK Y is down from the coxa, which stands body_height up
PHOENIX_BODY_HEIGHT = 60.0


def phoenix_data() -> dict:
    return tomllib.loads(preset_text("phoenix"))


def with_body(body_legs=None, **top) -> dict:
    d = phoenix_data()
    if body_legs is not None:
        d["body"] = {"legs": body_legs}
    d.update(top)
    return d


# -- description ---------------------------------------------------------------------------
def test_body_defines_the_legs_and_records_round_trip():
    r = load_preset("phoenix")
    assert r.legs == 6 and r.body.names == LEGS
    assert [leg.side for leg in r.body.legs] == ["right"] * 3 + ["left"] * 3
    again = robot_from_record(robot_record(r))
    assert again == r
    # the body decides the fit only by the mirror's margin: the plan-cache key is that of the
    # bare robot at the reduced tolerance
    bare = dataclasses.replace(r, body=None)
    tighter = dataclasses.replace(bare, fit=dataclasses.replace(bare.fit, tolerance_pu=r.fitted.fit.tolerance_pu))
    assert r.fit_record() == tighter.fit_record() != bare.fit_record()


def test_no_body_keeps_the_record():
    for name in ("hexapod", "cylinder-leg"):
        r = load_preset(name)
        assert r.body is None and "body" not in robot_record(r)


_LEG = {"name": "A", "x": 0.0, "y": 0.0, "z": 0.0, "yaw": 0.0, "side": "right"}


@pytest.mark.parametrize("data, message", [
    (with_body([_LEG, {**_LEG, "name": "B", "side": "left"}, {**_LEG, "name": "A"}]),
     "body.legs[2].name must be unique, not 'A' (body.legs[0] has it)"),
    (with_body([_LEG, {**_LEG, "name": "B", "yaw": float("nan")}]), "body.legs[1].yaw must be finite, not nan"),
    (with_body([_LEG, {**_LEG, "name": "B", "side": "middle"}]),
     "body.legs[1].side must be one of right, left, not 'middle'"),
    (with_body([_LEG, {**_LEG, "name": "B"}], legs=6),
     "legs must be 2 (the number of [[body.legs]]) or absent, not 6"),
    (with_body([_LEG]), "body.legs must hold at least 2 legs (the legs of a body share one robot core, "
                        "which applies the mirror and the channel table), not 1"),
    (with_body([_LEG, {**_LEG, "name": "B", "x": "far"}]), "body.legs[1].x must be a number, not 'far'"),
    (with_body([_LEG, {**_LEG, "name": "B", "roll": 1.0}]),
     "unknown field body.legs[1].roll (expected one of: name, servos, side, x, y, yaw, z)"),
    (with_body([_LEG, {**_LEG, "name": "1B"}]),
     "body.legs[1].name must be an ASCII letter followed by at most 15 ASCII letters, digits, '-' and '_', "
     "not '1B'"),
])
def test_body_messages(data, message):
    with pytest.raises(RobotError) as e:
        parse_robot(data)
    assert str(e.value) == message


def test_body_needs_a_symmetric_y_box_with_left_legs_and_a_cartesian_target():
    d = phoenix_data()
    d["workspace"]["y"]["min"] = -30.0
    with pytest.raises(RobotError) as e:
        parse_robot(d)
    assert str(e.value) == ("workspace.y must be symmetric about 0 (min = -max) with a left leg (LR: its target is "
                            "mirrored, y -> -y, onto the one box), not [-30, 32]")
    d = phoenix_data()
    d["body"]["legs"] = [leg for leg in d["body"]["legs"] if leg["side"] == "right"]
    d["workspace"]["y"]["min"] = -30.0
    assert parse_robot(d).legs == 3                 # right legs only: no mirror, any box
    cyl = tomllib.loads(preset_text("cylinder-leg"))
    cyl["body"] = {"legs": [_LEG, {**_LEG, "name": "B"}]}
    with pytest.raises(RobotError) as e:
        parse_robot(cyl)
    assert str(e.value) == "body needs a geometry with a Cartesian target (x, y, z) mm, not (r, theta, z)"


# -- frames ----------------------------------------------------------------------------------
def test_body_leg_frames_round_trip():
    rng = np.random.default_rng(3)
    p = rng.uniform(-300, 300, (3, 1000))
    for k in range(20):
        x, y, z, yaw = rng.uniform(-200, 200, 3).tolist() + [float(rng.uniform(-360, 360))]
        leg = BodyLeg("L", x, y, z, yaw, "left" if k % 2 else "right")
        for there, back in ((body_to_leg, leg_to_body), (body_to_mount, mount_to_body), (mirror, mirror)):
            np.testing.assert_allclose(np.array(back(leg, *there(leg, *p))), p, atol=1e-9)
        # a point on the leg's rest direction, r out from the mount, is (r, 0, dz) in its frames
        r = rng.uniform(10, 100, 1000)
        q = (x + r * np.cos(np.radians(yaw)), y + r * np.sin(np.radians(yaw)), z + p[2])
        np.testing.assert_allclose(np.array(body_to_leg(leg, *q)), [r, np.zeros_like(r), p[2]], atol=1e-9)
    # a point counter-clockwise of a left leg's rest direction: y > 0 in its mount frame, < 0 in
    # its (mirrored) leg frame
    left = BodyLeg("L", 0.0, 0.0, 0.0, 90.0, "left")
    np.testing.assert_allclose(body_to_mount(left, -10.0, 50.0, 0.0), (50.0, 10.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(body_to_leg(left, -10.0, 50.0, 0.0), (50.0, -10.0, 0.0), atol=1e-12)


def test_phoenix_preset_is_the_phoenix_firmware_exact_ik():
    """Body-frame targets of every leg's box: the preset's channel pulses are the Phoenix's own
    (LegIK, the Inv flip, the SSC-32 map; the exact form) to 1e-9 us, inside its per-leg limits."""
    r = load_preset("phoenix")
    rng = np.random.default_rng(5)
    lx, ly, lz = (rng.uniform(s.min, s.max, 400) for s in r.workspace.inputs)
    for k, name in enumerate(LEGS):
        xb, yb, zb = leg_to_body(r.body.legs[k], lx, ly, lz)
        mine = np.array(body_pulses_pu(r, name, xb, yb, zb)) * r.calibration.pulse_unit_us
        X, Y, Z = phoenix_code.legik_target(phoenix.PHOENIX, name, xb, yb, zb, PHOENIX_BODY_HEIGHT)
        assert phoenix.within_limits(name, X, Y, Z).all()
        np.testing.assert_allclose(mine, np.array(phoenix.pulses_exact(name, X, Y, Z)), rtol=0, atol=1e-9)


def test_left_leg_pulses_are_the_mirrored_right_legs():
    """Body targets mirrored in the body's x-z plane: LF's pulses are 2 centre - RF's, channel
    by channel (the reference, 1e-9 pu)."""
    r = load_preset("phoenix")
    rng = np.random.default_rng(6)
    lx, ly, lz = (rng.uniform(s.min, s.max, 300) for s in r.workspace.inputs)
    centre = r.calibration.neutral_pulse_pu
    for right, left in (("RR", "LR"), ("RM", "LM"), ("RF", "LF")):
        xb, yb, zb = leg_to_body(r.body.leg(right)[1], lx, ly, lz)
        pr = np.array(body_pulses_pu(r, right, xb, yb, zb))
        pl = np.array(body_pulses_pu(r, left, xb, -yb, zb))
        np.testing.assert_allclose(pl, 2 * centre - pr, rtol=0, atol=1e-9)


def test_channel_calibration_and_table_of_phoenix():
    r = load_preset("phoenix")
    cal = channel_calibration(r)
    tpu = r.ticks_per_pu
    assert len(cal) == 18 and [c.leg_name for c in cal[::3]] == list(LEGS)
    assert [c.direction for c in cal] == [-1] * 9 + [1] * 9      # cXXInv: right 1 (pulse falls), left 0
    t = channel_table(r)
    assert t.mirror_input == "y" and t.mirrored == (False,) * 3 + (True,) * 3
    twice = int(np.rint(2 * r.calibration.neutral_pulse_pu * tpu))
    assert [c.sign for c in t.channels] == [1] * 9 + [-1] * 9
    assert [c.offset for c in t.channels] == [0] * 9 + [twice] * 9
    base = r.pulse_limits_ticks()      # each leg's own clamp (tests/test_preset_agreement.py), inside the plan's
    assert all(base[s][0] <= c.lo < c.hi <= base[s][1] for c, s in zip(t.channels, r.servos * 6))
    recs = channel_records(r, {k: f"p{k}" for k in range(18)})
    assert recs[9]["leg_name"] == "LR" and recs[9]["mirrored"] and recs[9]["port"] == "p9"
    assert recs[9]["mirror_error_ticks"] == pytest.approx(abs(twice - 2 * r.calibration.neutral_pulse_pu * tpu))
    assert recs[0]["mount"] == {"x": -82.0, "y": -43.0, "z": 0.0, "yaw": -150.0}
    assert channel_table(load_preset("hexapod")).mirror_input is None


# -- hardware ---------------------------------------------------------------------------------
def mirror_plan():
    """Inputs a (unsigned) and y (symmetric in range, its port one value wider: -8 is out of
    range), three non-negative outputs."""
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("y", "mm", 0, -7, 7, 4, True)])
    a, y = b.input_nodes["a"], b.input_nodes["y"]
    s1 = b.clamp(b.add(b.mul(a, y), b.const(120, 0)), 10, 230)
    s2 = b.clamp(b.add(b.mul(a, a), y), 0, 230)
    s3 = b.clamp(b.add(b.mul(y, y), b.const(7, 0)), 5, 60)
    return b.build([PlanOutput(n, v, v, "ticks", 1.0) for n, v in (("s1", s1), ("s2", s2), ("s3", s3))])


def mirror_table() -> ChannelTable:
    """Leg 0 right with trims, legs 1 and 2 left (mirrored, one servo not), narrow limits."""
    T = TableChannel
    chans = (T(1, 3, 10, 230), T(1, 0, 0, 200), T(1, -2, 5, 60),
             T(-1, 240, 10, 230), T(-1, 230, 0, 230), T(1, 0, 5, 60),
             T(-1, 235, 50, 200), T(1, 5, 0, 230), T(-1, 65, 5, 60))
    return ChannelTable(3, ("s1", "s2", "s3"), "y", (False, True, True), chans)


def _every_target(plan, legs: int, n_random: int, seed: int):
    c = corner_targets(plan, port_extremes=True)
    t = random_targets(plan, n_random, seed)
    t = {k: np.concatenate([np.tile(c[k], legs), t[k]]) for k in c}
    nc = len(next(iter(c.values())))
    lg = np.concatenate([np.repeat(np.arange(legs), nc), np.random.default_rng(seed).integers(0, legs, n_random)])
    return t, lg


def test_robot_core_channel_table_is_bit_exact_with_the_golden_model():
    plan, table = mirror_plan(), mirror_table()
    core = RobotCore(plan, 3, period=500, clock_hz=1e6, multipliers=1, channels=table)
    assert core.channels is table
    assert core.latency == core.evaluator.latency + TABLE_LATENCY
    assert core.initiation_interval == core.evaluator.initiation_interval + TABLE_LATENCY
    t, legs = _every_target(plan, 3, 150, 7)
    res = simulate_robot(core, legs, t)
    exp = golden.robot_outputs(plan, table, legs, t)
    assert np.array_equal(res.legs, legs)
    for s in core.servos:
        assert np.array_equal(res.outputs[s], exp[s]), s
    assert set(res.latencies.tolist()) == {core.latency}
    assert set(np.diff(res.input_cycles).tolist()) == {core.initiation_interval}
    res = simulate_robot(core, legs[:60], {k: v[:60] for k, v in t.items()}, ready_prob=0.3, seed=2)
    assert all(np.array_equal(res.outputs[s], exp[s][:60]) for s in core.servos)


def test_golden_channel_table_semantics():
    """The table's meaning, spelled out: a mirrored leg sees -y (the out-of-range port value
    -8 saturates to 7), then offset + sign * width saturated to [lo, hi]."""
    plan, table = mirror_plan(), mirror_table()
    t = {"a": np.array([3, 3, 15, 0]), "y": np.array([5, 5, -8, -8])}
    legs = np.array([0, 1, 1, 2])
    got = golden.robot_outputs(plan, table, legs, t)
    plain = golden.outputs(plan, {"a": t["a"], "y": np.array([5, -5, 7, 7])})   # mirrored by hand
    for s in table.servos:
        want = [min(max(c.offset + c.sign * int(w), c.lo), c.hi)
                for c, w in zip((table.channel(int(k), s) for k in legs), plain[s])]
        assert got[s].tolist() == want, s


def test_identity_table_gives_the_core_without_a_table():
    """No mirrored leg, signs +1, offsets 0, limits at the plan's clamp: no stage, the same
    Verilog as a core given no table."""
    plan = mirror_plan()
    lims = [(10, 230), (0, 230), (5, 60)]
    table = ChannelTable(2, ("s1", "s2", "s3"), None, (False, False),
                         tuple(TableChannel(1, 0, *lims[j]) for _ in range(2) for j in range(3)))
    a = RobotCore(plan, 2, period=500, clock_hz=1e6, channels=table)
    b = RobotCore(plan, 2, period=500, clock_hz=1e6)
    assert a.channels is None and a.latency == b.latency
    assert robot_verilog(a, "m") == robot_verilog(b, "m")


def test_channel_table_messages():
    plan = mirror_plan()
    bad = dataclasses.replace(mirror_table(), channels=(TableChannel(1, 0, 0, 256),) + mirror_table().channels[1:])
    with pytest.raises(ValueError) as e:
        RobotCore(plan, 3, period=500, clock_hz=1e6, channels=bad)
    assert str(e.value) == "channel 0 (leg 0 s1) limits [0, 256] ticks must fit the plan's 8-bit unsigned output [0, 255]"
    b = PlanBuilder([PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("y", "mm", 0, -8, 7, 4, True)])
    lop = b.build([PlanOutput(n, b.clamp(b.add(b.input_nodes["a"], b.input_nodes["y"]), 0, 30), 0, "ticks", 1.0)
                   for n in ("s1", "s2", "s3")])
    table = ChannelTable(3, ("s1", "s2", "s3"), "y", (False, True, True), tuple(TableChannel(1, 0, 0, 30)
                                                                                for _ in range(9)))
    with pytest.raises(ValueError) as e:
        RobotCore(lop, 3, period=500, clock_hz=1e6, channels=table)
    assert str(e.value) == "plan input y must have a range symmetric about 0 to be mirrored, not [-8, 7]"
    with pytest.raises(ValueError) as e:
        RobotCore(plan, 2, period=500, clock_hz=1e6, channels=mirror_table())
    assert str(e.value) == "channels must be a table of 2 legs, not 3"


def test_trim_or_limit_change_regenerates_the_table_only():
    """A trim and a limit changed in the per-channel calibration: the fit key and the plan are
    untouched, the table and the Verilog change, and the Verilog only in its constants."""
    plan, table = mirror_plan(), mirror_table()
    chans = list(table.channels)
    chans[4] = dataclasses.replace(chans[4], offset=chans[4].offset - 7)     # trim -7 ticks
    chans[0] = dataclasses.replace(chans[0], hi=200)                         # a lower limit
    other = dataclasses.replace(table, channels=tuple(chans))
    text = plan.dumps()
    va = robot_verilog(RobotCore(plan, 3, 500, 1e6, channels=table), "m")
    vb = robot_verilog(RobotCore(plan, 3, 500, 1e6, channels=other), "m")
    assert plan.dumps() == text and va != vb
    literal = re.compile(r"\d+'[sd]?[hdbo][0-9a-fA-F_xz]+|\b\d+\b")
    assert literal.sub("K", va) == literal.sub("K", vb)
    # the description side: a trimmed calibration changes the table, not the robot's fit key
    r = load_preset("phoenix")
    key = r.fit_record()
    cal = list(channel_calibration(r))
    cal[10] = dataclasses.replace(cal[10], trim=-12)
    assert channel_table(r, tuple(cal)).channels[10].offset == channel_table(r).channels[10].offset - 12
    assert r.fit_record() == key


# -- one real plan: the phoenix legs at a loose tolerance --------------------------------------
@pytest.fixture(scope="module")
def phoenix_small(tmp_path_factory):
    r = load_preset("phoenix")
    r = dataclasses.replace(r, name="phoenix-small", fit=dataclasses.replace(r.fit, tolerance_pu=4.0))
    return r, shared_fit(tmp_path_factory, "phoenix-small", r)[0]


def test_phoenix_plan_left_legs_mirror_bit_exactly(phoenix_small):
    """Mount-frame targets (x, y, z) on a left leg and (x, -y, z) on its right twin: the left
    widths are 2 centre (rounded to ticks) - the right ones, in the golden model and in the
    Amaranth simulation of the RobotCore; and within the plan's bound plus the mirror's
    rounding of the reference's mirrored pulses."""
    r, plan = phoenix_small
    table = channel_table(r)
    core = RobotCore(plan, 6, r.hardware.pwm_period_ticks, r.hardware.clock_hz, multipliers=1, dsp=(16, 16),
                     channels=table)
    t = random_targets(plan, 40, 9)
    pairs = np.repeat(np.arange(3), len(t["x"]))
    mount = {k: np.tile(v, 3) for k, v in t.items()}
    twin = {**mount, "y": -mount["y"]}
    legs = np.concatenate([pairs + 3, pairs])                   # LR LM LF, then RR RM RF
    targets = {k: np.concatenate([mount[k], twin[k]]) for k in mount}
    exp = golden.robot_outputs(plan, table, legs, targets)
    res = simulate_robot(core, legs, targets)
    twice = table.channels[9].offset
    n = len(pairs)
    for s in core.servos:
        assert np.array_equal(res.outputs[s], exp[s]), s
        assert np.array_equal(exp[s][:n], twice - exp[s][n:]), s
    # against the reference: the left leg's own channel pulses at its leg-frame target
    tpu = r.ticks_per_pu
    bound = r.fit.tolerance_pu + abs(twice / tpu - 2 * r.calibration.neutral_pulse_pu)
    q = [mount[i.name] * 2.0 ** -i.frac for i in plan.inputs]
    for k in range(3):
        sel = pairs == k
        leg_xyz = mirror(r.body.legs[k + 3], *(v[sel] for v in q))
        ref = channel_pulses_pu(r, k + 3, *leg_xyz)
        for j, s in enumerate(core.servos):
            assert np.max(np.abs(exp[s][:n][sel] / tpu - ref[j])) <= bound


def test_robot_core_channel_table_cocotb(tmp_path_factory):
    """The exported robot top with a channel table on Icarus: the bench's model applies the
    manifest's table (widths per channel, o_leg, latency, the last leg's PWM waveforms, a
    mirrored left leg); told another table (one trim), the same design fails."""
    import json

    from ikseries.sim.runner import run, simulator_available
    ok, why = simulator_available("icarus")
    if not ok:
        pytest.skip(why)
    plan, table = mirror_plan(), mirror_table()
    period = 400
    core = RobotCore(plan, 3, period, 1e6, multipliers=1, channels=table)
    d = tmp_path_factory.mktemp("cocotb_table")
    (d / "plan.json").write_text(plan.dumps())
    res = run(d / "plan.json", period, "icarus", d / "good", core=core, n_random=200)
    assert res.ok and res.legs == 3 and res.latency == core.latency, res.summary()
    man = json.loads(res.manifest.read_text())
    assert ChannelTable.from_record(man["channel_table"]) == table
    chans = list(table.channels)
    chans[7] = dataclasses.replace(chans[7], offset=chans[7].offset + 1)    # leg 2 s2: trim + 1
    man["channel_table"] = dataclasses.replace(table, channels=tuple(chans)).record()
    (d / "wrong.json").write_text(json.dumps(man))
    bad = run(d / "plan.json", period, "icarus", d / "bad", core=core, n_random=200, manifest=d / "wrong.json",
              testcase="test_back_to_back")
    assert not bad.ok, bad.summary()


# -- the command line ---------------------------------------------------------------------------
def _cli(capsys, *argv):
    from ikseries.cli import main
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("argv, message", [
    (["--preset", "hexapod", "--leg", "A", "80", "0", "0"],
     "--leg and --body need a robot with a [body], which hexapod has not"),
    (["--preset", "phoenix", "--body", "80", "0", "0"], "--body needs --leg (one of RR, RM, RF, LR, LM, LF)"),
    (["--preset", "phoenix", "--leg", "XX", "80", "0", "0"], "--leg must be one of RR, RM, RF, LR, LM, LF, not 'XX'"),
    (["--preset", "phoenix", "--leg", "LF", "--body", "0", "0", "0"],
     "x must be within [90, 130] mm in the leg frame of LF, not -92.5141 (from the body-frame target)"),
    (["--preset", "phoenix", "--leg", "RM", "100", "40", "0"], "y must be within [-32, 32] mm in the leg frame of RM, not 40"),
])
def test_eval_leg_messages(capsys, argv, message):
    code, _, err = _cli(capsys, "eval", *argv)
    assert code == 2 and err == f"ikseries: error: {message}\n"


def test_eval_leg_body_frame(capsys, phoenix_small, tmp_path):
    """``eval --leg NAME --body``: mirrored body targets on LF and RF give widths that sum to
    the rounded 2 centre, each within the fit's tolerance (plus the mirror's rounding) of its
    channel's reference."""
    r, plan = phoenix_small
    plan.meta["robot_description"] = robot_record(r)
    pfile, rfile = tmp_path / "plan.json", tmp_path / "phoenix4.toml"
    pfile.write_text(plan.dumps())
    rfile.write_text(preset_text("phoenix").replace("tolerance_pu = 0.5", "tolerance_pu = 4.0"))
    rows = {}
    for leg, y in (("LF", 95.0), ("RF", -95.0)):
        code, out, _ = _cli(capsys, "eval", "--robot", str(rfile), "--plan", str(pfile), "--leg", leg, "--body",
                            "173", str(y), "10")
        assert code == 0 and f"leg {leg} (" in out
        rows[leg] = [line.split() for line in out.splitlines() if re.match(r"\d+ +s\d", line)]
    assert [row[1] for row in rows["LF"]] == ["s1", "s2", "s3"] and [row[0] for row in rows["LF"]] == ["15", "16", "17"]
    twice = channel_table(r).channels[15].offset
    for a, b in zip(rows["LF"], rows["RF"]):
        assert int(a[3]) + int(b[3]) == twice
        assert abs(float(a[5])) <= 4.0 + 0.5 / r.ticks_per_pu and abs(float(b[5])) <= 4.0


def test_legs_override_must_keep_the_body():
    from ikseries.robot import with_hardware
    with pytest.raises(RobotError) as e:
        with_hardware(load_preset("phoenix"), labels={"legs": "--legs"}, legs=4)
    assert str(e.value) == "--legs must be 6 (the number of [[body.legs]]) for phoenix, not 4"


def test_report_lists_every_channel():
    from ikseries.report import _channels_section
    r = load_preset("phoenix")
    recs = channel_records(r, {k: f"pwm_l{k // 3}_s{k % 3 + 1}" for k in range(18)})
    board = {"channels": [{"channel": k, "pin": f"P{k}"} for k in range(18)]}
    lines = _channels_section({"channels": recs, "board": board})
    rows = [line for line in lines if line.startswith("| ") and line[2].isdigit()]
    assert len(rows) == 18
    assert rows[9] == ("| 9 | 3 LR | s1 | left | -82, 43, 0, 150 | +1 | 36004.165 | 0 | 18083 | 42300 | "
                       "yes (0.331 tick) | pwm_l3_s1 | P9 |")


def test_a_mirrored_legs_margin_is_reserved_by_the_fit(phoenix_small):
    """The plan of a robot with left legs is certified to the tolerance less the largest error
    a mirrored channel adds (its 2 centre rounded to ticks): every channel within tolerance."""
    from ikseries.channels import mirror_margin_pu
    r, plan = phoenix_small
    margin = mirror_margin_pu(r)
    assert 0 < margin <= 0.5 / r.ticks_per_pu
    assert r.fitted.fit.tolerance_pu == pytest.approx(r.fit.tolerance_pu - margin)
    assert r.fit_record() != dataclasses.replace(r, body=None).fit_record()    # not one plan-cache entry
    totals = [s["total_pu"] for s in plan.meta["certificate"]["servos"]]
    assert max(totals) + margin <= r.fit.tolerance_pu, (totals, margin)
