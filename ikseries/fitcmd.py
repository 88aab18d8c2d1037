"""``ikseries fit``: fit a robot by one method and report the fit alone (no hardware).

Methods
-------
``ikseries``             the automatic fit (the one ``ikseries build`` uses): plan.json + fit.md/json
``paper``                the integer power series paper's procedure beside the automatic fit, on
                         the same points: paper_plan.json, plan.json, comparison.md/json
``divided-differences``  path mode for the planar arm: Newton cubics through 4 poses on each
                         straight tool path, checked by forward kinematics: divided.md/json
"""
from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

from .accuracy import measure
from .buildrecord import OutputDirError, check_output_dir, remove_created
from .fit.fitter import FitError, fit_robot, output_multipliers
from .robot import robot_record

__all__ = ["METHODS", "FitCommandError", "run_fit", "default_fit_dir"]

METHODS = ("ikseries", "paper", "divided-differences")
PAPER_CERT_CELLS = 100_000   # cell budget per servo when certifying the paper's plan


class FitCommandError(RuntimeError):
    """The method cannot run on this robot, or its fit is refused."""


def default_fit_dir(robot, method: str) -> Path:
    return Path("build") / robot.name / f"fit-{method}"


def _dump(obj) -> str:
    return json.dumps(obj, indent=1, sort_keys=True) + "\n"


def _ikseries(robot, progress, jobs) -> tuple[dict, dict]:
    from .architecture import cost_model       # the plan records the robot: fitted as its build would be
    plan, fits = fit_robot(robot, progress, cost_model=cost_model(robot), jobs=jobs)
    plan.meta["robot_description"] = robot_record(robot)
    progress("measuring the error on >= 10^6 points")
    acc = measure(robot, plan)
    mults = output_multipliers(plan)
    cert = {c["name"]: c for c in plan.meta.get("certificate", {}).get("servos", [])}
    rows = [{"servo": sf.name, "variables": sf.features.structure(),
             "names": list(sf.features.names),
             "degree": sf.degree, "terms": len(sf.poly), "multiplications": mults[sf.name],
             "coefficient_frac_bits": sf.frac, "sampled_max_pu": acc["servos"][sf.name]["total"],
             "certified_rounding_pu": sf.bound_pu, "certified_total_pu": cert[sf.name]["total_pu"]}
            for sf in fits]
    rec = {"robot": robot.name, "method": "ikseries", "tolerance_pu": robot.fit.tolerance_pu,
           "points": acc["points"], "servos": rows}
    md = [f"# {robot.name}: ikseries fit", "", f"Tolerance ±{robot.fit.tolerance_pu:g} pu; sampled on "
          f"{acc['points']:,} representable points.", "",
          "| servo | variables | degree | terms | multiplications | coefficient frac bits | "
          "sampled max (pu) | certified rounding (pu) | certified total (pu) |",
          "|---|---|---|---|---|---|---|---|---|"]
    md += [f"| {r['servo']} | {r['variables']} ({', '.join(r['names'])}) | {r['degree']} | {r['terms']} | "
           f"{r['multiplications']} | {r['coefficient_frac_bits']} | {r['sampled_max_pu']:.4f} | "
           f"{r['certified_rounding_pu']:.4f} | {r['certified_total_pu']:.4f} |" for r in rows]
    return {"plan.json": plan.dumps(), "fit.json": _dump(rec), "fit.md": "\n".join(md) + "\n"}, rec


def _paper(robot, progress, jobs) -> tuple[dict, dict]:
    from .accuracy import verification_points
    from .fit.certify import certify
    from .fit.baselines.comparison import compare, render_comparison
    from .fit.baselines.paper import fit_paper, paper_plan
    try:
        pfit = fit_paper(robot)
    except ValueError as e:
        raise FitCommandError(f"--method paper: {e}") from None
    pplan = paper_plan(robot, pfit, progress)
    progress("certifying the paper plan's error over the continuous workspace")
    pts = verification_points(robot)
    sampled = measure(robot, pplan, pts)["servos"]
    # refine each servo to just above its sampled error: the bound is then close to the truth
    cert = certify(robot, pplan, target_pu=1.05 * max(e["approximation"] for e in sampled.values()),
                   max_cells=PAPER_CERT_CELLS, jobs=jobs)
    for line in cert.lines():
        progress("  " + line)
    rec = cert.to_json()
    for c in rec["servos"]:
        c.pop("seconds", None)
    pplan.meta["certificate"] = rec
    progress("fitting the same robot with ikseries")
    plan, _ = fit_robot(robot, progress, jobs=jobs)
    progress("measuring both on the same >= 10^6 points")
    res = compare(robot, plan, pplan, pts)
    return {"paper_plan.json": pplan.dumps(), "plan.json": plan.dumps(), "comparison.json": _dump(res),
            "comparison.md": render_comparison(res)}, res


def _divided(robot, progress, jobs) -> tuple[dict, dict]:   # one path at a time: jobs unused
    from .fit.baselines.divided import render_markdown, run_divided_differences
    from .planar_arm import PlanarArm
    if not isinstance(robot.geometry, PlanarArm):
        raise FitCommandError(f"--method divided-differences needs a planar-arm robot, not {robot.name!r} "
                              f"(geometry {type(robot.geometry).__name__})")
    progress("divided differences on the three tool paths")
    res = run_divided_differences(robot.geometry, pu_per_degree=robot.calibration.pu_per_degree,
                                  tolerance_pu=robot.fit.tolerance_pu)
    return {"divided.json": _dump(res), "divided.md": render_markdown(res)}, res


def run_fit(robot, method: str, out_dir, progress=print, jobs: int = 1) -> dict:
    """Fit ``robot`` by ``method`` and write its artifacts into ``out_dir`` (all or nothing);
    ``jobs``: processes for the servos of an ikseries fit (:func:`~ikseries.fit.fitter.fit_robot`)."""
    if method not in METHODS:
        raise FitCommandError(f"method must be one of {list(METHODS)}, not {method!r}")
    run = {"ikseries": _ikseries, "paper": _paper, "divided-differences": _divided}[method]
    out_dir = Path(out_dir)
    try:
        created = check_output_dir(out_dir)     # before the fit, which takes minutes
    except OutputDirError as e:
        raise FitCommandError(str(e)) from None
    try:
        files, rec = run(robot, progress, jobs)
    except FitError as e:
        raise FitCommandError(str(e)) from None
    done = False
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".ikseries-tmp-", dir=out_dir))
        try:
            for name, text in files.items():
                (tmp / name).write_text(text)
            for name in files:
                shutil.move(tmp / name, out_dir / name)
            done = True
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError as e:
        raise FitCommandError(f"cannot write the fit output to {str(out_dir)!r}: {e}") from None
    finally:
        if not done:
            remove_created(out_dir, created)
    progress(f"wrote {out_dir}/: " + ", ".join(sorted(files)))
    return rec
