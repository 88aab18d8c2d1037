"""Side-by-side figures of two evaluation plans of the same robot (e.g. ikseries vs the paper).

Per servo: terms, multiplications in the output's cone (split into the part shared with
other servos, such as ikseries' coordinate stage, and the servo's own), coefficient
constants and their bits, the sampled max error and the certified rounding bound.
"""
from __future__ import annotations

from ...accuracy import measure
from ..plan import Plan

__all__ = ["compare", "plan_figures", "render_comparison"]


def _shared_nodes(plan: Plan) -> set[int]:
    """Nodes in the cone of more than one output."""
    seen: dict[int, int] = {}
    for o in plan.outputs:
        for i in plan.cone(o.preround):
            seen[i] = seen.get(i, 0) + 1
    return {i for i, n in seen.items() if n > 1}


def _servo_terms(plan: Plan, name: str):
    for s in plan.meta.get("servos", []):
        if s.get("name") == name:
            return len(s.get("coefficients", ())) or s.get("terms")
    return None


def plan_figures(robot, plan: Plan, points: dict | None = None) -> dict:
    """Per-servo structure, cost and accuracy figures of ``plan`` (errors in pu).

    ``points`` are port integers (default :func:`ikseries.accuracy.verification_points`).
    """
    acc = measure(robot, plan, points)
    bounds = plan.rounding_bounds()
    shared = _shared_nodes(plan)
    cert = {c["name"]: c for c in plan.meta.get("certificate", {}).get("servos", [])}
    out = {}
    for o in plan.outputs:
        cone = plan.cone(o.preround)
        muls = [i for i in cone if plan.nodes[i].op == "mul"]
        consts = [plan.nodes[i] for i in cone - shared if plan.nodes[i].op == "const"]
        tables = [plan.nodes[i] for i in cone - shared if plan.nodes[i].op == "lut"]
        e = acc["servos"][o.name]
        out[o.name] = {
            "terms": _servo_terms(plan, o.name),
            "multiplications": len(muls),
            "shared_multiplications": sum(1 for i in muls if i in shared),
            "own_multiplications": sum(1 for i in muls if i not in shared),
            "coefficients": len(consts) + sum(len(n.param) for n in tables),
            "coefficient_bits_total": sum(n.width for n in consts) + sum(n.width * len(n.param) for n in tables),
            "coefficient_bits_max": max((n.width for n in consts + tables), default=0),
            "table_cells": max((len(n.param) for n in tables), default=1),
            "accumulator_frac_bits": plan.nodes[o.preround].frac,
            "max_error_pu": e["total"],
            "approximation_pu": e["approximation"],
            "quantization_pu": e["quantization"],
            "worst_at": e["at"],
            "certified_rounding_pu": bounds[o.preround] / o.ticks_per_pu,
            "certified_total_pu": cert[o.name]["total_pu"] if o.name in cert else None,
            "certified_converged": cert[o.name]["converged"] if o.name in cert else None,
        }
    return {"points": acc["points"], "servos": out,
            "plan": {"nodes": len(plan.nodes), "multiplications": plan.count("mul"),
                     "adders": plan.count("add"), "latency_cycles": plan.depth,
                     "max_width": max(n.width for n in plan.nodes)}}


def compare(robot, ikseries_plan: Plan, paper_plan: Plan, points: dict | None = None) -> dict:
    """Figures of both plans on the same points, with the robot's tolerance."""
    names = [o.name for o in ikseries_plan.outputs]
    other = [o.name for o in paper_plan.outputs]
    if names != other:
        raise ValueError(f"plans must have the same servos, not {names!r} and {other!r}")
    return {"robot": robot.name, "tolerance_pu": robot.fit.tolerance_pu,
            "methods": {"ikseries": plan_figures(robot, ikseries_plan, points),
                        "paper": plan_figures(robot, paper_plan, points)}}


_HEADER = ("terms", "multiplications (shared + own)", "coefficients", "coefficient bits (total / max)",
           "max error (pu)", "approximation (pu)", "certified rounding bound (pu)",
           "certified max error (pu)")


def _cells(f: dict) -> list[str]:
    """One table row's figures, in :data:`_HEADER` order."""
    return [str(f["terms"]),
            f"{f['multiplications']} ({f['shared_multiplications']} + {f['own_multiplications']})",
            str(f["coefficients"]), f"{f['coefficient_bits_total']} / {f['coefficient_bits_max']}",
            f"{f['max_error_pu']:.4f}", f"{f['approximation_pu']:.4f}", f"{f['certified_rounding_pu']:.4f}",
            _certified(f)]


def _certified(f: dict) -> str:
    if f.get("certified_total_pu") is None:
        return "not run"
    if not f.get("certified_converged"):
        return f"≤ {f['certified_total_pu']:.4g} (cell budget spent before the bound got tight)"
    return f"{f['certified_total_pu']:.4f}"


def render_comparison(result: dict) -> str:
    """Markdown table of :func:`compare`'s result."""
    tol = result["tolerance_pu"]
    lines = [f"# {result['robot']}: ikseries vs the integer power series paper", "",
             (f"Tolerance ±{tol:g} pu. Errors are the max |emitted pulse - exact pulse| over the "
              "same sampled workspace points; multiplications count the servo's whole cone "
              "(shared with other servos + its own)."), "",
             "| servo | method | " + " | ".join(_HEADER) + " | meets tolerance |",
             "|" + "---|" * (len(_HEADER) + 3)]
    methods = result["methods"]
    for name in next(iter(methods.values()))["servos"]:
        for m, figs in methods.items():
            f = figs["servos"][name]
            ok = "yes" if f["max_error_pu"] <= tol else "**no**"
            lines.append(f"| {name} | {m} | " + " | ".join(_cells(f)) + f" | {ok} |")
    lines += ["", "| method | points | plan nodes | multiplications | adders | latency (cycles) | widest (bits) |",
              "|---|---|---|---|---|---|---|"]
    for m, figs in methods.items():
        p = figs["plan"]
        lines.append(f"| {m} | {figs['points']:,} | {p['nodes']} | {p['multiplications']} | {p['adders']} | "
                     f"{p['latency_cycles']} | {p['max_width']} |")
    return "\n".join(lines) + "\n"
