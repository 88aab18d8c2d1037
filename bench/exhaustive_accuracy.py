"""Benchmark: the error of a built plan at EVERY representable input point of the workspace.

The default test suite and `ikseries build` check >= 10**6 points; this script walks the
whole input grid (297 million points for cylinder-leg with 3 fractional bits per input,
about 10 minutes on one core) and prints and writes the measured maxima.

    python bench/exhaustive_accuracy.py [build/cylinder-leg] [--stride N]
                                          [--json docs/results/exhaustive_accuracy.json]

``--stride N`` takes every N-th value of each input (N**3 fewer points) for a quick run.
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

import numpy as np

from ikseries.accuracy import measure
from ikseries.fit.plan import Plan
from ikseries.robot import robot_from_record

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("build_dir", nargs="?", default="build/cylinder-leg")
    ap.add_argument("--stride", type=int, default=1)
    ap.add_argument("--json", default=FACTS["default_json"]("exhaustive_accuracy"), help="output JSON")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("exhaustive_accuracy", argv)
    if args.stride < 1:
        sys.exit(f"--stride must be >= 1, not {args.stride}")
    bdir = Path(args.build_dir)
    plan = Plan.from_json(json.loads((bdir / "plan.json").read_text()))
    robot = robot_from_record(plan.meta["robot_description"])
    r_in, th_in, z_in = plan.inputs
    rs = np.arange(r_in.lo, r_in.hi + 1, args.stride)
    zs = np.arange(z_in.lo, z_in.hi + 1, args.stride)
    ths = np.arange(th_in.lo, th_in.hi + 1, args.stride)
    rr, zz = (g.ravel() for g in np.meshgrid(rs, zs, indexing="ij"))
    per = max(1, 1_000_000 // len(rr))
    total = {o.name: dict.fromkeys(("approximation", "quantization", "rounding", "total"), 0.0)
             for o in plan.outputs}
    worst_at = {}
    n = 0
    t0 = time.perf_counter()
    for k in range(0, len(ths), per):
        th = ths[k:k + per]
        pts = {r_in.name: np.tile(rr, len(th)), z_in.name: np.tile(zz, len(th)),
               th_in.name: np.repeat(th, len(rr))}
        m = measure(robot, plan, pts, chunk=len(rr) * per)
        n += m["points"]
        for s, e in m["servos"].items():
            if e["total"] > total[s]["total"]:
                worst_at[s] = e["at"]
            for key in total[s]:
                total[s][key] = max(total[s][key], e[key])
        if k // per % 20 == 0:
            print(f"  {n:,} points, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    secs = time.perf_counter() - t0
    out = {"robot": robot.name, "points": n, "stride": args.stride, "seconds": round(secs, 1),
           "tolerance_pu": robot.fit.tolerance_pu,
           "servos": {s: {**total[s], "worst_at": worst_at.get(s)} for s in total}}
    print(f"{robot.name}: {n:,} points (stride {args.stride}) in {secs:.0f} s")
    print(f"{'servo':6} {'approx':>8} {'quant':>8} {'round':>8} {'total':>8}  worst at")
    for s, e in out["servos"].items():
        print(f"{s:6} {e['approximation']:8.4f} {e['quantization']:8.4f} {e['rounding']:8.4f} "
              f"{e['total']:8.4f}  {e['worst_at']}")
    dest = FACTS["write_result"](args.json, out, run)
    print(f"wrote {dest}")
    return 0 if all(e["total"] <= robot.fit.tolerance_pu for e in total.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
