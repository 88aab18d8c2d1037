"""Benchmark: the divided-differences method (path mode) on the planar arm's three cases.

For each case (phi = 90, y = x + 40; phi = 45, y = -0.5 x + 40; phi = 180, x = -50) it
prints the Newton-cubic formula's error along the path and over the case's 2-D box, the FK
position error along the path and where it occurs, the joint velocity and acceleration
errors, and the minimax comparisons, and writes the whole record as JSON.

    python bench/divided_differences.py [--preset planar-arm] [--json docs/results/divided_differences.json] [--samples N] [--grid N]

The arm's link lengths, pu per degree and tolerance come from the preset; each case sets
its own tool orientation.
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import runpy
import sys
import time
from pathlib import Path

from ikseries.fit.baselines.divided import render_markdown, run_divided_differences
from ikseries.planar_arm import PlanarArm
from ikseries.robot import RobotError, load_preset

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="planar-arm")
    ap.add_argument("--json", default=FACTS["default_json"]("divided_differences"), help="output JSON")
    ap.add_argument("--samples", type=int, default=2001, help="fit samples along each path")
    ap.add_argument("--grid", type=int, default=41, help="2-D fit grid points per side")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("divided_differences", argv)
    try:
        robot = load_preset(args.preset)
    except RobotError as e:
        sys.exit(str(e))
    if not isinstance(robot.geometry, PlanarArm):
        sys.exit(f"--preset must name a planar-arm robot, not {args.preset!r}")
    t0 = time.perf_counter()
    result = run_divided_differences(robot.geometry, pu_per_degree=robot.calibration.pu_per_degree,
                                     tolerance_pu=robot.fit.tolerance_pu, samples=args.samples, grid=args.grid)
    result["seconds"] = time.perf_counter() - t0
    result["preset"] = args.preset
    print(render_markdown(result))
    print(f"({result['seconds']:.2f} s)")
    out = FACTS["write_result"](args.json, result, run)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
