"""Benchmark: the integer power series paper's procedure beside ikseries' own fit.

Fits the robot both ways (``fit.fitter.fit_robot`` and ``fit.baselines.paper.fit_paper``), lowers both
to evaluation plans, measures both on the same >= 10**6 workspace points and prints a
Markdown table; writes the figures as JSON. About a minute on one core for cylinder-leg.

    python bench/paper_baseline.py [--preset cylinder-leg] [--theta-fit minimax|chebyshev]
                                   [--json docs/results/paper_baseline.json]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import runpy
import sys
import time
from pathlib import Path

from ikseries.fit.baselines.comparison import compare, render_comparison
from ikseries.fit.fitter import fit_robot
from ikseries.fit.baselines.paper import THETA_FITS, fit_paper, paper_errors, paper_plan

from ikseries.accuracy import verification_points
from ikseries.robot import load_preset, preset_names

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="cylinder-leg", choices=preset_names())
    ap.add_argument("--theta-fit", default="minimax", choices=THETA_FITS)
    ap.add_argument("--json", default=FACTS["default_json"]("paper_baseline"), help="output JSON")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("paper_baseline", argv)
    robot = load_preset(args.preset)
    times = {}
    t0 = time.perf_counter()
    ik_plan, _ = fit_robot(robot)
    times["ikseries_fit_s"] = round(time.perf_counter() - t0, 1)
    t0 = time.perf_counter()
    fit = fit_paper(robot, args.theta_fit)
    pplan = paper_plan(robot, fit)
    times["paper_fit_s"] = round(time.perf_counter() - t0, 1)
    points = verification_points(robot)
    t0 = time.perf_counter()
    result = compare(robot, ik_plan, pplan, points)
    float_err = paper_errors(robot, fit, points)
    uncut_err = paper_errors(robot, fit.uncut(), points)
    times["measure_s"] = round(time.perf_counter() - t0, 1)
    result["paper"] = {
        "theta_fit": args.theta_fit, "counts": fit.counts(),
        "float_max_error_pu": {s: e["max_error_pu"] for s, e in float_err["servos"].items()},
        "float_uncut_max_error_pu": {s: e["max_error_pu"] for s, e in uncut_err["servos"].items()},
        "circle_error_pu": {s.name: s.circle_error_pu for s in fit.servos},
        "meta": {k: v for k, v in pplan.meta.items() if k != "servos"},
    }
    result["times_s"] = times
    print(render_comparison(result))
    print("paper series in float64 (7 significant figures, no fixed point), max error (pu): "
          + ", ".join(f"{s} {e:.4f}" for s, e in result["paper"]["float_max_error_pu"].items()))
    print("paper series in float64 before the cut to 7 significant figures, max error (pu): "
          + ", ".join(f"{s} {e:.4f}" for s, e in result["paper"]["float_uncut_max_error_pu"].items()))
    print("paper step 1 alone (theta series on the worst circle, unrounded), max error (pu): "
          + ", ".join(f"{s} {e:.4f}" for s, e in result["paper"]["circle_error_pu"].items()))
    FACTS["write_result"](args.json, result, run)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
