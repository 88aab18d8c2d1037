"""Benchmark: the CORDIC baseline against the polynomial evaluator, measured in the same run.

For one robot (default: the cylinder-leg preset):

1. fit the polynomial plan (``fit_robot``) and measure it (``ikseries.accuracy.measure``);
2. size the CORDIC leg solver (``size_cordic``: fewest iterations / narrowest formats meeting
   the same tolerance on the same >= 10**6 verification points) and measure it, also on a
   second, independent point set (another seed) to show how the sizing generalises;
3. export both as flat-port Verilog tops with identical stream interfaces
   (``ikseries.hdl.flat.FlatStreamTop``: evaluator / solver only, no PWM);
4. Yosys resource counts for every family of the device registry (``ikseries.synth``), netlists
   kept in ``<out>/<design>/<target>/netlist.json`` for a place-and-route step;
5. with ``--pnr DEVICES``: Fmax and placed utilisation from Yosys + nextpnr (``ikseries.pnr``)
   on each device, at the robot's clock.

Prints a table and writes JSON (default ``docs/results/cordic_vs_poly.json``; Verilog and netlists
under ``--out``).

    python bench/cordic_vs_poly.py [--robot FILE] [--margins 0,0.075] [--design JSON] [--no-poly]
                                   [--targets ice40,ecp5,xc7] [--pnr DEVICES] [--jobs N] [--out DIR]
                                   [--json FILE]

One CORDIC design per sizing margin: margin 0 meets the tolerance exactly on the verification
points (it may exceed it slightly elsewhere: see the fresh-point figures), 0.075 pu is the
margin the polynomial fitter keeps (15 % of the tolerance). ``--design '{"rot_iters": 13, ...}'``
skips the sizing (about 1.5 min per margin) and uses that design.
Whole run on 2 cores: about 15 minutes, mostly Yosys on the polynomial design.
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

from ikseries.accuracy import measure, verification_points
from ikseries.fit.baselines.cordic import CordicDesign, CordicPlan
from ikseries.fit.baselines.cordic_sizing import measure_cordic, size_cordic
from ikseries.fit.fitter import fit_robot
from ikseries.hdl.cordic import CordicLegSolver
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.hdl.flat import stream_verilog
from ikseries.robot import load_preset, load_robot
from ikseries.constraints.devices import FAMILIES as TARGETS, PNR_DEVICES
from ikseries.synth import synth_counts

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# -- steps: each takes and extends the shared ``ctx`` ------------------------------------------
def polynomial_step(ctx: dict) -> None:
    robot = ctx["robot"]
    t0 = time.perf_counter()
    plan, _ = fit_robot(robot)
    m = measure(robot, plan, ctx["points"])
    ctx["designs"]["polynomial"] = {
        "core": PlanEvaluator(plan), "top": "poly_evaluator",
        "record": {"latency_cycles": plan.depth,
                   "max_error_pu": {s: e["total"] for s, e in m["servos"].items()},
                   "error_points": m["points"],
                   "seconds_fit_and_measure": round(time.perf_counter() - t0, 1),
                   "plan": {"nodes": len(plan.nodes), "multiplies": plan.count("mul")}}}
    say(f"polynomial: latency {plan.depth}, max error "
        + ", ".join(f"{s} {e['total']:.4f}" for s, e in m["servos"].items()) + " pu")


def cordic_step(ctx: dict) -> None:
    robot, args = ctx["robot"], ctx["args"]
    for margin in ctx["margins"]:
        name = "cordic" if margin == 0 else f"cordic_m{margin:g}"
        t0 = time.perf_counter()
        if args.design:
            design = CordicDesign(**json.loads(args.design))
            sized = "given on the command line"
        else:
            design = size_cordic(robot, ctx["points"], margin_pu=margin, progress=say)
            sized = f"size_cordic on the verification points, margin {margin:g} pu"
        t_size = time.perf_counter() - t0
        m = measure_cordic(robot, design, ctx["points"])
        fresh = measure_cordic(robot, design, verification_points(robot, seed=2))
        cp = CordicPlan(robot, design)
        ctx["designs"][name] = {
            "core": CordicLegSolver(robot, design),
            "top": name.replace(".", "p") + "_solver",
            "record": {"latency_cycles": cp.latency,
                       "max_error_pu": {s: e["total"] for s, e in m["servos"].items()},
                       "error_points": m["points"],
                       "max_error_pu_fresh_points": {s: e["total"] for s, e in fresh["servos"].items()},
                       "worst_at": {s: e["at"] for s, e in m["servos"].items()},
                       "design": design.as_dict(), "sized": sized, "margin_pu": margin,
                       "seconds_sizing": round(t_size, 1), "register_bits": cp.register_bits(),
                       "stages": {"isqrt": sum(n.startswith("sqrt") for n in cp.stage_names)}}}
        say(f"{name}: {design.as_dict()}, latency {cp.latency}, max error "
            + ", ".join(f"{s} {e['total']:.4f}" for s, e in m["servos"].items()) + " pu (fresh points: "
            + ", ".join(f"{s} {e['total']:.4f}" for s, e in fresh["servos"].items()) + ")")
        if args.design:
            break


def export_step(ctx: dict) -> None:
    for name, d in ctx["designs"].items():
        ddir = ctx["out"] / name
        ddir.mkdir(parents=True, exist_ok=True)
        path = ddir / f"{d['top']}.v"
        path.write_text(stream_verilog(d["core"], d["top"]))
        d["verilog"] = path
        d["record"]["verilog"] = str(path)


def synth_step(ctx: dict) -> None:
    targets = ctx["targets"]
    for name, d in ctx["designs"].items():
        say(f"synthesising {name} ...")
        res = synth_counts(d["verilog"], d["top"], targets, workdir=ctx["out"] / name, progress=say,
                           jobs=ctx["args"].jobs, netlist=True)
        d["record"]["synth"] = {t: {"device": r["device"], "script": r["script"], "counts": r["counts"],
                                    "seconds": r["seconds"]} for t, r in res.items()}
        d["netlists"] = {t: ctx["out"] / name / t / "netlist.json" for t in targets}


def pnr_step(ctx: dict) -> None:
    """Fmax and placed utilisation per ``--pnr`` device (``ikseries.pnr``, nextpnr seed 1) at
    the robot's clock; a design that does not fit the device is recorded as such."""
    devices = ctx["pnr_devices"]
    if not devices:
        ctx["notes"].append("place and route not run (--pnr DEVICES runs it)")
        return
    from ikseries.pnr import DoesNotFitError, place_and_route
    clock = ctx["robot"].hardware.clock_hz
    for name, d in ctx["designs"].items():
        d["record"]["pnr"] = {}
        for dev in devices:
            say(f"place and route of {name} on {dev} ...")
            try:
                res = place_and_route(d["verilog"].read_text(), d["top"], dev, clock, ctx["out"] / name / f"pnr-{dev}")
                d["record"]["pnr"][dev] = res.to_json()
            except DoesNotFitError as e:
                d["record"]["pnr"][dev] = {"fits": False, "overflow": {k: list(v) for k, v in e.overflow.items()}}


