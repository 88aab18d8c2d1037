"""Benchmark: fit every preset and report, per servo, what the fit costs and achieves.

Per preset and servo: variables, total degree, terms, multiplications per evaluation
(coordinate stage included), coefficient bits, sampled max total error (pu) on >= 10**6
representable points, certified bound (pu), and the preset's fit time (wall and CPU, certification
included; the CPU seconds of the certifications alone beside them).

    python bench/fit_benchmark.py [PRESET ...] [--box-scale S] [--table-entries N] [--jobs N] [--cost device]
                                  [--json docs/results/fit_benchmark.json] [--merge]

``--box-scale S`` fits every preset's workspace box scaled S times about its centre (each
range's half-width times S; an end the geometry refuses, such as r < 0 or theta past +-180 deg,
stays where it was); the preset is reported as ``NAME-xS`` (the dot an underscore).
``--table-entries N`` fits with ``fit.table_entries = N`` (from 64: cells of computed features),
reported beside the name.
With ``--jobs N`` each preset is fitted a second time with its servos in N processes
(``fit_robot(jobs=N)``): its wall time beside the one-process fit's, and the two plans compared
byte for byte (the run fails if they differ).
``--cost device`` fits one-leg presets with ``hardware.architecture = "pipelined"`` and
``hardware.cost = "device"`` (:class:`ikseries.fit.cost.DeviceCost` of the preset's
``hardware.dsp`` family's reference part), reported as ``NAME (cost device)``; the rows then
also carry the plan's usage of that part. Every fit minimises the robot's cost model
(:func:`ikseries.architecture.cost_model`).
``--merge`` keeps the rows of the ``--json`` file for every preset (as reported, box scale and
table entries included) this run does not fit, before this run's, with the runs they come from:
e.g. the enlarged cylinder-leg box recorded beside every preset's default box.

Targets for cylinder-leg at +-0.5 pu: <= 100 multiply-adds per servo, certified (issue 3); fit
plus certification <= 10 s CPU on one core ("a fit ten times faster").
"""
from __future__ import annotations

from ikseries.memory import keep_freed_memory
from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS
keep_freed_memory()      # as the ikseries command does: freed arrays reused, not fresh pages

import argparse
import contextlib
import tomllib
import runpy
import sys
import time
from pathlib import Path

import ikseries.fit.fitter as fitter
from ikseries.accuracy import measure
from ikseries.fit.fitter import FitError, fit_robot, output_multipliers
from ikseries.architecture import cost_model
from ikseries.fit.cost import COSTS, DEFAULT_COST_MODEL
from ikseries.robot import RobotError, load_preset, parse_robot, preset_names, preset_text, with_fit, with_hardware
from ikseries.robot_parts import TABLE_ENTRIES, FitOptions

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


@contextlib.contextmanager
def certify_seconds():
    """A list that receives the CPU seconds of every certification the fitter runs meanwhile."""
    seconds, certify = [], fitter.certify

    def timed(*args, **kwargs):
        c0 = time.process_time()
        try:
            return certify(*args, **kwargs)
        finally:
            seconds.append(time.process_time() - c0)
    fitter.certify = timed
    try:
        yield seconds
    finally:
        fitter.certify = certify


def scaled_robot(name: str, scale: float):
    """Preset ``name`` with its workspace box scaled ``scale`` times about its centre (an end
    the geometry refuses stays put)."""
    if not scale > 0:
        raise ValueError(f"box scale must be > 0, not {scale!r}")
    robot, data = load_preset(name), tomllib.loads(preset_text(name))
    for spec in robot.workspace.inputs:
        mid, half = (spec.min + spec.max) / 2, (spec.max - spec.min) / 2 * scale
        lo, hi = mid - half, mid + half
        if robot.geometry.workspace_error(spec.name, lo, spec.max):
            lo = spec.min
        if robot.geometry.workspace_error(spec.name, spec.min, hi):
            hi = spec.max
        data["workspace"][spec.name].update(min=lo, max=hi)
    data["name"] = f"{name}-x{scale:g}".replace(".", "_")
    return parse_robot(data, f"preset {name} scaled {scale:g}")


