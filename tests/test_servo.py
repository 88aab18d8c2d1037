"""ServoController (hdl/servo.py) against its model (sim/servo_model.py), on the pins."""
from __future__ import annotations

import random

import pytest
from amaranth.back import verilog
from amaranth.lib import data

from ikseries.hdl.servo import ChannelField as F, FailsafeAction as A, ServoController
from ikseries.hdl.servo_microcode import Ins, assemble
from ikseries.sim.servo_model import ServoModel, profile_step
from servo_bench import run

W = 8
FULL = (1 << W) - 1


def period_for(channels, **kw):
    """The shortest period whose pulses show every ``W``-bit width (``max_width >= FULL``)."""
    return ServoController(channels, W, 10 ** 6, time_bits=4, **kw).lead + FULL


def replay(model: ServoModel, schedule, periods, max_width=FULL):
    """What the pins, strobes and status answers must show (same indexing as ``run``): the
    widths of pass k show in period k, after the pass, at most ``max_width``."""
    exp = {"widths": [], "clamped": [], "bad": [], "failsafe": [False], "status": [],
           "fired": []}
    for k in range(periods - 1):
        widths, clamped = model.period()
        exp["fired"].append(model.failsafe)
        bad = 0
        for cmd in schedule[k] if k < len(schedule) else ():
            kind, args = cmd[0], cmd[1:]
            if kind == "write":
                bad += not model.write(*args)
            elif kind == "target":
                model.stage(*args)
            elif kind == "commit":
                model.commit()
            elif kind == "ik":
                bad += not model.ik(*args)
            elif kind == "keepalive":
                model.keepalive()
            else:
                exp["status"].append(model.read(*args))
        exp["widths"].append([min(w, max_width) for w in widths])
        exp["clamped"].append(clamped)
        exp["bad"].append(bad)
        exp["failsafe"].append(model.failsafe)
    return exp


def check(dut, model, schedule, periods):
    got = run(dut, schedule, periods)
    exp = replay(model, schedule, periods, dut.max_width)
    n = len(got["widths"])
    assert n >= periods - 2
    for k in range(n):
        assert got["widths"][k] == exp["widths"][k], f"period {k}"
    assert got["clamped"][:n - 1] == exp["clamped"][:n - 1]
    assert got["bad"][:n - 1] == exp["bad"][:n - 1]
    assert [bool(f) for f in got["failsafe"][:n]] == exp["failsafe"][:n]
    assert got["status"] == exp["status"][:len(got["status"])]
    assert got["busy_max"] <= dut.init_cycles + dut.pass_cycles
    return exp["widths"][:n], exp


def ik_layout(legs, servos):
    # one leg code more than there are legs, so a leg out of range can be sent
    return data.StructLayout({"leg": range(legs + 1),
                              "widths": data.StructLayout({f"s{j}": W for j in range(servos)})})


def random_schedule(rng, periods, channels, legs, servos):
    def command():
        r = rng.random()
        ch = rng.randrange(channels)
        if r < 0.30:
            fld = rng.choice(list(F) + [9, 15])
            value = {F.TRIM: rng.randint(-(1 << W), FULL), F.ENABLE: rng.choice([0, 1, 1, 1, 2]),
                     F.FAILSAFE: rng.randrange(4), F.TIMEOUT: rng.choice([0, 3, 6, 6]),
                     F.SPEED: rng.choice([0, 1, 3, 9, 40]), F.ACCEL: rng.choice([0, 1, 2, 5]),
                     F.MIN: rng.choice([0, 10, 60]), F.MAX: rng.choice([FULL, 200, 90])
                     }.get(fld, rng.randint(-(1 << W), FULL))
            return ("write", ch, fld, value)
        if r < 0.55:
            return ("target", ch, rng.randrange(1 << W), rng.choice([0, 0, 0, 1, 4, 11]))
        if r < 0.65:
            return ("commit",)
        if r < 0.75:
            return ("ik", rng.randrange(legs + 1), [rng.randrange(1 << W) for _ in range(servos)])
        if r < 0.80:
            return ("keepalive",)
        return ("read", ch)
    schedule = [[command() for _ in range(rng.choice([0, 1, 2, 3]))] for _ in range(periods)]
    schedule[0].append(("write", 0, F.TIMEOUT, 5))      # the failsafe armed from the start
    return schedule


@pytest.mark.parametrize("seed,home", [(1, None), (2, [30, 0, 255, 128])])
def test_random_commands_match_model_on_the_pins(seed, home):
    rng = random.Random(seed)
    dut = ServoController(4, W, 288, time_bits=4, home_at_reset=home, ik_layout=ik_layout(2, 2),
                          ik_legs=2)
    model = ServoModel(4, W, 4, home_at_reset=home, ik_servos=2, ik_legs=2)
    schedule = random_schedule(rng, 70, 4, 2, 2)
    widths, exp = check(dut, model, schedule, 70)
    # the sequence exercises what it is meant to: moves, clamps, refusals, failsafe, status
    assert any(0 < w < FULL for ws in widths for w in ws)
    assert sum(exp["clamped"]) and sum(exp["bad"]) and any(exp["fired"]) and exp["status"]