STEPS = [polynomial_step, cordic_step, export_step, synth_step, pnr_step]


def _table(ctx: dict) -> str:
    rows = [f"{'':24}" + "".join(f"{n:>14}" for n in ctx["designs"])]
    recs = {n: d["record"] for n, d in ctx["designs"].items()}

    def row(label, get):
        vals = []
        for n in ctx["designs"]:
            try:
                vals.append(f"{get(recs[n]):>14}")
            except KeyError:
                vals.append(f"{'-':>14}")
        rows.append(f"{label:24}" + "".join(vals))

    row("latency (cycles)", lambda r: r["latency_cycles"])
    for s in ctx["robot"].servos:
        row(f"max error {s} (pu)", lambda r, s=s: f"{r['max_error_pu'][s]:.4f}")
    for s in ctx["robot"].servos:
        row(f"  fresh points {s}", lambda r, s=s: f"{r['max_error_pu_fresh_points'][s]:.4f}")
    row("register bits", lambda r: r["register_bits"])
    for t in ctx["targets"]:
        for c in ("LUT", "FF", "carry", "DSP"):
            row(f"{t} {c}", lambda r, t=t, c=c: r["synth"][t]["counts"][c])
    for dev in ctx["pnr_devices"]:
        row(f"{dev} Fmax (MHz)", lambda r, dev=dev: (f"{r['pnr'][dev]['fmax_mhz']:.1f}" if r["pnr"][dev]["fits"]
                                                      else "does not fit"))
    return "\n".join(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default=None, help="robot TOML (default: the cylinder-leg preset)")
    ap.add_argument("--design", default=None, help="one CORDIC design as JSON (skips the sizing)")
    ap.add_argument("--margins", default="0,0.075",
                    help="CORDIC sizing margins (pu), one design each; 0 = exactly the tolerance on "
                         "the verification points, 0.075 = the polynomial fitter's 15 %% margin")
    ap.add_argument("--no-poly", action="store_true", help="skip the polynomial design")
    ap.add_argument("--targets", default=",".join(TARGETS))
    ap.add_argument("--pnr", default="", help="place-and-route devices, comma-separated (default: none)")
    ap.add_argument("--jobs", type=int, default=1, help="parallel Yosys processes")
    ap.add_argument("--out", default="build/cordic_vs_poly")
    ap.add_argument("--json", default=FACTS["default_json"]("cordic_vs_poly"), help="output JSON")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("cordic_vs_poly", argv)
    targets = [t for t in args.targets.split(",") if t]
    for t in targets:
        if t not in TARGETS:
            sys.exit(f"--targets must name targets among {', '.join(TARGETS)}, not {t!r}")
    if args.jobs < 1:
        sys.exit(f"--jobs must be >= 1, not {args.jobs}")
    pnr_devices = [v for v in args.pnr.split(",") if v]
    for v in pnr_devices:
        if v not in PNR_DEVICES:
            sys.exit(f"--pnr must name devices among {', '.join(PNR_DEVICES)}, not {v!r}")
    try:
        margins = [float(v) for v in args.margins.split(",") if v]
    except ValueError:
        sys.exit(f"--margins must be comma-separated numbers, not {args.margins!r}")
    robot = load_robot(args.robot) if args.robot else load_preset("cylinder-leg")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    ctx = {"args": args, "robot": robot, "targets": targets, "out": out, "designs": {}, "notes": [],
           "margins": margins, "pnr_devices": pnr_devices,
           "points": verification_points(robot)}
    t0 = time.perf_counter()
    for step in STEPS:
        if step is polynomial_step and args.no_poly:
            continue
        say(f"== {step.__name__}")
        step(ctx)
    result = {"robot": robot.name, "tolerance_pu": robot.fit.tolerance_pu,
              "points": len(next(iter(ctx["points"].values()))),
              "designs": {n: d["record"] for n, d in ctx["designs"].items()},
              "notes": ctx["notes"], "seconds": round(time.perf_counter() - t0, 1)}
    path = FACTS["write_result"](args.json, result, run)
    print(_table(ctx))
    for n in ctx["notes"]:
        print(f"note: {n}")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
