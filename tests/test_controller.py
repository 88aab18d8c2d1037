"""The robot controller on its pins: host frames bit-timed into rx, answers decoded off tx,
servo pulses measured on pwm and compared with the golden model."""
import pytest

from controller_bench import golden_widths, run
from ikseries.hdl import protocol as P
from ikseries.hdl.controller import RobotController
from ikseries.host.protocol import encode, frame

CLOCK = 48_000_000
BAUD = 12e6          # divisor 4: the smallest the UART takes, for a short simulation
PERIOD = 820         # the pass before the pulses (354 cycles, two legs of three servos) and the pulses
MANIFEST = bytes(range(0xA0, 0xA8))
REF = (240, 100, 160)        # a target inside the workspace; the others are near it
T1, T2, T3 = REF, (242, 96, 161), (238, 104, 159)
MARGIN = 30          # shortest pulse after the trims


@pytest.fixture(scope="module")
def two_legs(small_plan):
    return RobotController(small_plan, 2, PERIOD, CLOCK, BAUD, name="two-leg test", manifest=MANIFEST)


def _trims(plan, legs, targets, max_width):
    """Per-channel trims that bring the golden pulses of ``targets`` below ``max_width``."""
    g = [golden_widths(plan, t) for t in targets]
    low = [min(w[j] for w in g) for j in range(len(plan.outputs))]
    high = [max(w[j] for w in g) for j in range(len(plan.outputs))]
    assert max(h - lo for h, lo in zip(high, low)) + MARGIN < max_width - 20, "targets too far apart for the period"
    return [MARGIN - lo for lo in low] * legs


