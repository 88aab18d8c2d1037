"""Benchmark: pipeline latency of the servo polynomials lowered by Horner vs the Horner/Estrin mix.

Fits the preset once (the fits are not changed; the fitter itself lowers as ``fit.lowering``
says, by default the mix with at most ``MIX_EXTRA_MULTIPLIERS`` = 2 extra multipliers per
servo, "mix+2" below), then rebuilds the plan from the same fits
and formats with each lowering and reports the plan latency, the multipliers (plan total
and per servo, coordinate stage included) and, per servo, the certified rounding bound
(pu) with its ratio to Horner's and the split chosen.

Schemes: ``horner`` (as the fitter lowers), ``mix`` (per servo the split of least depth,
then fewest multipliers: :func:`ikseries.fit.horner.lower_poly`), ``mix+N`` (at most N
multipliers more than Horner per servo polynomial) and ``mix guard G`` (the powers of the
variables kept with G more fractional bits).

    python bench/lowering_latency.py [PRESET] [--extra N ...] [--guard G ...] [--json docs/results/lowering_latency.json]

Rebuilding a plan from fits uses the fitter internals ``_Nodes`` (the feature nodes) and the
coordinate stage as ``fit_robot`` configures it.
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import runpy
import time
from pathlib import Path

from ikseries.fit import fitter
from ikseries.fit.context import FitContext
from ikseries.fit.fitter import QUANTIZATION_SHARES
from ikseries.fit.lowering import MIX_EXTRA_MULTIPLIERS, FeatureNodes, output_multipliers, parity_variable, poly_inputs
from ikseries.fit.horner import choose_split, estrin, poly_degrees
from ikseries.fit.plan import PlanBuilder, PlanOutput
from ikseries.robot import load_preset

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def rebuild(robot, plan, fits, extra: int | None, horner: bool = False, guard: int = 0):
    """The plan of ``fits`` (formats as fitted) with Horner or the mix; also the splits."""
    ctx = FitContext.for_robot(robot, QUANTIZATION_SHARES[0])   # the ports and stage of fit_robot
    fv = plan.meta["features"]["frac_bits"]
    b = PlanBuilder(list(ctx.inputs))
    nodes = FeatureNodes(ctx, b, fv)
    limits = robot.pulse_limits_ticks()
    outs, splits = [], {}
    for sf in fits:
        feats, coefficient = poly_inputs(b, sf.features, nodes[sf.features.kind], fv)
        k = parity_variable(sf.features)

        def lower(split, sf=sf, feats=feats, k=k, coefficient=coefficient):
            return estrin(b, sf.poly, feats, sf.frac, coefficient, split=split, parity=k, guard=guard)
        split = None if horner else choose_split(b, lower, poly_degrees(sf.poly, k), extra)[0]
        splits[sf.name] = split
        acc = lower(split)
        out = b.clamp(b.round(acc, 0), *limits[sf.name])
        outs.append(PlanOutput(sf.name, out, acc, "ticks", robot.ticks_per_pu))
    return b.build(outs), splits


def measure(robot, plan, fits, extras, guards=()) -> dict:
    schemes = {"horner": rebuild(robot, plan, fits, None, horner=True)}
    for e in extras:
        schemes["mix" if e is None else f"mix+{e}"] = rebuild(robot, plan, fits, e)
    for g in guards:
        schemes[f"mix guard {g}"] = rebuild(robot, plan, fits, None, guard=g)
    ref = schemes["horner"][0].rounding_bounds()
    href = {o.name: ref[o.preround] for o in schemes["horner"][0].outputs}
    out = {}
    for name, (p, splits) in schemes.items():
        bounds, st, mults = p.rounding_bounds(), p.stages(), output_multipliers(p)
        out[name] = {"latency": p.depth, "multipliers": p.count("mul"), "servos": [
            {"servo": o.name, "split": splits[o.name], "stage": st[o.node], "multipliers": mults[o.name],
             "rounding_bound_pu": bounds[o.preround] / robot.ticks_per_pu,
             "bound_vs_horner": bounds[o.preround] / href[o.name]} for o in p.outputs]}
    return out


def table(res: dict) -> str:
    rows = [("scheme", "latency", "mults", "servo", "split", "out stage", "servo mults", "bound pu", "x horner")]
    for name, r in res.items():
        for s in r["servos"]:
            rows.append((name, r["latency"], r["multipliers"], s["servo"], str(s["split"]), s["stage"],
                         s["multipliers"], f"{s['rounding_bound_pu']:.4f}", f"{s['bound_vs_horner']:.3f}"))
    w = [max(len(str(row[i])) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(str(c).ljust(w[i]) for i, c in enumerate(row)) for row in rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("preset", nargs="?", default="cylinder-leg")
    ap.add_argument("--extra", type=int, nargs="*", default=[0, 2],
                    help="multiplier allowances per servo polynomial to report besides the unlimited mix")
    ap.add_argument("--guard", type=int, nargs="*", default=[4],
                    help="extra fractional bits of the powers of the variables to report for the mix")
    ap.add_argument("--json", default=FACTS["default_json"]("lowering_latency"))
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("lowering_latency", argv)
    robot = load_preset(args.preset)
    t0 = time.perf_counter()
    plan, fits = fitter.fit_robot(robot)
    print(f"fitted {args.preset} in {time.perf_counter() - t0:.1f} s: latency {plan.depth}, "
          f"{plan.count('mul')} multipliers")
    t0 = time.perf_counter()
    res = measure(robot, plan, fits, [None, *args.extra], args.guard)
    fitted = "horner" if robot.fit.lowering == "horner" else f"mix+{MIX_EXTRA_MULTIPLIERS}"
    if fitted in res and (res[fitted]["latency"], res[fitted]["multipliers"]) != (plan.depth, plan.count("mul")):
        raise SystemExit(f"the {fitted} rebuild does not reproduce the fitted plan")
    print(table(res))
    print(f"lowered and measured in {time.perf_counter() - t0:.1f} s")
    out = FACTS["write_result"](args.json, {"preset": args.preset, "schemes": res}, run)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
