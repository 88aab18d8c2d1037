"""Channel tables with gains: a leg whose servos have maps of their own (``[body.legs.servos]``)
scales the plan's pulse in the table after it. The semantics, the hardware (Amaranth and
cocotb, bit-exact against the golden model), the description's fields and messages, and
the tolerance the fit keeps for what a scaled channel adds."""
from __future__ import annotations

import dataclasses
import json
import tomllib

import numpy as np
import pytest

from ikseries.channels import (GAIN_WIDTH, channel_calibration, channel_errors, channel_pulses_pu, channel_table,
                           fit_tolerance_pu, gain_bits)
from ikseries.fit.channels import ChannelTable, TableChannel
from ikseries.hdl.shared import TABLE_LATENCY, RobotCore
from ikseries.robot import RobotError, load_preset, parse_robot, preset_text, robot_from_record, robot_record
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_robot
from test_body import _every_target, mirror_plan

F = 6


def gains_table() -> ChannelTable:
    """Three legs: leg 0 plain, leg 1 mirrored and scaled, leg 2 scaled both ways; offsets
    carry the rounding half; a gain of 1.0 (64) and limits narrower than the sums."""
    T, h = TableChannel, 1 << (F - 1)
    chans = (T(1, h, 10, 230, 64), T(1, 3 * 64 + h, 0, 200, 64), T(1, h, 5, 60, 64),
             T(-1, 250 * 64 + h, 10, 230, 70), T(-1, 240 * 64 + h, 0, 230, 59), T(1, -5 * 64 + h, 5, 60, 66),
             T(1, -10 * 64 + h, 50, 200, 73), T(-1, 235 * 64 + 17, 0, 230, 61), T(-1, 70 * 64 + h, 5, 60, 67))
    return ChannelTable(3, ("s1", "s2", "s3"), "y", (False, True, True), chans, F)