def test_trusted_writes_of_values_in_range_match_model_on_the_pins():
    # trusted_writes leaves the range check out: a sender of values in range sees no difference
    rng = random.Random(3)
    in_range = {F.ENABLE: range(2), F.FAILSAFE: range(max(A) + 1)}

    def ok(cmd):
        if cmd[0] != "write":
            return True
        _, _, fld, v = cmd
        return fld in set(F) and (v in in_range[fld] if fld in in_range else fld == F.TRIM or v >= 0)
    schedule = [[c for c in cmds if ok(c)] for cmds in random_schedule(rng, 70, 4, 2, 2)]
    dut = ServoController(4, W, 288, time_bits=4, ik_layout=ik_layout(2, 2), ik_legs=2, trusted_writes=True)
    model = ServoModel(4, W, 4, ik_servos=2, ik_legs=2)
    widths, exp = check(dut, model, schedule, 70)
    assert any(0 < w < FULL for ws in widths for w in ws) and sum(exp["clamped"])


def _enable_all(channels, **params):
    return [("write", c, F.ENABLE, 1) for c in range(channels)] + \
        [("write", c, f, v) for c in range(channels) for f, v in params.items()]


def test_speed_and_acceleration_limits_hold_on_the_pins():
    dut = ServoController(2, W, period_for(2), time_bits=4, home_at_reset=[10, 240])
    model = ServoModel(2, W, 4, home_at_reset=[10, 240])
    setup = [("write", 0, F.SPEED, 7), ("write", 0, F.ACCEL, 2), ("write", 1, F.ACCEL, 3),
             ("target", 0, 200, 0), ("target", 1, 13, 0), ("commit",)]
    widths, _ = check(dut, model, [setup, [], [], [], [], [], [], [], [], [],
                                [("target", 1, 100, 0), ("commit",)]], 40)
    for c, (speed, accel, end) in enumerate([(7, 2, 200), (FULL, 3, 100)]):
        track = [w[c] for w in widths]
        steps = [b - a for a, b in zip(track, track[1:])]
        assert max(abs(s) for s in steps) <= speed
        assert all(abs(b - a) <= accel for a, b in zip(steps, steps[1:]))
        assert track[-1] == end
    assert max(w[0] for w in widths) == 200          # no overshoot
    assert 7 in [b - a for a, b in zip([w[0] for w in widths], [w[0] for w in widths][1:])]


def test_timed_move_channels_arrive_together_after_exactly_T_periods():
    home = [50, 200, 120]
    dut = ServoController(3, W, period_for(3), time_bits=4, home_at_reset=home)
    model = ServoModel(3, W, 4, home_at_reset=home)
    T = 9
    # channel 2 has a speed limit and an acceleration limit; a timed move overrides both
    sched = [[("write", 2, F.SPEED, 1), ("write", 2, F.ACCEL, 1),
              ("target", 0, 53, T), ("target", 1, 20, T), ("target", 2, 121, T), ("commit",)]]
    widths, _ = check(dut, model, sched, 16)
    first = next(k for k, w in enumerate(widths) if w != home)
    goal = [53, 20, 121]
    for c in range(3):
        track = [w[c] for w in widths]
        arrive = next(k for k in range(len(track)) if track[k:] == [goal[c]] * (len(track) - k))
        assert arrive == 1 + T - 1, (c, track)      # pass 1 makes the first step of T
    assert first <= 1 + T - 1


def test_group_commit_changes_all_channels_in_the_same_period():
    home = [100, 100, 100, 100]
    dut = ServoController(4, W, period_for(4), time_bits=4, home_at_reset=home)
    model = ServoModel(4, W, 4, home_at_reset=home)
    stage = [("target", c, 100 + 10 * (c + 1), 0) for c in range(4)]
    sched = [stage[:2], stage[2:], [], [("commit",)]]
    widths, _ = check(dut, model, sched, 8)
    changed = [next(k for k, w in enumerate(widths) if w[c] != 100) for c in range(4)]
    assert changed == [4, 4, 4, 4]      # committed after pass 3, applied by pass 4


def test_no_pulse_from_reset_until_enabled_then_first_target_at_once():
    dut = ServoController(3, W, period_for(3), time_bits=4)
    model = ServoModel(3, W, 4)
    sched = [[("write", 0, F.SPEED, 1), ("target", 0, 150, 0), ("target", 1, 90, 0), ("commit",)],
             [], [], [("write", 0, F.ENABLE, 1)], [], [("target", 0, 160, 0), ("commit",)]]
    widths, _ = check(dut, model, sched, 10)
    assert widths[:4] == [[0, 0, 0]] * 4
    assert [w[0] for w in widths[4:9]] == [150, 150, 151, 152, 153]   # then speed limited
    assert all(w[1:] == [0, 0] for w in widths)


