"""cocotb tests of the exported robot controller at its pins (``rx``, ``tx``, ``pwm``).

Every test resets the design, finds the PWM phase (enable, one set_pulse), sends its requests
a fixed part of the period after a period start and ends with :func:`~.scene.final_checks`:
every period's widths equal the model's (:class:`~.model.ControllerModel`), one answer per
request, pulses on the period grid. On top of that each test checks its own property.
"""
from __future__ import annotations

import json
import os
import random
from pathlib import Path

import cocotb

from ikseries.hdl import protocol as P
from ikseries.host.protocol import encode

from ..cocotb_leg.config import ENV_CONFIG
from .checker import first_period_with
from .host import Host, parse_requests
from .scene import ROOM, Scene, final_checks
from .stream import fuzz_traffic


async def _ready(dut, test: str, trims: bool | None = True):
    """Reset, PWM phase found, the scene's trims set (``trims`` None: only where the box's
    golden widths do not fit the period untrimmed; a long period saves the requests)."""
    host = Host(dut, test)
    await host.start()
    await host.find_phase(0, host.period // 4)
    scene = Scene(host.plan, host.config.legs, host.period - host.config.lead)
    if trims or (trims is None and not scene.fits_untrimmed):
        await scene.set_trims(host)
    return host, scene


def _leg(host, leg: int) -> list[int]:
    n = len(host.plan.outputs)
    return list(range(leg * n, (leg + 1) * n))


@cocotb.test()
async def test_identity_and_status(dut):
    host, _ = await _ready(dut, "test_identity_and_status", trims=False)
    cfg = host.config
    ident = await host.request("identity")
    assert ident.fields == {"version": P.PROTOCOL_VERSION, "clock_hz": cfg.clock_hz, "pwm_period": cfg.period,
                            "legs": cfg.legs, "coords": host.shape.coords, "channels": host.shape.channels,
                            "manifest": cfg.manifest_bytes, "name": cfg.name}, ident
    first = await host.request("status")
    await host.periods(5)
    second = await host.request("status")
    a1, a2 = (host.pwm.index(c) for c, _ in host.acked[-2:])
    since_reset = a1 - host.pwm.index(host.reset_at)
    assert second.fields["uptime"] - first.fields["uptime"] == a2 - a1, (first, second, a1, a2)
    assert abs(first.fields["uptime"] - since_reset) <= 1, (first.fields["uptime"], since_reset)
    for st in (first, second):
        assert all(st.fields[n] == 0 for n, _ in P.ERROR_COUNTERS), st
        assert st.fields["enabled"] == (1 << host.shape.channels) - 1 and st.fields["moving"] == 0, st
    final_checks(host)


async def _move_and_check(host, scene, command: str, moved: list[int], **fields):
    """Send a move, wait, and check its channels change together exactly in the period after
    its answer began (its pass, at that period's start) and stay."""
    await host.request(command, **fields)
    ack = host.acked[-1][0]
    await host.periods(4)
    measured = final_checks(host)
    targets = [fields["target"]] if "target" in fields else fields["targets"]
    chans = [c for leg in moved for c in _leg(host, leg)]
    want = [w for leg, t in zip(moved, targets) for w in scene.pins(leg, t)]
    k = host.pwm.index(ack) + 1
    assert first_period_with(measured, chans, want, host.pwm.index(ack) - 1) == k, (k, measured)
    assert all([measured[j][c] for c in chans] == want for j in measured if j >= k), measured
    return measured, k


@cocotb.test()
async def test_move_leg(dut):
    host, scene = await _ready(dut, "test_move_leg")
    measured, k = await _move_and_check(host, scene, "move_leg", [0], leg=0, target=scene.corner(0))
    assert all(measured[j][c] == 0 for j in measured for c in _leg(host, 1)), "leg 1 moved"


@cocotb.test()
async def test_move_legs(dut):
    host, scene = await _ready(dut, "test_move_legs")
    await host.request("move_leg", leg=0, target=scene.corner(1))
    await host.periods(3)
    a, b = scene.corner(6), scene.corner(3)
    assert all(x != y for x, y in zip(scene.pins(0, a) + scene.pins(1, b), scene.pins(0, scene.corner(1)) + [0] * 3))
    measured, k = await _move_and_check(host, scene, "move_legs", [0, 1], legs=0b11, targets=[a, b])
    assert [measured[k - 1][c] for c in _leg(host, 0)] == scene.pins(0, scene.corner(1)), "leg 0 changed early"


async def _long_move(host, scene, setting: str, **fields):
    """From one corner of the box to the opposite one on leg 0 after ``setting``; returns the
    measured widths, the period the move's first step shows in, start and end pins."""
    a, b = scene.corner(0), scene.corner(7)
    await host.request("move_leg", leg=0, target=a)
    await host.periods(3)
    for c in _leg(host, 0) if "channel" in fields else [None]:
        await host.request(setting, **({**fields, "channel": c} if c is not None else fields))
    await host.request("move_leg", leg=0, target=b)
    return scene.pins(0, a), scene.pins(0, b), host.pwm.index(host.acked[-1][0]) + 1


@cocotb.test()
async def test_speed_limit(dut):
    host, scene = await _ready(dut, "test_speed_limit")
    a, b = scene.pins(0, scene.corner(0)), scene.pins(0, scene.corner(7))
    speed = max(abs(x - y) for x, y in zip(a, b)) // 12     # a move of at least 12 periods
    assert speed >= 1
    start, end, k = await _long_move(host, scene, "set_speed", channel=0, speed=speed)
    await host.periods(16)
    measured = final_checks(host)
    chans = _leg(host, 0)
    for c, x, y in zip(chans, start, end):
        seq = [measured[j][c] for j in range(k - 1, max(measured) + 1)]
        steps = [q - p for p, q in zip(seq, seq[1:])]
        assert seq[0] == x and seq[-1] == y, (c, seq)
        assert all(abs(s) <= speed for s in steps), (c, speed, seq)
        if abs(y - x) > speed:
            assert sum(1 for s in steps if s) >= abs(y - x) // speed, (c, seq)


@cocotb.test()
async def test_timed_move(dut):
    host, scene = await _ready(dut, "test_timed_move")
    periods = 9
    start, end, k = await _long_move(host, scene, "set_move_time", periods=periods)
    await host.periods(periods + 4)
    measured = final_checks(host)
    chans = _leg(host, 0)
    arrive = first_period_with(measured, chans, end, k)
    assert arrive == k + periods - 1, (k, arrive, periods)
    assert all([measured[j][c] for c in chans] != end for j in range(k - 1, arrive)), "arrived early"


@cocotb.test()
async def test_failsafe(dut):
    host, scene = await _ready(dut, "test_failsafe")
    timeout = 5
    t = scene.corner(2)
    await host.request("move_legs", legs=0b11, targets=[t, t])
    home = [w + ROOM // 2 for w in scene.pins(1, t)]      # in the room below the widest pulse
    for c, h in zip(_leg(host, 1), home):
        await host.request("set_home", channel=c, pulse=h)
        await host.request("set_failsafe_action", channel=c, action="home")
    for c in _leg(host, 0):
        await host.request("set_failsafe_action", channel=c, action="relax")
    await host.request("set_failsafe", periods=timeout)
    last = host.pwm.index(host.acked[-1][0])
    await host.periods(timeout + 5)
    measured = final_checks(host)
    fired = first_period_with(measured, _leg(host, 0) + _leg(host, 1), [0] * 3 + home, last)
    assert fired is not None and abs(fired - (last + timeout)) <= 1, (last, timeout, fired)
    assert all([measured[j][c] for c in _leg(host, 0)] == scene.pins(0, t) for j in range(last + 2, fired))


@cocotb.test()
async def test_fuzz(dut):
    host, scene = await _ready(dut, "test_fuzz")
    cfg = host.config
    traffic = fuzz_traffic(random.Random(cfg.seed), host.shape, cfg.fuzz_bytes, scene.box, scene.pulses)
    assert traffic.resyncs and all(traffic.counters.values()), traffic.counters
    before = len(host.acked)
    for seg in traffic.segments:
        await host.send(seg)
    await host.periods(3)
    measured = final_checks(host)
    whole = parse_requests(host.shape, b"".join(traffic.segments))
    assert [m for _, m in host.acked[before:]] == whole, "segments framed differently from the whole stream"
    assert whole[-1].command == "status"
    got = host.rx.answers[-1].message.fields
    assert {k: got[k] for k in traffic.counters} == traffic.counters, (got, traffic.counters)
    assert all(got[k] == 0 for k in ("framing", "overrun", "dropped", "clamped")), got
    summary = {"bytes": traffic.nbytes, "good_frames": len(host.acked) - before, "after_bad": traffic.resyncs,
               "counters": traffic.counters, "cycles": host.cycle(), "periods_checked": len(measured)}
    dut._log.info(f"fuzz: {summary}")
    # the bench script's figures, next to the run configuration
    Path(os.environ[ENV_CONFIG]).with_name("fuzz.json").write_text(json.dumps(summary) + "\n")


#: full move_legs requests the link-rate test sends, streamed and then one answer at a time
RATE_FRAMES = 8


def _full_moves(host, scene, n: int) -> list[bytes]:
    legs = host.shape.legs
    return [encode("move_legs", host.shape, legs=(1 << legs) - 1,
                   targets=[scene.corner((k + leg) % 8) for leg in range(legs)]) for k in range(n)]


@cocotb.test()
async def test_link_rate(dut):
    """Full move_legs requests (every leg) back to back at the line rate, then one at a time
    waiting for each answer: every one answered, none dropped, the last one's widths on the pins;
    cycles per update measured both ways (``link_rate.json`` beside the run configuration)."""
    host, scene = await _ready(dut, "test_link_rate", trims=None)
    frames = _full_moves(host, scene, 2 * RATE_FRAMES)
    streamed = await host.send(b"".join(frames[:RATE_FRAMES]), aligned=False)
    t0 = host.cycle()
    lockstep = [(await host.send(f, aligned=False))[0] for f in frames[RATE_FRAMES:]]
    lock_cycles = (lockstep[-1].end - t0) / len(lockstep)
    stream_cycles = (streamed[-1].end - streamed[0].end) / (len(streamed) - 1)
    assert all(not a.message.nack for a in streamed + lockstep), [a.message for a in streamed + lockstep]
    status = await host.request("status")
    assert all(status.fields[n] == 0 for n, _ in P.ERROR_COUNTERS), status
    await host.periods(3)
    final_checks(host, unaligned=len(host.acked) - 1)      # the pins after the last move and the status
    line = host.tx.byte_cycles(len(frames[0]))
    assert stream_cycles < 1.05 * line, f"streamed updates every {stream_cycles} cycles, the line takes {line}"
    summary = {"frame_bytes": len(frames[0]), "line_cycles": line, "streamed_cycles": stream_cycles,
               "lockstep_cycles": lock_cycles, "updates": 2 * RATE_FRAMES, "channels": host.shape.channels,
               "divisor": host.config.divisor, "clock_hz": host.config.clock_hz}
    dut._log.info(f"link rate: {summary}")
    Path(os.environ[ENV_CONFIG]).with_name("link_rate.json").write_text(json.dumps(summary) + "\n")