def test_identity_moves_pulses_trims_and_limits_reach_the_pins(two_legs, small_plan):
    dut, plan, shape = two_legs, small_plan, two_legs.shape
    k = len(plan.outputs)
    trims = _trims(plan, 2, [T1, T2, T3], dut.servo.max_width)
    g1, g2, g3 = (golden_widths(plan, t) for t in (T1, T2, T3))
    assert all(a != b for a, b in zip(g1, g2)), "T1 and T2 must differ on every servo"
    seen = {}

    async def script(ctx, host):
        ident, _ = await host.request(ctx, encode("identity", shape))
        seen["identity"] = ident
        for msg in [(await host.request(ctx, encode("enable", shape, channels=(1 << shape.channels) - 1)))[0]] + [
                (await host.request(ctx, encode("set_trim", shape, channel=c, trim=t)))[0] for c, t in enumerate(trims)]:
            assert not msg.nack and msg.fields == {}, msg
        msg, seen["t1"] = await host.request(ctx, encode("move_leg", shape, leg=0, target=T1))
        assert msg.command == "move_leg" and not msg.nack
        await host.periods(ctx, 3)
        msg, seen["t23"] = await host.request(ctx, encode("move_legs", shape, legs=0b11, targets=(T2, T3)))
        assert msg.command == "move_legs" and not msg.nack
        await host.periods(ctx, 3)
        seen["pulse_w"] = 200
        msg, seen["pulse"] = await host.request(ctx, encode("set_pulse", shape, channel=4, pulse=200 - trims[4]))
        await host.periods(ctx, 3)
        seen["max"] = g2[0] + trims[0] - 17
        msg, _ = await host.request(ctx, encode("set_limits", shape, channel=0, min=0, max=seen["max"]))
        assert not msg.nack
        msg, seen["limited"] = await host.request(ctx, encode("move_leg", shape, leg=0, target=T2))
        await host.periods(ctx, 3)
        msg, _ = await host.request(ctx, encode("set_limits", shape, channel=0, min=10, max=9))
        seen["bad_limits"] = msg

    commits = []

    async def commit_probe(ctx):
        cycle = 0
        while True:
            if ctx.get(dut.dispatcher.commit):
                commits.append(cycle)
            cycle += 1
            await ctx.tick()

    host = run(dut, script, probes=[commit_probe])

    def shown_by(sent, legs):
        """The rise of the pulses of the period after the request's commit (when its widths are
        on the pins at the latest), the commit within the dispatcher's bound of the frame's end."""
        commit = next(c for c in commits if c >= sent)
        assert commit - sent <= dut.link.latency + dut.dispatcher.move_cycles(legs), (sent, commit)
        return [p for p in host.period_starts if p > commit][0] + dut.servo.lead

    ident = seen["identity"]
    assert ident.command == "identity" and ident.fields == {
        "version": P.PROTOCOL_VERSION, "clock_hz": CLOCK, "pwm_period": PERIOD, "legs": 2,
        "coords": len(plan.inputs), "channels": 2 * k, "manifest": MANIFEST, "name": "two-leg test"}
    want1 = [w + t for w, t in zip(g1, trims)]
    # move_leg: leg 0 shows T1's golden pulses by the second period start after its commit,
    # the commit within the dispatcher's bound of the request; leg 1 nothing
    firsts = [host.first_pulse(c, seen["t1"], want1[c]) for c in range(k)]
    shown = shown_by(seen["t1"], 1)
    assert all(f is not None and f <= shown for f in firsts), (firsts, shown, host.pulses[:k])
    assert len(set(firsts)) == 1
    # move_legs: both legs change at the same period start
    want23 = [w + t for w, t in zip(g2 + g3, trims)]
    firsts = [host.first_pulse(c, seen["t23"], want23[c]) for c in range(2 * k)]
    shown = shown_by(seen["t23"], 2)
    assert all(f is not None and f <= shown for f in firsts), (firsts, shown)
    assert len(set(firsts)) == 1, firsts
    before = [w for t, w in host.pulses[0] if seen["t23"] <= t < firsts[0]]
    assert before and set(before) == {want1[0]}
    # set_pulse acts on its channel alone (trim added); set_limits clamps the next move
    assert host.widths_after(4, shown_by(seen["pulse"], 0))[:2] == [seen["pulse_w"]] * 2
    assert host.widths_after(3, seen["pulse"])[:3] == [want23[3]] * 3
    shown = shown_by(seen["limited"], 1)
    assert host.widths_after(0, shown)[:2] == [seen["max"]] * 2
    assert host.widths_after(1, shown)[:2] == [want23[1]] * 2
    assert seen["bad_limits"].nack and seen["bad_limits"].fields == {"reason": "bad_value"}
    assert seen["bad_limits"].command == "set_limits"


