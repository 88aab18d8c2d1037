"""Benchmark: >= 10**6 random targets through the exported Verilog of the leg core, bit-exact.

Exports the leg core (from a build directory written by ``ikseries build``, or by fitting the
preset with ``--fit``), draws N seeded random in-range targets plus every corner (input range
limits, and port extremes that the core clamps), computes the expected pulse widths with the
vectorised golden model, builds a C++ Verilator testbench (ikseries.sim.verilator_bench) and
streams the targets twice:

1. back-to-back, ``o_ready`` always high: the headline rate (targets/s of simulated hardware);
2. with random backpressure (``o_ready`` low with probability --stall) and input bubbles
   (``i_valid`` low with probability --bubble): bit-exactness and latency under stalls.

Every output transfer is compared bit-exactly with the golden model and every target's latency
is checked (pipeline-advance cycles between its input and output transfers == the core's
latency). Prints the figures, writes JSON, and exits with status 1 if anything mismatched.
Pipelined and modulo-scheduled builds (a target every N cycles: the latency is counted in cycles
of the pipeline enable); folded and shared builds handshake differently and are refused.

    python bench/verilator_throughput.py [BUILD_DIR] [-n 1000000] [--seed 1]
                                           [--json docs/results/verilator_throughput.json]
    python bench/verilator_throughput.py --fit [--preset cylinder-leg] ...
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import json
import runpy
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ikseries.fit.plan import Plan
from ikseries.sim import golden
from ikseries.sim.targets import corner_targets, random_targets
from ikseries.sim.verilator_bench import build_testbench, run_testbench, write_vectors

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer

TOP = "leg_core"


#: stream rules (:data:`ikseries.hdl.architectures.STREAM_RULES`) of leg tops that stall as a
#: whole when an output waits (the bench counts latency in cycles of that pipeline enable); the
#: folded, shared and buffered cores handshake differently
GLOBAL_STALL = ("pipelined", "modulo")


def _load(args) -> tuple[Plan, str, str, int, int, str]:
    """(plan, Verilog text, top module, latency, initiation interval, where it came from)."""
    from ikseries.hdl.export import leg_verilog
    from ikseries.hdl.leg import LegCore
    if args.fit:
        from ikseries.fit.fitter import fit_robot
        from ikseries.robot import load_preset
        robot = load_preset(args.preset)
        plan = fit_robot(robot)[0]
        core = LegCore(plan, robot.hardware.pwm_period_ticks)
        return plan, leg_verilog(core, TOP), TOP, core.latency, 1, f"fitted preset {args.preset}"
    bdir = Path(args.build_dir)
    if not (bdir / "manifest.json").is_file() or not (bdir / "plan.json").is_file():
        sys.exit(f"{str(bdir)!r} holds no ikseries build (no manifest.json / plan.json); run "
                 f"`ikseries build -o {bdir}` first or give --fit")
    man = json.loads((bdir / "manifest.json").read_text())
    rule = man.get("stream_rule", "pipelined")
    if rule not in GLOBAL_STALL:
        sys.exit(f"this bench runs leg cores whose whole pipeline stalls while an output waits (stream rules "
                 f"{', '.join(GLOBAL_STALL)}), not a {rule!r} build ({bdir})")
    plan = Plan.from_json(json.loads((bdir / "plan.json").read_text()))
    vfile = bdir / f"{man['module']}.v"
    return (plan, vfile.read_text(), man["module"], int(man["latency_cycles"]),
            int(man.get("initiation_interval", 1)), str(vfile))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("build_dir", nargs="?", default="build/cylinder-leg")
    ap.add_argument("--fit", action="store_true", help="fit the preset instead of reading a build")
    ap.add_argument("--preset", default="cylinder-leg")
    ap.add_argument("-n", type=int, default=1_000_000, help="random targets (plus corners); default 10**6")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--stall", type=float, default=0.25, help="o_ready low probability in the 2nd pass")
    ap.add_argument("--bubble", type=float, default=0.1, help="i_valid low probability in the 2nd pass")
    ap.add_argument("--cxx-opt", default="-O2", help="C++ optimisation of the Verilated model")
    ap.add_argument("--workdir", help="keep the Verilator build here (default: a temporary directory)")
    ap.add_argument("--json", default=FACTS["default_json"]("verilator_throughput"), help="output JSON")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("verilator_throughput", argv)
    if args.n < 1:
        sys.exit(f"-n must be a positive integer, not {args.n}")
    for name in ("stall", "bubble"):
        if not 0 <= getattr(args, name) < 1:
            sys.exit(f"--{name} must be a probability in [0, 1), not {getattr(args, name)}")

    t0 = time.perf_counter()
    plan, verilog, top, latency, ii, source = _load(args)
    prep_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    corners = corner_targets(plan, port_extremes=True)
    rand = random_targets(plan, args.n, args.seed)
    targets = {k: np.concatenate([corners[k], rand[k]]) for k in corners}
    expected = golden.outputs(plan, targets)
    golden_s = time.perf_counter() - t0

    tmp = None
    if args.workdir:
        wd = Path(args.workdir)
    else:
        tmp = tempfile.mkdtemp(prefix="ikseries-vbench-")
        wd = Path(tmp)
    try:
        wd.mkdir(parents=True, exist_ok=True)
        n = write_vectors(wd / "vectors.bin", plan, targets, expected)
        print(f"{source}: {n:,} targets ({n - args.n} corners), golden model {golden_s:.1f} s; "
              f"building the Verilator testbench ({args.cxx_opt}) ...", flush=True)
        tb = build_testbench(plan, verilog, top, wd, cxx_opt=args.cxx_opt, advance="i_ready" if ii == 1 else "enable")
        print(f"built in {tb.build_s:.1f} s", flush=True)
        passes = {}
        for name, stall, bubble in (("back_to_back", 0.0, 0.0), ("backpressure", args.stall, args.bubble)):
            r = run_testbench(tb, wd / "vectors.bin", latency, stall=stall, bubble=bubble, seed=args.seed,
                              initiation_interval=ii)
            passes[name] = r
            print(f"{name:13}: {r['outputs_checked']:,}/{r['targets']:,} targets checked in {r['cycles']:,} "
                  f"cycles, {r['loop_seconds']:.2f} s -> {r['targets_per_second']:,} targets/s "
                  f"({r['cycles_per_second']:,} cycles/s); mismatches {r['mismatches']}, latency errors "
                  f"{r['latency_errors']}, latency {r['latency_cycles_min']}..{r['latency_cycles_max']} cycles "
                  f"(expected {latency} pipeline steps) -> {'PASS' if r['passed'] else 'FAIL'}", flush=True)
            for m in r["first_mismatches"] + r["first_latency_errors"]:
                print(f"    {m}")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)

    out = {"source": source, "targets": n, "random_targets": args.n, "corner_targets": n - args.n,
           "seed": args.seed, "latency_cycles": latency, "initiation_interval": ii, "cxx_opt": args.cxx_opt,
           "rate_targets_per_second": passes["back_to_back"]["targets_per_second"],
           "mismatches": sum(p["mismatches"] for p in passes.values()),
           "latency_errors": sum(p["latency_errors"] for p in passes.values()),
           "passed": all(p["passed"] for p in passes.values()),
           "wall_seconds": {"export_or_fit": round(prep_s, 2), "golden": round(golden_s, 2),
                            "verilator_build": tb.build_s,
                            **{f"run_{k}": p["wall_seconds"] for k, p in passes.items()}},
           "passes": passes}
    jpath = FACTS["write_result"](args.json, out, run)
    print(f"rate {out['rate_targets_per_second']:,} targets/s, {out['mismatches']} mismatches, "
          f"{out['latency_errors']} latency errors: {'PASS' if out['passed'] else 'FAIL'}; wrote {jpath}")
    return 0 if out["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
