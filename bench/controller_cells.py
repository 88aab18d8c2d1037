"""Yosys iCE40 counts of the robot controller for a hexapod (6 legs of the small plan's 3
servos, 18 channels) and of its parts, and what it adds beyond its IK core (issue 13's budget:
at most 600 logic cells on the iCE40UP5K for everything but the core).

    python bench/controller_cells.py [--legs 6] [--clock 12e6] [--baud 1e6] [--period-us 20000]
                                     [--tolerance-pu 4] [--workdir DIR]
                                     [--json docs/results/controller_cells.json]

The core inside the controller leaves its own PWM bank unconnected (synthesis removes it), so
the core's share is the RobotCore alone minus that bank; the servo controller's share is
given with and without its own bank (the servo pins' PWM is the one part of it a plain IK
core with a bank would have as well).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import runpy
import tempfile
from pathlib import Path

from amaranth.back import verilog

from ikseries.fit.fitter import fit_robot
from ikseries.hdl.controller import RobotController
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.robot import load_preset
from ikseries.synth import synth_counts
from ikseries.threads import single_threaded_blas

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def counts(component, name, workdir: Path) -> dict:
    d = workdir / name
    d.mkdir(parents=True, exist_ok=True)
    (d / "top.v").write_text(verilog.convert(component, name="top", emit_src=False))
    return synth_counts(d / "top.v", "top", ["ice40"], workdir=d)["ice40"]["counts"]


def minus(a: dict, b: dict) -> dict:
    return {k: a.get(k, 0) - b.get(k, 0) for k in a}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--legs", type=int, default=6)
    ap.add_argument("--clock", type=float, default=12e6)
    ap.add_argument("--baud", type=float, default=1e6)
    ap.add_argument("--period-us", type=float, default=20000.0)
    ap.add_argument("--tolerance-pu", type=float, default=4.0, help="the fit's tolerance (a small plan)")
    ap.add_argument("--workdir", type=Path)
    ap.add_argument("--json", default=FACTS["default_json"]("controller_cells"))
    a = ap.parse_args(argv)
    run = FACTS["run_facts"]("controller_cells", argv)
    single_threaded_blas()
    robot = load_preset("cylinder-leg")
    robot = dataclasses.replace(robot, fit=dataclasses.replace(robot.fit, tolerance_pu=a.tolerance_pu))
    plan = fit_robot(robot)[0]
    period = round(a.period_us * a.clock / 1e6)
    ctl = RobotController(plan, a.legs, period, int(a.clock), a.baud)
    core, servo = ctl.core, ctl.servo
    parts = {"link": ctl.link, "dispatcher": ctl.dispatcher, "servo": servo, "core": core,
             "servo_bank": ServoPWMBank(period, ctl.width_bits, servo.channels, 1),
             "core_bank": ServoPWMBank(period, ctl.width_bits, a.legs, len(core.servos))}
    with tempfile.TemporaryDirectory() as tmp:
        wd = a.workdir or Path(tmp)
        got = {"controller": counts(ctl, "controller", wd)}
        got.update({name: counts(c, name, wd) for name, c in parts.items()})
    core_used = minus(got["core"], got["core_bank"])
    payload = {"legs": a.legs, "channels": servo.channels, "width_bits": ctl.width_bits,
               "period": period, "clock_hz": a.clock, "divisor": ctl.divisor,
               "pass_cycles": servo.pass_cycles, "init_cycles": servo.init_cycles, **got,
               "servo_without_bank": minus(got["servo"], got["servo_bank"]),
               "core_without_bank": core_used,
               "beyond_core": minus(got["controller"], core_used)}
    print(json.dumps(payload, indent=1))
    print(f"wrote {FACTS['write_result'](a.json, payload, run)}")


if __name__ == "__main__":
    main()