def test_failsafe_fires_at_its_timeout_and_takes_each_action():
    home = [100, 100, 100]
    dut = ServoController(3, W, period_for(3), time_bits=4, home_at_reset=home)
    model = ServoModel(3, W, 4, home_at_reset=home)
    timeout = 4
    setup = [("write", 0, F.FAILSAFE, A.HOLD), ("write", 1, F.FAILSAFE, A.RELAX),
             ("write", 2, F.FAILSAFE, A.HOME), ("write", 2, F.HOME, 40),
             ("write", 0, F.SPEED, 2), ("target", 0, 200, 0), ("target", 2, 120, 0),
             ("commit",), ("write", 0, F.TIMEOUT, timeout)]
    sched = [setup, [("keepalive",)], [("keepalive",)]]     # last keepalive after pass 2
    got = run(dut, sched, 14)
    exp = replay(model, sched, 14)
    n = len(got["widths"])
    assert got["widths"] == exp["widths"][:n]
    assert [bool(f) for f in got["failsafe"][:n]] == exp["failsafe"][:n]
    fired = got["failsafe"].index(1) - 1        # the flag is seen at the next period start
    assert abs(fired - (2 + timeout)) <= 1      # the pass that fired: timeout passes later
    at = got["widths"][fired]
    assert at[1] == 0 and got["widths"][fired - 1][1] == 100           # relaxed
    assert all(w[0] == at[0] for w in got["widths"][fired:])           # held
    assert got["widths"][-1][2] == 40                                  # went home


def test_corners_trim_and_limits_at_full_scale_and_zero():
    dut = ServoController(3, W, 256, time_bits=4, home_at_reset=[FULL, 1, 128])
    model = ServoModel(3, W, 4, home_at_reset=[FULL, 1, 128])
    sched = [
        [("write", 0, F.TRIM, FULL), ("target", 0, FULL, 0),               # max trim, max width
         ("write", 1, F.TRIM, -(1 << W)), ("target", 1, 0, 0),             # most negative
         ("write", 2, F.SPEED, FULL), ("write", 2, F.ACCEL, FULL),         # limits above distance
         ("target", 2, 129, 0), ("commit",)],
        [("write", 2, F.MIN, FULL), ("target", 2, 0, 0), ("commit",)],     # min = max = full
        [("write", 2, F.MIN, 0), ("write", 2, F.MAX, 0), ("target", 2, FULL, 0), ("commit",)],
        [("write", 2, F.MAX, FULL), ("write", 2, F.TRIM, 5), ("target", 2, 10, 3), ("commit",)],
        [("write", 0, F.MIN, 9), ("write", 0, F.MAX, 3), ("target", 0, 5, 0), ("commit",)],
        [("write", 0, F.SPEED, -1), ("write", 0, F.ENABLE, 2), ("write", 0, 12, 0)],
    ]
    got = run(dut, sched, 12)
    exp = replay(model, sched, 12, dut.max_width)
    n = len(got["widths"])
    assert got["widths"] == exp["widths"][:n]
    assert got["clamped"][:n - 1] == exp["clamped"][:n - 1]
    assert got["bad"][:n - 1] == exp["bad"][:n - 1]
    assert exp["clamped"][1:6] == [2, 1, 1, 0, 1] and exp["bad"][5] == 3
    # trims clamped to full scale (shown as the widest pulse a period holds) and to 0
    assert dut.max_width < FULL and got["widths"][1][:2] == [dut.max_width, 0]


def test_profile_arrives_exactly_within_limits_without_overshoot():
    """Every move from rest at small sizes: exact arrival, |step| <= speed, |Δstep| <= accel."""
    for accel in range(1, 7):
        for speed in range(0, 12):
            first = accel if speed == 0 else (speed - 1) % accel + 1
            for dist in range(0, 60):
                rem, step, stop, prev = dist, 0, 0, 0
                for _ in range(dist + 2):
                    step, stop = profile_step(rem, step, stop, accel, speed, first)
                    assert abs(step - prev) <= accel and (speed == 0 or step <= speed)
                    rem, prev = rem - step, step
                    assert rem >= 0, (dist, accel, speed)
                    if rem == 0 and step == 0:
                        break
                else:
                    raise AssertionError(f"no arrival for {(dist, accel, speed)}")


