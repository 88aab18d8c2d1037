"""The exported robot controller at its UART pin under a long seeded fuzz, on Verilator.

Builds ``RobotController`` over the small test plan (the cylinder leg at 4 pu; two legs, PWM
period 820 cycles, UART divisor 4) and runs the cocotb fuzz test
(``ikseries.sim.cocotb_controller.tests.test_fuzz``) with ``--bytes`` of good, corrupted and
garbage traffic: every answer against the receiver model's good frames, every PWM period's
widths against the model, the status counters against the model's. Prints a table and writes JSON.

    python bench/controller_fuzz.py [--bytes 100000] [--seed 1] [--simulator verilator] [--out docs/results/controller_fuzz.json]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import dataclasses
import json
import runpy
import sys
import tempfile
import time
from pathlib import Path

from ikseries.fit.fitter import fit_robot
from ikseries.robot import load_preset
from ikseries.sim.controller_runner import run_controller

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer
LEGS, PERIOD, CLOCK_HZ, BAUD = 2, 820, 48_000_000, 12e6


def small_plan_file(workdir: Path) -> Path:
    """The tests' small plan: the cylinder leg fitted at a 4 pu tolerance."""
    robot = load_preset("cylinder-leg")
    small = dataclasses.replace(robot, name="cylinder-leg-small", fit=dataclasses.replace(robot.fit, tolerance_pu=4.0))
    path = workdir / "plan.json"
    path.write_text(fit_robot(small)[0].dumps())
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bytes", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--simulator", choices=("verilator", "icarus"), default="verilator")
    ap.add_argument("--out", default=FACTS["default_json"]("controller_fuzz"))
    args = ap.parse_args(argv)
    if args.bytes < 1:
        ap.error(f"--bytes must be a positive integer, not {args.bytes}")
    run = FACTS["run_facts"]("controller_fuzz", argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        plan = small_plan_file(work)
        t0 = time.perf_counter()
        res = run_controller(plan, LEGS, PERIOD, CLOCK_HZ, BAUD, args.simulator, work / "build", seed=args.seed,
                             fuzz_bytes=args.bytes, testcase="test_fuzz")
        seconds = time.perf_counter() - t0
        summary_file = work / "build" / "fuzz.json"
        fuzz = json.loads(summary_file.read_text()) if summary_file.exists() else None
    print(res.summary())
    passed = res.ok and fuzz is not None
    if fuzz:
        print(f"\n{'bytes':>8} {'good frames':>12} {'after bad':>10} {'periods':>8} {'cycles':>10} {'crc':>6} "
              f"{'bad_length':>10} {'unknown':>8}")
        c = fuzz["counters"]
        print(f"{fuzz['bytes']:8} {fuzz['good_frames']:12} {fuzz['after_bad']:10} {fuzz['periods_checked']:8} "
              f"{fuzz['cycles']:10} {c['crc']:6} {c['bad_length']:10} {c['unknown_command']:8}")
    payload = {"simulator": args.simulator, "seed": args.seed, "legs": LEGS, "period": PERIOD, "clock_hz": CLOCK_HZ,
               "baud": BAUD, "passed": passed, "message": res.tests.get("test_fuzz", (False, "no result"))[1],
               "fuzz": fuzz, "build_s": round(res.run.build_s, 1), "simulation_s": round(res.run.test_s, 1),
               "seconds": round(seconds, 1)}
    out = FACTS["write_result"](args.out, payload, run)
    print(f"wrote {out}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