def test_bad_frames_nacks_status_and_clamped_targets(two_legs, small_plan):
    dut, plan, shape = two_legs, small_plan, two_legs.shape
    k = len(plan.outputs)
    outside = (plan.inputs[0].hi + 100, 0, plan.inputs[2].lo)
    inside = (plan.inputs[0].hi, 0, plan.inputs[2].lo)
    seen = {}

    async def script(ctx, host):
        await host.request(ctx, encode("enable", shape, channels=0b111))
        good = bytearray(encode("move_leg", shape, leg=0, target=T1))
        good[4] ^= 0x10                 # a payload byte: the CRC no longer matches
        seen["bad_at"] = host.cycle
        await host.send(ctx, bytes(good))
        await host.periods(ctx, 4)
        seen["bad_end"] = host.cycle
        seen["nack_channel"], _ = await host.request(ctx, frame(P.command("channel_status").code, bytes([40])))
        seen["nack_pulse"], _ = await host.request(ctx, frame(P.command("set_pulse").code, bytes([2 * k, 1, 0, 0])))
        seen["nack_leg"], _ = await host.request(ctx, frame(P.command("move_leg").code, bytes([2] + [0] * 2 * len(plan.inputs))))
        seen["nack_mask"], _ = await host.request(ctx, frame(P.command("move_legs").code, bytes([0b100] + [0] * 2 * len(plan.inputs))))
        await host.request(ctx, encode("move_leg", shape, leg=0, target=outside))
        await host.request(ctx, encode("move_legs", shape, legs=0b11, targets=(outside, T2)))
        await host.periods(ctx, 3)
        seen["ch0"], _ = await host.request(ctx, encode("channel_status", shape, channel=0))
        seen["ch4"], _ = await host.request(ctx, encode("channel_status", shape, channel=4))
        starts = len(host.period_starts)
        seen["status"], _ = await host.request(ctx, encode("status", shape))
        seen["uptime"] = (starts, len(host.period_starts))

    host = run(dut, script)
    # the corrupted frame: no answer, no pulse on any pin, counted as a CRC error
    assert all(not host.pulses[c] or host.pulses[c][0][0] > seen["bad_end"] for c in range(2 * k))
    for name in ("nack_channel", "nack_pulse", "nack_leg", "nack_mask"):
        assert seen[name].nack and seen[name].fields == {"reason": "bad_value"}, (name, seen[name])
    assert [seen[n].command for n in ("nack_channel", "nack_pulse", "nack_leg", "nack_mask")] == [
        "channel_status", "set_pulse", "move_leg", "move_legs"]
    g_in, g2 = golden_widths(plan, inside), golden_widths(plan, T2)
    assert seen["ch0"].fields == {"channel": 0, "commanded": g_in[0], "current": g_in[0], "moving": 0, "enabled": 1}
    # a relaxed channel takes its target but does not move (no pulse places the servo)
    assert seen["ch4"].fields == {"channel": 4, "commanded": g2[1], "current": 0, "moving": 1, "enabled": 0}
    st = seen["status"].fields
    assert seen["uptime"][0] <= st["uptime"] <= seen["uptime"][1]
    assert st["crc"] == 1 and st["clamped"] == 2
    assert all(st[n] == 0 for n in ("framing", "overrun", "bad_length", "unknown_command", "dropped"))
    assert st["enabled"] == 0b111 and st["moving"] == 0b111000
    assert len(host.answers) == host.requests       # every good request answered once, the bad frame not


def test_hexapod_move_legs_is_executed_faster_than_it_arrives_at_1_mbaud(small_plan):
    """The dispatcher's time for a full 6-leg move_legs (request offered to its answer), measured,
    against that frame's time on the wire at 1 Mbaud with the robot's clock."""
    clock, legs = 48_000_000, 6
    dut = RobotController(small_plan, legs, 2000, clock, BAUD)     # a short period: frequent passes to wait for
    shape = dut.shape
    targets = [T1, T2, T3, T1, T2, T3]
    frames = [encode("move_legs", shape, legs=(1 << legs) - 1, targets=targets[n:] + targets[:n]) for n in range(3)]
    service, seen = [], {}

    async def probe(ctx):
        start = None
        while True:
            if start is None and ctx.get(dut.link.request.valid):
                start = 0
            if start is not None:
                if ctx.get(dut.link.answer.valid) and ctx.get(dut.link.answer.ready):
                    service.append(start)
                    start = None
                else:
                    start += 1
            await ctx.tick()

    async def script(ctx, host):
        for data in frames:
            msg, _ = await host.request(ctx, data)
            assert msg.command == "move_legs" and not msg.nack
        seen["status"], _ = await host.request(ctx, encode("status", shape))

    run(dut, script, probes=[probe])
    line_cycles = len(frames[0]) * 10 * clock / 1e6
    # the measured times include some wait for the engine's pass; add a whole pass to be sure
    worst = max(service[:3]) + dut.servo.pass_cycles
    rate = clock / max(worst, line_cycles)
    assert len(service) == 4 and seen["status"].fields["dropped"] == 0
    assert worst < line_cycles, (service, line_cycles)
    assert rate >= 1000, rate
    print(f"hexapod move_legs: {service[:3]} cycles in the dispatcher (at most {worst}), {line_cycles:.0f} on the wire at "
          f"1 Mbaud: {rate:.0f} full updates a second at {clock / 1e6:g} MHz")


