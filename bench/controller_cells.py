"""Yosys counts of the robot controller for a hexapod (6 legs of the small plan's 3 servos,
18 channels) and of its parts, and what it adds beyond its IK core, per device family (the
budget: at most 600 logic cells on the iCE40UP5K for everything but the core).

    python bench/controller_cells.py [--legs 6] [--clock 12e6] [--baud 1e6] [--period-us 20000]
                                     [--tolerance-pu 4] [--families ice40 ecp5] [--workdir DIR]
                                     [--json docs/results/controller_cells.json]

The core inside the controller leaves its own PWM bank unconnected (synthesis removes it), so
the core's share is the RobotCore alone minus that bank (the plain core, with its own input
register: the controller's reads the dispatcher's target register instead); the servo controller's share is
given with and without its own pins' PWM (``servo_bank``: its pulse counters, a
:class:`~ikseries.hdl.pwmcounters.ServoPWMCounters`; the core's is a
:class:`~ikseries.hdl.pwmbank.ServoPWMBank`). Two figures of what the controller adds: beyond the bare
core (its servo PWM bank counted as added), and beyond the core with its own bank (what a
plain IK core on a board has already: the servo pins' PWM; the rest is the UART, link,
dispatcher and per-channel limiter and calibration).

On the iCE40 the budget is in logic cells, one LUT4, one carry and one flip-flop each: the
LUT and FF counts alone do not give it (a flip-flop shares a cell only with a LUT that drives
nothing but its D input; one fed by another flip-flop, a block RAM or a LUT of several loads
takes a cell of its own, and so does a carry whose LUT inputs differ). So each design's netlist
is also packed by nextpnr (``--pack-only``, the UP5K SG48): ``LC`` is its ICESTORM_LC count,
and the beyond-core figures subtract the packed cells the same way.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import runpy
import subprocess
import tempfile
from pathlib import Path

from ikseries.constraints.devices import FAMILIES, PNR_DEVICES
from ikseries.fit.fitter import fit_robot
from ikseries.hdl.controller import RobotController
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.hdl.pwmcounters import ServoPWMCounters
from ikseries.pnr import nextpnr_command
from ikseries.robot import load_preset
from ikseries.synth import synth_counts
from ikseries.threads import single_threaded_blas

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def minus(a: dict, b: dict) -> dict:
    return {k: a.get(k, 0) - b.get(k, 0) for k in a if k in b or k != "LC"}


def counts(component, workdir: Path, families) -> dict:
    """``{family: counts}`` of ``component`` (as :func:`~ikseries.synth.component_counts`), the iCE40's
    with ``LC``: its netlist packed by nextpnr (``--pack-only``: no placement, so a design with more
    ports than the package still counts)."""
    from amaranth.back import verilog
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "top.v").write_text(verilog.convert(component, name="top", emit_src=False))
    got = {t: r["counts"] for t, r in synth_counts(workdir / "top.v", "top", families, workdir=workdir,
                                                   netlist="ice40" in families).items()}
    if "ice40" in got:
        tdir = workdir / "ice40"
        subprocess.run([*nextpnr_command("ice40"), *PNR_DEVICES["ice40-up5k-sg48"].nextpnr_args, "--json",
                        "netlist.json", "--pack-only", "--report", "pack.json", "-q"],
                       cwd=tdir, check=True, capture_output=True)
        got["ice40"]["LC"] = json.loads((tdir / "pack.json").read_text())["utilization"]["ICESTORM_LC"]["used"]
    return got


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
    # the core as a board without the controller has it: with its own input register (the
    # controller's core reads the dispatcher's target register instead, see RobotCore.held_input)
    core, servo = ctl.core.registered(), ctl.servo
    parts = {"link": ctl.link, "dispatcher": ctl.dispatcher, "servo": servo, "core": core,
             "servo_bank": ServoPWMCounters(period, ctl.width_bits, servo.channels, servo.lead),
             "core_bank": ServoPWMBank(period, ctl.width_bits, a.legs, len(core.servos))}
    designs = {"controller": ctl, **parts}
    with tempfile.TemporaryDirectory() as tmp:
        wd = a.workdir or Path(tmp)
        got = {name: counts(c, wd / name, a.families) for name, c in designs.items()}
    per_family = {}
    for fam in a.families:
        c = {name: got[name][fam] for name in designs}
        core_used = minus(c["core"], c["core_bank"])
        per_family[fam] = {**c, "servo_without_bank": minus(c["servo"], c["servo_bank"]),
                           "core_without_bank": core_used, "beyond_core": minus(c["controller"], core_used),
                           "beyond_core_with_bank": minus(c["controller"], c["core"])}
    payload = {"legs": a.legs, "channels": servo.channels, "width_bits": ctl.width_bits,
               "period": period, "clock_hz": a.clock, "divisor": ctl.divisor,
               "pass_cycles": servo.pass_cycles, "init_cycles": servo.init_cycles, "lead": servo.lead,
               "max_width": servo.max_width, "families": per_family}
    for fam, c in per_family.items():
        cols = ((("LC", 6),) if fam == "ice40" else ()) + (("LUT", 6), ("FF", 6), ("carry", 6), ("DSP", 4), ("BRAM", 5))
        print(f"\n{fam}: {'design':<22} " + " ".join(f"{k:>{w}}" for k, w in cols))
        for name in (*designs, "servo_without_bank", "core_without_bank", "beyond_core", "beyond_core_with_bank"):
            print(f"{'':{len(fam) + 2}}{name:<22} " + " ".join(f"{c[name].get(k, 0):>{w}}" for k, w in cols))
    print(f"wrote {FACTS['write_result'](a.json, payload, run)}")


if __name__ == "__main__":
    main()