def test_profile_reaches_the_speed_limit_on_a_long_move():
    rem, step, stop, steps = 500, 0, 0, []
    while rem or step:
        step, stop = profile_step(rem, step, stop, 3, 10, (10 - 1) % 3 + 1)
        rem -= step
        steps.append(step)
    assert max(steps) == 10 and steps[:4] == [1, 4, 7, 10]


def test_timed_schedule_arrives_after_exactly_T_periods():
    for dist in range(-20, 40):
        for T in range(1, 15):
            m = ServoModel(1, W, 4, home_at_reset=[100])
            m.write(0, F.SPEED, 1)          # a timed move is not speed limited
            m.stage(0, 100 + dist, T)
            m.commit()
            track = [100] + [m.period()[0][0] for _ in range(T + 2)]
            assert track[T:] == [100 + dist] * 3, (dist, T)
            assert dist == 0 or track[T - 1] != 100 + dist
            steps = {abs(b - a) for a, b in zip(track[:T], track[1:T + 1])}
            assert steps <= {abs(dist) // T, -(-abs(dist) // T)}


def test_write_refusals_and_field_ranges():
    m = ServoModel(2, W)
    assert m.write(0, F.TRIM, -(1 << W)) and m.write(0, F.TRIM, FULL)
    assert not m.write(0, F.SPEED, -1) and not m.write(0, F.ENABLE, 2)
    assert not m.write(0, F.FAILSAFE, 3) and not m.write(0, 9, 0)
    with pytest.raises(ValueError, match="value must fit signed"):
        m.write(0, F.TRIM, 1 << W)


@pytest.mark.parametrize("args,kw,msg", [
    ((0, 8, 1000), {}, "channels must be an integer >= 1, not 0"),
    ((2, 1, 1000), {}, "width_bits must be an integer >= 2, not 1"),
    ((2, 8, True), {}, "period must be an integer >= 2, not True"),
    ((2, 8, 1000), {"time_bits": 0}, "time_bits must be an integer >= 1, not 0"),
    ((2, 8, 1000), {"home_at_reset": [1]}, r"home_at_reset must be 2 integers in \[0, 255\], not \[1\]"),
    ((2, 8, 1000), {"home_at_reset": [1, 256]}, r"home_at_reset must be 2 integers in \[0, 255\]"),
    ((2, 8, 1000), {"ik_legs": 2}, "ik_legs needs an ik_layout, not ik_legs=2 alone"),
    ((2, 8, 1000), {"ik_layout": data.StructLayout({"leg": 1})}, "ik_layout must be a StructLayout of 'leg' and 'widths'"),
    ((2, 8, 1000), {"ik_layout": data.StructLayout({"leg": 1, "widths": data.StructLayout({"a": 9})})},
     r"ik_layout widths.a must fit width_bits=8, not unsigned\(9\)"),
    ((3, 8, 1000), {"ik_layout": ik_layout(2, 2), "ik_legs": 2}, r"ik_legs \* servos must be <= channels=3, not 2 \* 2"),
])
def test_parameter_errors(args, kw, msg):
    with pytest.raises(ValueError, match=msg):
        ServoController(*args, **kw)


def test_period_must_hold_the_initialisation_and_a_pass():
    probe = ServoController(2, 8, 10 ** 6)
    least = probe.init_cycles + probe.pass_cycles + 2
    ServoController(2, 8, least)
    with pytest.raises(ValueError, match=f"period must be >= {least} cycles for 2 channels of 8 bits, "
                                         f"not {least - 1}"):
        ServoController(2, 8, least - 1)


def test_verilog_is_deterministic():
    def make():
        return verilog.convert(ServoController(3, W, 400, home_at_reset=[1, 2, 3], ik_layout=ik_layout(1, 3),
                                               ik_legs=1), name="servo", emit_src=False)
    assert make() == make()


def test_microprogram_assembler_refuses_a_read_of_the_word_just_written():
    word, back = (0, 3), Ins(cond="always", to="L")
    assemble([Ins("LD", (0, 1), st=word, label="L"), Ins("ADD", (0, 2)), back])   # another word: fine
    with pytest.raises(ValueError, match=r"instruction 1 reads \(0, 3\) that 0 writes in the same cycle"):
        assemble([Ins("LD", (0, 1), st=word, label="L"), Ins("ADD", word), back])
    with pytest.raises(ValueError, match="uses D but names no word"):
        assemble([Ins("ADD", label="L"), back])
    with pytest.raises(ValueError, match="must jump, not fall off the program"):
        assemble([Ins("LD", (0, 1))])


def test_a_hexapod_pass_takes_well_under_a_millisecond_at_12_mhz():
    ik = data.StructLayout({"leg": range(6), "widths": data.StructLayout({f"s{j}": 16 for j in range(3)})})
    ctl = ServoController(18, 16, 240000, ik_layout=ik)
    assert ctl.init_cycles == 16 * 18 + 1
    assert ctl.pass_cycles < 12000 // 4