def test_host_controller_drives_the_simulated_controller(two_legs, small_plan):
    from controller_bench import SimulatedPort
    from ikseries.host.controller import AnswerTimeout, Controller, NackError
    plan = small_plan
    host = Controller(SimulatedPort(two_legs), timeout=60)
    assert (host.shape, host.clock_hz, host.period, host.name, host.manifest) == (
        two_legs.shape, CLOCK, PERIOD, "two-leg test", MANIFEST)
    host.enable(range(6))
    host.trim(1, -10.0)                                  # µs -> ticks with the controller's clock
    host.move(0, T1)
    assert host.channel_status(1)["commanded"] == golden_widths(plan, T1)[1] - round(10.0 * CLOCK / 1e6)
    host.move_legs({1: T2})
    assert host.channel_status(5)["commanded"] == golden_widths(plan, T2)[2]
    host.set_pulse(3, 1500.0)
    assert host.channel_status(3)["commanded_us"] == 1500.0
    assert host.status()["enabled"] == 0b111111
    from ikseries.hostcmd import status_lines
    lines = status_lines(host, None)
    assert lines[0].startswith(f"two-leg test: 2 legs, 6 channels, clock {CLOCK / 1e6:g} MHz")
    assert lines[1] == "errors: crc 0, framing 0, overrun 0, bad_length 0, unknown_command 0, dropped 0, clamped 0"
    assert lines[2 + 3] == "channel 3: on, commanded 1500.00 µs, current " + lines[5].split("current ")[1]
    assert len(lines) == 2 + 6
    with pytest.raises(NackError, match=r"^the controller refused set_limits: bad_value \("):
        host.limits(0, 2000.0, 1000.0)
    with pytest.raises(ValueError, match=r"^channel must be in \[0, 5\], not 40$"):
        host.set_pulse(40, 1500.0)
    with pytest.raises(ValueError, match=r"^pulse must be a number of µs, not 'x'$"):
        host.set_pulse(0, "x")

    class DeadLine:
        def write(self, data):
            return len(data)

        def read(self, n):
            return b""
    with pytest.raises(AnswerTimeout, match=r"^no answer to identity within 0.05 s$"):
        Controller(DeadLine(), timeout=0.05)


def test_controller_with_a_channel_table_commands_the_table_widths(small_plan):
    """With a channel table the core's table stage is the output register that rotates for the
    dispatcher (RobotCore rotate_outputs): every channel's commanded pulse is its table width."""
    import numpy as np

    from controller_bench import SimulatedPort
    from ikseries.fit.channels import ChannelTable, TableChannel
    from ikseries.host.controller import Controller
    from ikseries.sim.golden import robot_outputs
    plan = small_plan
    names = tuple(o.name for o in plan.outputs)
    nodes = [plan.nodes[o.node] for o in plan.outputs]
    mirror = next((i.name for i in plan.inputs if i.lo == -i.hi), None)
    # leg 0 shifted (a different offset per servo), leg 1 reflected within its servos' ranges
    chans = [TableChannel(1, 7 + 5 * j, n.lo, n.hi) for j, n in enumerate(nodes)]
    chans += [TableChannel(-1, n.lo + n.hi, n.lo, n.hi) for n in nodes]
    table = ChannelTable(2, names, mirror, (False, mirror is not None), tuple(chans))
    dut = RobotController(plan, 2, PERIOD, CLOCK, BAUD, channels=table)
    assert dut.core.channels is table
    host = Controller(SimulatedPort(dut), timeout=60)
    host.move(0, T1)
    host.move_legs({1: T2})
    for leg, target in ((0, T1), (1, T2)):
        ints = {i.name: np.array([v]) for i, v in zip(plan.inputs, target)}
        want = robot_outputs(plan, table, np.array([leg]), ints)
        got = [host.channel_status(len(names) * leg + j)["commanded"] for j in range(len(names))]
        assert got == [int(want[n][0]) for n in names], (leg, got)
