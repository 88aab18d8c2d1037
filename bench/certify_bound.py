"""Benchmark: certified error bound of the cylinder-leg fit vs the sampled maximum.

Fits the robot (or loads a plan), measures the sampled error on >= 10**6 points
(``ikseries.accuracy.measure``), certifies the bound over the continuous workspace box
(``ikseries.fit.certify``) and prints and writes both per servo.

    python bench/certify_bound.py [--preset cylinder-leg] [--plan plan.json]
                                  [--max-cells N] [--target PU]
                                  [--json docs/results/certify_bound.json]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import json
import runpy
import sys
import time
from pathlib import Path

from ikseries.accuracy import measure
from ikseries.fit.certify import DEFAULT_MAX_CELLS, CertificationError, certify
from ikseries.fit.fitter import fit_robot
from ikseries.fit.plan import Plan
from ikseries.robot import load_preset

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="cylinder-leg")
    ap.add_argument("--plan", default=None, help="plan JSON to certify (default: fit the preset)")
    ap.add_argument("--max-cells", type=int, default=DEFAULT_MAX_CELLS, help="cell budget per servo")
    ap.add_argument("--target", type=float, default=None,
                    help="approximation target in pu (default: what the tolerance leaves)")
    ap.add_argument("--json", default=FACTS["default_json"]("certify_bound"))
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("certify_bound", argv)
    if args.max_cells < 1:
        sys.exit(f"--max-cells must be >= 1, not {args.max_cells}")
    robot = load_preset(args.preset)
    if args.plan:
        plan = Plan.from_json(json.loads(Path(args.plan).read_text()))
    else:
        t0 = time.perf_counter()
        plan = fit_robot(robot)[0]
        print(f"fitted {args.preset}: {len(plan.nodes)} nodes, {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    sampled = measure(robot, plan)
    t_sampled = time.perf_counter() - t0
    print(f"sampled {sampled['points']:,} points in {t_sampled:.1f} s")
    t0 = time.perf_counter()
    cert = certify(robot, plan, target_pu=args.target, max_cells=args.max_cells,
                   progress=lambda m: print(m, file=sys.stderr, flush=True))
    t_cert = time.perf_counter() - t0
    print(f"{'servo':6} {'sampled approx':>14} {'certified approx':>16} {'sampled total':>13} "
          f"{'certified total':>15} {'cells':>8} {'time':>7}")
    rows = []
    for s in cert.servos:
        m = sampled["servos"][s.name]
        print(f"{s.name:6} {m['approximation']:14.4f} {s.approximation_pu:16.4f} {m['total']:13.4f} "
              f"{s.total_pu:15.4f} {s.cells:8d} {s.seconds:6.1f}s" + ("" if s.converged else "  budget spent"))
        rows.append({"servo": s.name, "sampled_approximation_pu": m["approximation"],
                     "sampled_total_pu": m["total"], "certified": {**s.__dict__, "total_pu": s.total_pu}})
    try:
        cert.check(robot.fit.tolerance_pu)
        verdict = f"certified within the tolerance {robot.fit.tolerance_pu:g} pu"
    except CertificationError as e:
        verdict = f"NOT certified: {e}"
    print(verdict)
    out = {"preset": args.preset, "nodes": len(plan.nodes), "points_sampled": sampled["points"],
           "seconds_sampled": t_sampled, "seconds_certify": t_cert, "max_cells": args.max_cells,
           "tolerance_pu": robot.fit.tolerance_pu, "verdict": verdict, "servos": rows,
           "certificate": cert.to_json()}
    FACTS["write_result"](args.json, out, run)
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
