"""Yosys iCE40 counts of the servo controller for a hexapod (18 channels), with and without
its pins' pulse counters (a :class:`~ikseries.hdl.pwmcounters.ServoPWMCounters`; in a robot
controller they replace the robot core's own PWM bank, which is then left unconnected).

    python bench/servo_cells.py [--channels 18] [--width-bits 16] [--period 240000] [--workdir DIR]
                                [--json docs/results/servo_cells.json]
"""
from __future__ import annotations

import argparse
import json
import runpy
import tempfile
from pathlib import Path

from amaranth.lib import data

from ikseries.hdl.pwmcounters import ServoPWMCounters
from ikseries.hdl.servo import ServoController
from ikseries.synth import component_counts

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def counts(component, name, workdir: Path) -> dict:
    return component_counts(component, workdir / name)["ice40"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--channels", type=int, default=18)
    ap.add_argument("--servos", type=int, default=3, help="servos per leg on the ik stream")
    ap.add_argument("--width-bits", type=int, default=16)
    ap.add_argument("--period", type=int, default=240000, help="20 ms at 12 MHz")
    ap.add_argument("--workdir", type=Path)
    ap.add_argument("--json", default=FACTS["default_json"]("servo_cells"))
    a = ap.parse_args(argv)
    run = FACTS["run_facts"]("servo_cells", argv)
    ik = data.StructLayout({"leg": range(a.channels // a.servos),
                            "widths": data.StructLayout({f"s{j}": a.width_bits for j in range(a.servos)})})
    with tempfile.TemporaryDirectory() as tmp:
        wd = a.workdir or Path(tmp)
        servo = ServoController(a.channels, a.width_bits, a.period, ik_layout=ik)
        ctl = counts(servo, "controller", wd)
        bank = counts(ServoPWMCounters(a.period, a.width_bits, a.channels, servo.lead), "bank", wd)
    payload = {"channels": a.channels, "width_bits": a.width_bits, "period": a.period,
               "controller": ctl, "pwm_bank": bank,
               "controller_without_bank": {k: ctl.get(k, 0) - bank.get(k, 0) for k in ctl}}
    print(json.dumps(payload, indent=1))
    print(f"wrote {FACTS['write_result'](a.json, payload, run)}")


if __name__ == "__main__":
    main()
