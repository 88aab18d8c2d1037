"""Full hexapod updates through the exported robot controller at its UART pin, on Verilator.

Builds ``RobotController`` for a hexapod's shape (6 legs of the small test plan's 3 servos: the
cylinder leg fitted at 4 pu, 18 channels) at the clock, baud and PWM period given, and runs the
cocotb test ``ikseries.sim.cocotb_controller.tests.test_link_rate``: full ``move_legs`` requests
(all 18 channels) streamed back to back at the line rate, then one at a time waiting for each
answer; every one answered and none dropped, the pins then checked against the model. Prints
updates per second both ways against the target (a full hexapod updated ≥ 1000 times a second at
1 Mbaud) and writes JSON.

    python bench/link_rate.py [--legs 6] [--clock 48e6] [--baud 1e6] [--period-us 20000]
                              [--simulator verilator] [--json docs/results/link_rate.json]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import json
import runpy
import sys
import tempfile
import time
from pathlib import Path

from ikseries.sim.controller_runner import run_controller

HERE = Path(__file__).resolve().parent
FACTS = runpy.run_path(str(HERE / "facts.py"))   # run record, JSON writer
small_plan_file = runpy.run_path(str(HERE / "controller_fuzz.py"))["small_plan_file"]
#: the issue's target: full updates a second at 1 Mbaud
TARGET_HZ = 1000


def rates(summary: dict) -> dict:
    """Updates a second, streamed and one at a time, from the test's cycle counts."""
    clock = summary["clock_hz"]
    return {"streamed_hz": clock / summary["streamed_cycles"], "lockstep_hz": clock / summary["lockstep_cycles"],
            "line_hz": clock / summary["line_cycles"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--legs", type=int, default=6)
    ap.add_argument("--clock", type=float, default=48e6)
    ap.add_argument("--baud", type=float, default=1e6)
    ap.add_argument("--period-us", type=float, default=20000.0)
    ap.add_argument("--simulator", choices=("verilator", "icarus"), default="verilator")
    ap.add_argument("--json", default=FACTS["default_json"]("link_rate"))
    a = ap.parse_args(argv)
    for name in ("legs", "clock", "baud", "period_us"):
        if getattr(a, name) <= 0:
            ap.error(f"--{name.replace('_', '-')} must be > 0, not {getattr(a, name)}")
    run = FACTS["run_facts"]("link_rate", argv)
    period = round(a.period_us * 1e-6 * a.clock)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        t0 = time.perf_counter()
        res = run_controller(small_plan_file(work), a.legs, period, int(a.clock), a.baud, a.simulator,
                             work / "build", testcase="test_link_rate")
        seconds = time.perf_counter() - t0
        found = work / "build" / "link_rate.json"
        summary = json.loads(found.read_text()) if found.exists() else None
    print(res.summary())
    passed = res.ok and summary is not None
    payload = {"simulator": a.simulator, "legs": a.legs, "clock_hz": int(a.clock), "baud": a.baud, "period": period,
               "passed": passed, "message": res.tests.get("test_link_rate", (False, "no result"))[1],
               "summary": summary, "rates": rates(summary) if summary else None, "target_hz": TARGET_HZ,
               "seconds": round(seconds, 1)}
    if summary:
        r = payload["rates"]
        print(f"\n{'channels':>8} {'frame B':>8} {'line cyc':>9} {'streamed':>9} {'upd/s':>7} {'lockstep':>9} "
              f"{'upd/s':>7} {'target':>7}")
        print(f"{summary['channels']:8} {summary['frame_bytes']:8} {summary['line_cycles']:9} "
              f"{summary['streamed_cycles']:9.1f} {r['streamed_hz']:7.0f} {summary['lockstep_cycles']:9.1f} "
              f"{r['lockstep_hz']:7.0f} {TARGET_HZ:7}")
    out = FACTS["write_result"](a.json, payload, run)
    print(f"wrote {out}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
