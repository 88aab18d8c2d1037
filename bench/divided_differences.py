"""Benchmark: the divided-differences method (path mode) on the planar arm's three cases.

For each case (phi = 90, y = x + 40; phi = 45, y = -0.5 x + 40; phi = 180, x = -50) it
prints the Newton-cubic formula's error along the path and over the case's 2-D box, the FK
position error along the path and where it occurs, the joint velocity and acceleration
errors, and the minimax comparisons, and writes the whole record as JSON.

    python bench/divided_differences.py [--preset planar-arm] [--json out.json] [--samples N] [--grid N]

The arm's link lengths, pu per degree and tolerance come from the preset; each case sets
its own tool orientation.
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import json
import sys
import time
from pathlib import Path

from ikseries.fit.baselines.divided import render_markdown, run_divided_differences
from ikseries.planar_arm import PlanarArm
from ikseries.robot import RobotError, load_preset


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="planar-arm")
    ap.add_argument("--json", default="build/divided_differences.json", help="output JSON")
    ap.add_argument("--samples", type=int, default=2001, help="fit samples along each path")
    ap.add_argument("--grid", type=int, default=41, help="2-D fit grid points per side")
    args = ap.parse_args(argv)
    try:
        robot = load_preset(args.preset)
    except RobotError as e:
        sys.exit(str(e))
    if not isinstance(robot.geometry, PlanarArm):
        sys.exit(f"--preset must name a planar-arm robot, not {args.preset!r}")
    t0 = time.perf_counter()
    result = run_divided_differences(robot.geometry, pu_per_degree=robot.pu_per_degree,
                                     tolerance_pu=robot.tolerance_pu, samples=args.samples, grid=args.grid)
    result["seconds"] = time.perf_counter() - t0
    result["preset"] = args.preset
    print(render_markdown(result))
    print(f"({result['seconds']:.2f} s)")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
