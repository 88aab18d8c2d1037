"""Simulation harness for tests/test_servo.py: drive a ServoController period by period and
measure every channel's pulse width on its pin."""
from __future__ import annotations

from amaranth.sim import Simulator

from ikseries.hdl.servo import ServoController


async def _send(ctx, port, **fields):
    for k, v in fields.items():
        ctx.set(getattr(port.payload, k) if k != "_" else port.payload, v)
    ctx.set(port.valid, 1)
    while True:
        ready = ctx.get(port.ready)
        await ctx.tick()
        if ready:
            break
    ctx.set(port.valid, 0)


async def _strobe(ctx, sig):
    ctx.set(sig, 1)
    await ctx.tick()
    ctx.set(sig, 0)


async def apply(ctx, dut, cmd, statuses):
    """One command: ("write", ch, field, value), ("target", ch, pulse, time), ("commit",),
    ("ik", leg, widths), ("keepalive",), ("read", ch)."""
    kind = cmd[0]
    if kind == "write":
        await _send(ctx, dut.write, channel=cmd[1], field=int(cmd[2]), value=cmd[3])
    elif kind == "target":
        await _send(ctx, dut.target, channel=cmd[1], pulse=cmd[2], time=cmd[3])
    elif kind == "commit":
        await _strobe(ctx, dut.commit)
    elif kind == "keepalive":
        await _strobe(ctx, dut.keepalive)
    elif kind == "ik":
        ctx.set(dut.ik.payload.leg, cmd[1])
        for name, w in zip(dut.servos, cmd[2]):
            ctx.set(dut.ik.payload.widths[name], w)
        await _send(ctx, dut.ik)
    elif kind == "read":
        # the target, then the current pulse (the flags of the second read)
        got = []
        for current in (0, 1):
            await _send(ctx, dut.read, channel=cmd[1], current=current)
            ctx.set(dut.status.ready, 1)
            while not ctx.get(dut.status.valid):
                await ctx.tick()
            got.append(ctx.get(dut.status.payload.pulse))
            flags = (bool(ctx.get(dut.status.payload.moving)), bool(ctx.get(dut.status.payload.enabled)))
            await ctx.tick()
            ctx.set(dut.status.ready, 0)
        statuses.append((*got, *flags))
    else:
        raise ValueError(f"unknown command {cmd!r}")


def run(dut: ServoController, schedule: list[list[tuple]], periods: int):
    """Widths measured on the pins per period (period 0 = from reset), the clamp and
    bad-write strobe counts per period, the failsafe flag at each period start, status
    answers, and the longest busy stretch. ``schedule[k]`` runs after pass k."""
    out = {"widths": [], "clamped": [], "bad": [], "failsafe": [], "status": [], "busy_max": 0}

    async def sampler(ctx):
        counts = [0] * dut.channels
        clamped = bad = busy = 0
        started = False
        for _ in range(periods * dut.period + 2):
            await ctx.tick()
            if ctx.get(dut.period_start):
                if started:
                    out["widths"].append(counts)
                    out["clamped"].append(clamped)
                    out["bad"].append(bad)
                out["failsafe"].append(ctx.get(dut.failsafe))
                counts, clamped, bad, started = [0] * dut.channels, 0, 0, True
            if started:
                bits = ctx.get(dut.pwm)
                for c in range(dut.channels):
                    counts[c] += (bits >> c) & 1
            clamped += ctx.get(dut.clamped)
            bad += ctx.get(dut.bad_write)
            busy = busy + 1 if ctx.get(dut.busy) else 0
            out["busy_max"] = max(out["busy_max"], busy)

    async def driver(ctx):
        for k in range(periods - 1):
            while not ctx.get(dut.period_start):
                await ctx.tick()
            await ctx.tick()
            start = 0
            while ctx.get(dut.busy):
                await ctx.tick()
                start += 1
            for cmd in schedule[k] if k < len(schedule) else ():
                await apply(ctx, dut, cmd, out["status"])
            assert not ctx.get(dut.period_start), "commands ran into the next period"

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(sampler)
    sim.add_testbench(driver)
    sim.run()
    return out