def test_table_with_gains_semantics():
    """``(offset + sign * gain * width) >> gain_bits`` (the floor), saturated to [lo, hi]."""
    plan, table = mirror_plan(), gains_table()
    t = {"a": np.array([3, 3, 15, 0, 9]), "y": np.array([5, 5, -8, -8, 2])}
    legs = np.array([0, 1, 1, 2, 2])
    got = golden.robot_outputs(plan, table, legs, t)
    plain = golden.outputs(plan, {"a": t["a"], "y": np.array([5, -5, 7, 7, -2])})    # mirrored by hand
    for s in table.servos:
        want = [min(max((c.offset + c.sign * c.gain * int(w)) // 2 ** F, c.lo), c.hi)
                for c, w in zip((table.channel(int(k), s) for k in legs), plain[s])]
        assert got[s].tolist() == want, s


def test_table_with_gains_round_trips_and_is_not_the_identity():
    plan, table = mirror_plan(), gains_table()
    rec = table.record()
    assert rec["gain_bits"] == F and rec["channels"][3]["gain"] == 70
    assert ChannelTable.from_record(json.loads(json.dumps(rec))) == table
    ident = ChannelTable(1, ("s1", "s2", "s3"), None, (False,),
                         tuple(TableChannel(1, 1 << (F - 1), 0, 255, 64) for _ in range(3)), F)
    assert not ident.is_identity(plan)         # a table with gains always has its stage
    no_gains = dataclasses.replace(table, gain_bits=0, channels=tuple(
        dataclasses.replace(c, gain=1) for c in table.channels))
    assert "gain_bits" not in no_gains.record() and "gain" not in no_gains.record()["channels"][0]


def test_table_with_gains_messages():
    chans = gains_table().channels
    with pytest.raises(ValueError) as e:
        ChannelTable(3, ("s1", "s2", "s3"), "y", (False, True, True), chans, 0)
    assert str(e.value) == f"channel 0 must have a gain >= 1 (1 with gain_bits 0), not 64"
    with pytest.raises(ValueError) as e:
        ChannelTable(3, ("s1", "s2", "s3"), "y", (False, True, True),
                     (dataclasses.replace(chans[0], gain=0),) + chans[1:], F)
    assert str(e.value) == "channel 0 must have a gain >= 1 (1 with gain_bits 0), not 0"


def test_robot_core_gains_table_is_bit_exact_with_the_golden_model():
    """Every corner target on every leg and seeded random ones, then under back-pressure."""
    plan, table = mirror_plan(), gains_table()
    core = RobotCore(plan, 3, period=500, clock_hz=1e6, multipliers=1, channels=table)
    assert core.latency == core.evaluator.latency + TABLE_LATENCY
    t, legs = _every_target(plan, 3, 150, 11)
    res = simulate_robot(core, legs, t)
    exp = golden.robot_outputs(plan, table, legs, t)
    for s in core.servos:
        assert np.array_equal(res.outputs[s], exp[s]), s
    assert set(res.latencies.tolist()) == {core.latency}
    res = simulate_robot(core, legs[:60], {k: v[:60] for k, v in t.items()}, ready_prob=0.3, seed=4)
    assert all(np.array_equal(res.outputs[s], exp[s][:60]) for s in core.servos)


def test_robot_core_gains_table_cocotb(tmp_path_factory):
    """The exported robot top with a gains table on Icarus, checked by the bench's model from
    the manifest; told another gain, the same design fails."""
    from ikseries.sim.runner import run, simulator_available
    ok, why = simulator_available("icarus")
    if not ok:
        pytest.skip(why)
    plan, table = mirror_plan(), gains_table()
    core = RobotCore(plan, 3, 400, 1e6, multipliers=1, channels=table)
    d = tmp_path_factory.mktemp("cocotb_gains")
    (d / "plan.json").write_text(plan.dumps())
    res = run(d / "plan.json", 400, "icarus", d / "good", core=core, n_random=200)
    assert res.ok and res.legs == 3, res.summary()
    man = json.loads(res.manifest.read_text())
    assert ChannelTable.from_record(man["channel_table"]) == table
    chans = list(table.channels)
    chans[4] = dataclasses.replace(chans[4], gain=chans[4].gain + 1)
    man["channel_table"] = dataclasses.replace(table, channels=tuple(chans)).record()
    (d / "wrong.json").write_text(json.dumps(man))
    bad = run(d / "plan.json", 400, "icarus", d / "bad", core=core, n_random=200, manifest=d / "wrong.json",
              testcase="test_back_to_back")
    assert not bad.ok, bad.summary()


# -- the description -------------------------------------------------------------------------
def phoenix_with(leg: int, servos: dict) -> dict:
    d = tomllib.loads(preset_text("phoenix"))
    d["body"]["legs"][leg]["servos"] = servos
    return d


def test_a_legs_own_servo_map_scales_its_channel():
    """Leg RF (index 2) with s2 at 1.05 times the plan's gain, its own zero pulse and limits: its
    channel is that map of the plan's servo angle; the others keep theirs; the record
    round-trips; the plan's fit tolerance is the tolerance less the table's rounding, over
    1.05."""
    base = load_preset("phoenix")
    m = base.joint_calibration.servos[1]
    u = base.calibration.pulse_unit_us
    own = {"zero_pulse_us": 1480.0, "us_per_degree": 1.05 * m.pu_per_degree * u, "pulse_min_us": 600.0,
           "pulse_max_us": 2500.0}
    r = parse_robot(phoenix_with(2, {"s2": own}))
    assert robot_from_record(json.loads(json.dumps(robot_record(r)))) == r
    cal = channel_calibration(r)
    c = cal[2 * 3 + 1]
    assert c.scale == pytest.approx(1.05) and c.scaled and not cal[0].scaled
    tick_us = r.hardware.clock_hz * 1e-6
    assert (c.min, c.max) == (int(np.ceil(600 * tick_us)), int(np.floor(2500 * tick_us)))
    pts = np.random.default_rng(3).uniform(r.workspace.lows, r.workspace.highs, size=(200, 3)).T
    angles = r.geometry.ik(*pts)
    want = (1480.0 + own["us_per_degree"] * angles[1]) / u
    np.testing.assert_allclose(channel_pulses_pu(r, 2, *pts)[1], want, atol=1e-9)
    np.testing.assert_allclose(channel_pulses_pu(r, 1, *pts)[1], channel_pulses_pu(base, 1, *pts)[1], atol=0)
    table = channel_table(r)
    assert table.gain_bits == gain_bits(cal) and table.channel(2, "s2").gain < 1 << GAIN_WIDTH
    worst = max(e for _, e in channel_errors(r))
    f, (lo, hi), tpu = table.gain_bits, r.pulse_limits_ticks()["s2"], r.ticks_per_pu
    assert 0.5 / tpu < worst <= (0.5 + 2.0 ** -(f + 1) * ((hi - lo) / 2 + 1)) / tpu   # rounding, gain, offset
    assert fit_tolerance_pu(r) == pytest.approx(min((r.fit.tolerance_pu - e) / k for k, e in channel_errors(r)))
    assert fit_tolerance_pu(r) < (r.fit.tolerance_pu - worst) / 1.04
    assert r.fitted.fit.tolerance_pu == fit_tolerance_pu(r)
    assert r.fit_record() != base.fit_record()


def test_limits_alone_change_the_table_not_the_fit():
    base = load_preset("phoenix")
    r = parse_robot(phoenix_with(4, {"s1": {"pulse_min_us": 900.0}}))
    assert channel_table(r).gain_bits == 0
    assert channel_table(r).channel(4, "s1").lo == int(np.ceil(900 * r.hardware.clock_hz * 1e-6))
    assert r.fit_record() == base.fit_record()


@pytest.mark.parametrize("servos, message", [
    ({"s9": {"pulse_min_us": 900.0}},
     "unknown field body.legs[1].servos.s9 (expected one of: s1, s2, s3)"),
    ({"s1": {"us_per_degree": 10.0}},
     "body.legs[1].servos.s1 must give exactly one of zero_pulse_us (the pulse at servo angle 0) or "
     "neutral_pulse_us (the pulse at the neutral pose) or a table, not neither"),
    ({"s1": {"zero_pulse_us": 1500.0}},
     "body.legs[1].servos.s1.us_per_degree must be given with body.legs[1].servos.s1.zero_pulse_us (a leg's "
     "own map is whole: its gain and one reference pulse)"),
    ({"s1": {"table": [[0, 1000], [90, 2000]]}},
     "body.legs[1].servos.s1.table cannot be a leg's own map: a leg's channel is an affine map of the plan's "
     "pulse; give us_per_degree and zero_pulse_us or neutral_pulse_us"),
    ({"s1": {"pulse_min_us": -3.0}}, "body.legs[1].servos.s1.pulse_min_us must be > 0 us, not -3.0"),
])
def test_leg_servo_messages(servos, message):
    with pytest.raises(RobotError) as e:
        parse_robot(phoenix_with(1, servos))
    assert str(e.value) == message


def test_a_legs_map_past_its_limits_is_refused_before_the_fit():
    """A leg's own map that drives its servo past its pulse limits inside the box: one line
    naming the target, the leg, the servo and the field, at parse time."""
    with pytest.raises(RobotError) as e:
        parse_robot(phoenix_with(0, {"s3": {"neutral_pulse_us": 1500.0, "us_per_degree": 40.0,
                                            "pulse_min_us": 1000.0, "pulse_max_us": 2000.0}}))
    msg = str(e.value)
    assert msg.startswith("calibration: target (") and "drives leg RR servo s3 to " in msg, msg
    assert msg.endswith("past its pulse limits [1000, 2000] us (body.legs[0].servos.s3.pulse_min_us)"), msg


def test_spotmicro_table_has_gains_within_a_dsp_operand():
    r = load_preset("spotmicro")
    table = channel_table(r)
    assert 0 < table.gain_bits < GAIN_WIDTH
    assert all(0 < c.gain < 1 << GAIN_WIDTH for c in table.channels)
    assert [c.gain == 1 << table.gain_bits for c in table.channels[:3]] == [True] * 3    # RF: the plan's


def test_report_lists_the_scale_and_error_of_every_channel():
    from ikseries.channels import channel_records
    from ikseries.report import _channels_section
    r = load_preset("spotmicro")
    lines = _channels_section({"channels": channel_records(r)})
    head = next(line for line in lines if line.startswith("| channel"))
    assert "| scale | error ticks |" in head
    rows = [line for line in lines if line.startswith("| ") and line[2].isdigit()]
    assert len(rows) == 12
    rec = channel_records(r)[3]                                      # RB s1: scaled and turned
    assert rec["scale"] == pytest.approx(12.162642045454545 / -11.71875)
    assert f"| {rec['scale']:.6f} | {rec['error_ticks']:.3f} |" in rows[3]


def test_a_channel_of_whole_gain_and_offset_adds_no_rounding():
    """SpotMicro's RF channels are the plan's own (scale 1, shift 0) in a table with gains: gain
    2**F and offset the rounding half alone, so the shift leaves the width as it is (error 0,
    in the golden model too); the scaled channels carry at least the final half tick."""
    from ikseries.channels import channel_error_ticks
    r = load_preset("spotmicro")
    cal, table = channel_calibration(r), channel_table(r)
    limits = r.pulse_limits_ticks()
    errs = [channel_error_ticks(c, t, table.gain_bits, limits[c.servo]) for c, t in zip(cal, table.channels)]
    assert errs[:3] == [0.0, 0.0, 0.0] and min(errs[3:]) >= 0.5
    w = np.arange(limits["s1"][0], limits["s1"][1] + 1, 97)
    out = table.apply(np.zeros(len(w), dtype=np.int64), {"s1": w, "s2": w, "s3": w})
    assert np.array_equal(out["s1"], w)


def test_a_right_legs_narrower_clamp_alone_is_checked_over_the_box():
    """A right leg's channel that passes the plan's pulse but clamps narrower (limits alone) is
    checked too: a clamp inside the box's pulses is refused before the fit, naming the field."""
    with pytest.raises(RobotError) as e:
        parse_robot(phoenix_with(0, {"s1": {"pulse_max_us": 1500.0}}))
    msg = str(e.value)
    assert "drives leg RR servo s1 to " in msg and msg.endswith("(body.legs[0].servos.s1.pulse_max_us)"), msg
