"""Benchmark: the hexapod leg fitted and certified as its closed form and as a generic chain.

The same leg, described twice: the ``hexapod-leg`` preset (IK as formulas,
``ikseries/hexapod_leg.py``) and the same preset with its geometry replaced by the serial chain
``HEXAPOD_CHAIN`` of ``tests/test_chain.py`` (continued Newton IK, its certifier enclosure a
Krawczyk step per cell, ``ikseries/chain/``). Both are fitted by ``fit_robot`` in one run, one
after the other; per robot the CPU seconds (``time.process_time``) of the whole fit and of the
certification inside it (``fit.fitter.certify`` wrapped by a timer, so the certifier runs once,
as in any fit), the cells the certifier evaluated and the certified bounds. Then the real robots'
presets (:data:`ROBOT_PRESETS`), each against the same closed-form leg. The issue's target: the
chain, and every robot, within 2x of the closed form.

``fit_robot`` reads no plan cache (only ``ikseries eval`` does, ``ikseries/plancache.py``);
the run points ``XDG_CACHE_HOME`` at an empty temporary directory all the same, and checks
that it is still empty afterwards, so no plan can come from an earlier run.

    python bench/chain_fit.py [--json docs/results/chain_fit.json] [--presets phoenix,spotmicro,...]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import hashlib
import os
import runpy
import tempfile
import time
from pathlib import Path

import ikseries.fit.fitter as fitter
from ikseries.chain import Chain
from ikseries.plancache import cache_dir
from ikseries.robot import load_preset, parse_robot

HERE = Path(__file__).resolve().parent
FACTS = runpy.run_path(str(HERE / "facts.py"))   # run record, JSON writer
#: the chain description of the leg and the preset data it replaces the geometry of
CHAIN_TESTS = runpy.run_path(str(HERE.parent / "tests" / "test_chain.py"))


#: the real robots' presets, each a 3-input leg (or arm) like the hexapod leg: the issue asks
#: each one's fit time within 2x of a closed-form leg of the same size
ROBOT_PRESETS = ("phoenix", "phantomx", "freenove-hexapod", "spotmicro", "mearm")


def robots(presets=ROBOT_PRESETS) -> dict:
    """The two descriptions of the hexapod leg, then the robot presets, by label."""
    data = CHAIN_TESTS["_robot_data"]("hexapod-leg", CHAIN_TESTS["HEXAPOD_CHAIN"])
    out = {"closed form": load_preset("hexapod-leg"), "chain": parse_robot(data)}
    for name in presets:
        r = load_preset(name)
        kind = "chain" if isinstance(r.geometry, Chain) else "closed form"
        legs = f", {r.legs} legs" if r.legs > 1 else ""
        out[f"{name} ({kind}{legs}, {len(r.servos)} servos, fitted to {r.fitted.fit.tolerance_pu:.4g} pu)"] = r
    return out


def timed_fit(robot) -> dict:
    """Fit ``robot`` (certified), with the CPU seconds of the fit and of its certifications."""
    spent, calls = [0.0], [0]
    certify = fitter.certify

    def timed_certify(*args, **kwargs):
        c0 = time.process_time()
        try:
            return certify(*args, **kwargs)
        finally:
            spent[0] += time.process_time() - c0
            calls[0] += 1
    fitter.certify = timed_certify
    try:
        c0 = time.process_time()
        plan = fitter.fit_robot(robot).plan
        fit_cpu = time.process_time() - c0
    finally:
        fitter.certify = certify
    servos = [{"servo": s["name"], "certified_total_pu": s["total_pu"], "converged": s["converged"],
               "cells": s["cells"], "evaluated": s["evaluated"]} for s in plan.meta["certificate"]["servos"]]
    return {"fit_cpu_s": fit_cpu, "certify_cpu_s": spent[0], "certifications": calls[0],
            "plan_multipliers": plan.count("mul"), "plan_sha256": hashlib.sha256(plan.dumps().encode()).hexdigest(),
            "servos": servos}


def table(results: list) -> str:
    head = ("robot", "fit CPU s", "certify CPU s", "rest CPU s", "x closed form", "mults", "cells evaluated",
            "certified pu")
    base = results[0]["fit_cpu_s"]
    rows = [head]
    for r in results:
        rows.append((r["robot"], f"{r['fit_cpu_s']:.1f}", f"{r['certify_cpu_s']:.1f}",
                     f"{r['fit_cpu_s'] - r['certify_cpu_s']:.1f}", f"{r['fit_cpu_s'] / base:.2f}",
                     r["plan_multipliers"], " / ".join(f"{s['evaluated']:,}" for s in r["servos"]),
                     " / ".join(f"{s['certified_total_pu']:.4f}" for s in r["servos"])))
    w = [max(len(str(row[i])) for row in rows) for i in range(len(head))]
    return "\n".join("  ".join(str(c).ljust(w[i]) for i, c in enumerate(row)) for row in rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default=FACTS["default_json"]("chain_fit"))
    ap.add_argument("--presets", default=",".join(ROBOT_PRESETS),
                    help="robot presets fitted after the two hexapod legs (comma list; empty: none)")
    args = ap.parse_args(argv)
    presets = tuple(p for p in args.presets.split(",") if p)
    run = FACTS["run_facts"]("chain_fit", argv)
    results = []
    with tempfile.TemporaryDirectory() as cache:
        old = os.environ.get("XDG_CACHE_HOME")
        os.environ["XDG_CACHE_HOME"] = cache
        try:
            for label, robot in robots(presets).items():
                print(f"fitting {label} ...", flush=True)
                results.append({"robot": label, **timed_fit(robot)})
            stored = list(cache_dir().glob("*")) if cache_dir().exists() else []
        finally:
            if old is None:
                os.environ.pop("XDG_CACHE_HOME")
            else:
                os.environ["XDG_CACHE_HOME"] = old
    if stored:
        raise SystemExit(f"the fits must not touch the plan cache, not leave {stored}")
    print(table(results))
    ratio = results[1]["fit_cpu_s"] / results[0]["fit_cpu_s"]
    print(f"chain / closed form: {ratio:.2f}x CPU (target <= 2x)")
    out = FACTS["write_result"](args.json, {"preset": "hexapod-leg", "results": results, "ratio": ratio,
                                            "target_ratio": 2.0}, run)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
