"""Yosys counts of the robot controller for a hexapod (6 legs of the small plan's 3 servos,
18 channels) and of its parts, and what it adds beyond its IK core, per device family (the
budget: at most 600 logic cells on the iCE40UP5K for everything but the core).

    python bench/controller_cells.py [--legs 6] [--clock 12e6] [--baud 1e6] [--period-us 20000]
                                     [--tolerance-pu 4] [--families ice40 ecp5] [--workdir DIR]
                                     [--json docs/results/controller_cells.json]

The core inside the controller leaves its own PWM bank unconnected (synthesis removes it), so
the core's share is the RobotCore alone minus that bank; the servo controller's share is
given with and without its own bank. Two figures of what the controller adds: beyond the bare
core (its servo PWM bank counted as added), and beyond the core with its own bank (what a
plain IK core on a board has already: the servo pins' PWM; the rest is the UART, link,
dispatcher and per-channel limiter and calibration).
"""
from __future__ import annotations

import argparse
import dataclasses
import runpy
import tempfile
from pathlib import Path

from ikseries.constraints.devices import FAMILIES
from ikseries.fit.fitter import fit_robot
from ikseries.hdl.controller import RobotController
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.robot import load_preset
from ikseries.synth import component_counts
from ikseries.threads import single_threaded_blas

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def minus(a: dict, b: dict) -> dict:
    return {k: a.get(k, 0) - b.get(k, 0) for k in a}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--legs", type=int, default=6)
    ap.add_argument("--clock", type=float, default=12e6)
    ap.add_argument("--baud", type=float, default=1e6)
    ap.add_argument("--period-us", type=float, default=20000.0)
    ap.add_argument("--tolerance-pu", type=float, default=4.0, help="the fit's tolerance (a small plan)")
    ap.add_argument("--families", nargs="+", choices=FAMILIES, default=["ice40", "ecp5"],
                    help="Yosys targets of the device registry (default: the issue's two boards' families)")
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
             "servo_bank": ServoPWMBank(period, ctl.width_bits, servo.channels, 1, in_order=True),
             "core_bank": ServoPWMBank(period, ctl.width_bits, a.legs, len(core.servos))}
    designs = {"controller": ctl, **parts}
    with tempfile.TemporaryDirectory() as tmp:
        wd = a.workdir or Path(tmp)
        got = {name: component_counts(c, wd / name, a.families) for name, c in designs.items()}
    per_family = {}
    for fam in a.families:
        c = {name: got[name][fam] for name in designs}
        core_used = minus(c["core"], c["core_bank"])
        per_family[fam] = {**c, "servo_without_bank": minus(c["servo"], c["servo_bank"]),
                           "core_without_bank": core_used, "beyond_core": minus(c["controller"], core_used),
                           "beyond_core_with_bank": minus(c["controller"], c["core"])}
    payload = {"legs": a.legs, "channels": servo.channels, "width_bits": ctl.width_bits,
               "period": period, "clock_hz": a.clock, "divisor": ctl.divisor,
               "pass_cycles": servo.pass_cycles, "init_cycles": servo.init_cycles, "families": per_family}
    for fam, c in per_family.items():
        print(f"\n{fam}: {'design':<22} {'LUT':>6} {'FF':>6} {'carry':>6} {'DSP':>4} {'BRAM':>5}")
        for name in (*designs, "servo_without_bank", "core_without_bank", "beyond_core", "beyond_core_with_bank"):
            print(f"{'':{len(fam) + 2}}{name:<22} " + " ".join(f"{c[name].get(k, 0):>{w}}" for k, w in
                                                             (("LUT", 6), ("FF", 6), ("carry", 6), ("DSP", 4), ("BRAM", 5))))
    print(f"wrote {FACTS['write_result'](a.json, payload, run)}")


if __name__ == "__main__":
    main()