def bench_preset(name: str, scale: float = 1.0, jobs: int = 1, table_entries: int = TABLE_ENTRIES,
                 cost: str = COSTS[0]) -> dict:
    robot = load_preset(name) if scale == 1.0 else scaled_robot(name, scale)
    name = robot.name
    if table_entries != TABLE_ENTRIES:
        robot = with_fit(robot, table_entries=table_entries)
        name += f" (table_entries {table_entries})"
    if cost != COSTS[0]:
        if robot.legs != 1:
            return {"preset": name, "error": f"--cost {cost} needs a one-leg preset (a pipelined core), not {robot.legs} legs"}
        robot = with_hardware(robot, architecture="pipelined", cost=cost)
        name += f" (cost {cost})"
    model = cost_model(robot)
    t0, c0 = time.perf_counter(), time.process_time()
    with certify_seconds() as cert_cpu:
        try:
            plan, fits = fit_robot(robot, cost_model=model)
        except FitError as e:
            return {"preset": name, "error": str(e)}
    fit_s, fit_cpu = time.perf_counter() - t0, time.process_time() - c0
    cert = {c["name"]: c for c in plan.meta["certificate"]["servos"]}
    acc = measure(robot, plan)
    mults = output_multipliers(plan)
    servos = []
    for sf in fits:
        coef_bits = sf.coefficient_bits()
        cs = cert[sf.name]
        servos.append({"servo": sf.name, "variables": sf.features.structure(),
                       "names": list(sf.features.names),
                       "degree": sf.degree, "terms": len(sf.poly), "multiplications": mults[sf.name],
                       "coefficient_bits": coef_bits, "coefficient_frac_bits": sf.frac,
                       "sampled_max_pu": acc["servos"][sf.name]["total"],
                       "certified_max_pu": cs["total_pu"], "certified": cs["converged"]})
    rec = {"preset": name, "tolerance_pu": robot.fit.tolerance_pu, "fit_s": fit_s, "fit_cpu_s": fit_cpu,
           "certify_cpu_s": sum(cert_cpu), "certifications": len(cert_cpu),
           "points": acc["points"], "plan_multipliers": plan.count("mul"),
           "servos": servos}
    if model != DEFAULT_COST_MODEL:
        rec["cost_model"] = model.record()
        rec["usage"] = vars(model.usage(plan))
    if jobs > 1:
        t0 = time.perf_counter()
        again = fit_robot(robot, cost_model=model, jobs=jobs).plan
        rec["parallel"] = {"jobs": jobs, "fit_s": time.perf_counter() - t0}
        if again.dumps() != plan.dumps():
            raise SystemExit(f"{name}: the plan fitted with jobs={jobs} differs from the one-process plan")
    return rec


def table(results: list) -> str:
    head = ("preset", "servo", "vars", "deg", "terms", "mults", "coef bits", "sampled pu", "certified pu",
            "fit s (cpu; certify cpu)")
    rows = [head]
    for r in results:
        if "error" in r:
            rows.append((r["preset"], "-", "fit refused: " + r["error"], *[""] * 7))
            continue
        for s in r["servos"]:
            rows.append((r["preset"], s["servo"], s["variables"], s["degree"], s["terms"], s["multiplications"],
                         s["coefficient_bits"], f"{s['sampled_max_pu']:.3f}",
                         f"{s['certified_max_pu']:.3f}" + ("" if s["certified"] else " (budget spent)"),
                         f"{r['fit_s']:.1f} ({r['fit_cpu_s']:.1f}; {r['certify_cpu_s']:.1f})"
                         + (f"; {r['parallel']['fit_s']:.1f} with {r['parallel']['jobs']} jobs" if "parallel" in r else "")))
    w = [max(len(str(row[i])) for row in rows) for i in range(len(head))]
    return "\n".join("  ".join(str(c).ljust(w[i]) for i, c in enumerate(row)) for row in rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("presets", nargs="*", help=f"default: all ({', '.join(preset_names())})")
    ap.add_argument("--box-scale", type=float, default=1.0, help="scale every workspace box about its centre")
    ap.add_argument("--table-entries", type=int, default=TABLE_ENTRIES,
                    help="fit.table_entries of every fit (from 64: cells of computed features)")
    ap.add_argument("--jobs", type=int, default=1, help="also fit each preset with its servos in N processes")
    ap.add_argument("--json", default=FACTS["default_json"]("fit_benchmark"))
    ap.add_argument("--cost", default=COSTS[0], choices=COSTS,
                    help="what one-leg presets are fitted to minimise (device: pipelined, hardware.cost = device)")
    ap.add_argument("--merge", action="store_true",
                    help="keep the --json file's rows of the presets this run does not fit")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        sys.exit(f"--jobs must be a positive integer, not {args.jobs}")
    run = FACTS["run_facts"]("fit_benchmark", argv)
    names = args.presets or preset_names()
    bad = [n for n in names if n not in preset_names()]
    if bad:
        sys.exit(f"preset must be one of {preset_names()}, not {bad[0]!r}")
    try:                                 # the description's own rule and message
        FitOptions(table_entries=args.table_entries).validate()
    except RobotError as e:
        sys.exit(str(e))
    if not args.box_scale > 0:
        sys.exit(f"--box-scale must be > 0, not {args.box_scale!r}")
    results = []
    for n in names:
        print(f"fitting {n} ...", flush=True)
        results.append(bench_preset(n, args.box_scale, args.jobs, args.table_entries, args.cost))
    earlier = FACTS["merge_rows"](args.json, results, "preset") if args.merge else []
    print(table(results))
    out = FACTS["write_result"](args.json, {"results": results, **({"earlier_runs": earlier} if earlier else {})},
                                run)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
