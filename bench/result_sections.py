"""Markdown sections of ``docs/results.md``, one renderer per bench script's JSON.

Each renderer takes the JSON a bench wrote (``docs/results/<bench>.json``) and returns the
section's body lines: figures only as the JSON holds them, formatted the same way every time.
:data:`SECTIONS` maps a bench name to its title, a one-line description and its renderer;
``bench/results.py`` assembles the document.
"""
from __future__ import annotations

from ikseries.fit.baselines.comparison import render_comparison
from ikseries.fit.baselines.divided import render_markdown as render_divided


def table(head, rows) -> list[str]:
    """A Markdown table of ``rows`` (sequences of cells) under ``head``."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return lines + [""]


def num(v, spec: str = ".3f", none: str = "–") -> str:
    """``v`` formatted by ``spec``, or ``none`` when it is missing."""
    return none if v is None else format(v, spec)


def demote(markdown: str, levels: int = 1) -> list[str]:
    """``markdown``'s lines with every heading ``levels`` deeper (to sit inside a section), and a
    blank line after them."""
    return [("#" * levels + line) if line.startswith("#") else line for line in markdown.splitlines()] + [""]


def _fit_seconds(r: dict) -> str:
    """Wall and CPU seconds of a preset's fit, with those of its certifications when recorded."""
    cert = f"; {r['certify_cpu_s']:.1f}" if "certify_cpu_s" in r else ""
    par = f"; {r['parallel']['fit_s']:.1f} s with {r['parallel']['jobs']} jobs" if "parallel" in r else ""
    return f"{r['fit_s']:.1f} ({r['fit_cpu_s']:.1f}{cert}){par}"


def fit_benchmark(res: dict) -> list[str]:
    """Lines of the ``bench/fit_benchmark.py`` section from its JSON ``res``."""
    rows, notes = [], []
    for r in res["results"]:
        if "error" in r:
            notes.append(f"- {r['preset']}: fit refused: {r['error']}")
            continue
        for k, s in enumerate(r["servos"]):
            certified = num(s["certified_max_pu"]) + ("" if s["certified"] else " (cell budget spent)")
            rows.append((r["preset"] if k == 0 else "", s["servo"], s["variables"], s["degree"], s["terms"],
                         s["multiplications"], s["coefficient_bits"], num(s["sampled_max_pu"]), certified,
                         _fit_seconds(r) if k == 0 else ""))
        notes.append(f"- {r['preset']}: tolerance ±{r['tolerance_pu']:g} pu, sampled on {r['points']:,} points, "
                     f"{r['plan_multipliers']} multipliers in the whole plan")
    head = ("preset", "servo", "variables", "degree", "terms", "mults", "coefficient bits", "sampled (pu)",
            "certified (pu)", "fit + certify, wall s (CPU s; certify CPU s; wall s with N jobs)")
    return ["*mults*: multiplications per evaluation of the servo, its share of the coordinate stage "
            "included. *sampled*: max |emitted − exact pulse| on the sampled points; *certified*: the "
            "proven bound over the continuous workspace box.", "", *table(head, rows), *notes, ""]


def lowering_latency(res: dict) -> list[str]:
    """Lines of the ``bench/lowering_latency.py`` section from its JSON ``res``."""
    rows = []
    for name, r in res["schemes"].items():
        for k, s in enumerate(r["servos"]):
            rows.append((name if k == 0 else "", r["latency"] if k == 0 else "", r["multipliers"] if k == 0 else "",
                         s["servo"], s["split"], s["stage"], s["multipliers"], num(s["rounding_bound_pu"], ".4f"),
                         num(s["bound_vs_horner"])))
    head = ("scheme", "plan latency (stages)", "plan mults", "servo", "split", "output stage", "servo mults",
            "rounding bound (pu)", "bound ÷ Horner's")
    return [f"Preset `{res['preset']}`, the same fits lowered by each scheme. *mix+N*: at most N "
            "multiplications more than Horner per servo polynomial; *mix guard G*: the powers of the "
            "variables kept with G more fractional bits.", "", *table(head, rows)]


def certify_bound(res: dict) -> list[str]:
    """Lines of the ``bench/certify_bound.py`` section from its JSON ``res``."""
    rows = []
    for s in res["servos"]:
        c = s["certified"]
        rows.append((s["servo"], num(s["sampled_approximation_pu"], ".4f"), num(c["approximation_pu"], ".4f"),
                     num(s["sampled_total_pu"], ".4f"), num(c["total_pu"], ".4f"), num(c["rounding_pu"], ".4f"),
                     num(c["output_rounding_pu"], ".4f"), f"{c['cells']:,}", "yes" if c["converged"] else "no",
                     num(c["seconds"], ".1f")))
    head = ("servo", "sampled approx. (pu)", "certified approx. (pu)", "sampled total (pu)",
            "certified total (pu)", "certified quantization (pu)", "output rounding (pu)", "cells",
            "converged", "certify s")
    return [f"Preset `{res['preset']}` ({res['nodes']} plan nodes), tolerance ±{res['tolerance_pu']:g} pu; "
            f"sampled on {res['points_sampled']:,} points in {res['seconds_sampled']:.1f} s, certified "
            f"(at most {res['max_cells']:,} cells per servo) in {res['seconds_certify']:.1f} s.", "",
            *table(head, rows), f"Verdict: {res['verdict']}.", ""]


def paper_baseline(res: dict) -> list[str]:
    """Lines of the ``bench/paper_baseline.py`` section from its JSON ``res``."""
    p = res["paper"]
    lines = demote(render_comparison(res))[1:]    # the section title replaces the heading
    for key, what in (("float_max_error_pu", "the paper's series in float64 (7 significant figures)"),
                      ("float_uncut_max_error_pu", "the same series with every digit (no cut to 7 significant figures)"),
                      ("circle_error_pu", "the paper's first step alone (θ series on the worst circle)")):
        lines.append(f"- {what}, max error (pu): " + ", ".join(f"{s} {e:.4f}" for s, e in p[key].items()))
    t = res["times_s"]
    lines += [f"- θ fit `{p['theta_fit']}`; fit times: ikseries {t['ikseries_fit_s']} s, paper "
              f"{t['paper_fit_s']} s; measuring both {t['measure_s']} s", ""]
    return lines


def divided_differences(res: dict) -> list[str]:
    """Lines of the ``bench/divided_differences.py`` section from its JSON ``res``."""
    return demote(render_divided(res))[1:] + [f"Preset `{res['preset']}`, {res['seconds']:.2f} s.", ""]


def folded_area(res: dict) -> list[str]:
    """Lines of the ``bench/folded_area.py`` section from its JSON ``res``."""
    rows, extra = [], []
    for r in res["rows"]:
        c = r["counts"]
        rows.append((r["design"], r["target"], c["LUT"], c["FF"], c["carry"], c["DSP"], c["BRAM"],
                     r.get("latency", "–"), r.get("initiation_interval", "–")))
        if "program" in r:
            p = r["program"]
            extra.append(f"- {r['design']}: {p['steps']} microcode steps of {p['microcode_bits'] // p['steps']} "
                         f"bits, {p['muls']} multiplications in limbs {p['limbs']}, store {p['store_width']} "
                         f"bits × {p['depth']}, {p['consts']} constants, accumulator {p['acc_width']} bits")
        if "refresh_hz_at" in r:
            extra.append(f"- {r['design']}: every leg refreshed " + ", ".join(
                f"{v:,.0f} times/s at {f}" for f, v in r["refresh_hz_at"].items()))
    head = ("design", "target", "LUT", "FF", "carry", "DSP", "BRAM", "latency (cycles)", "II (cycles)")
    return [f"The cylinder-leg plan ({res['plan_nodes']} nodes) on folded evaluators and the 6-leg shared "
            "core, with parts of the latter; Yosys cell counts.", "", *table(head, rows), *extra, ""]


def cordic_vs_poly(res: dict) -> list[str]:
    """Lines of the ``bench/cordic_vs_poly.py`` section from its JSON ``res``."""
    designs = res["designs"]
    names = list(designs)
    servos = list(next(iter(designs.values()))["max_error_pu"])
    rows = [("latency (cycles)", *(designs[n]["latency_cycles"] for n in names))]
    rows += [(f"max error {s} (pu)", *(num(designs[n]["max_error_pu"][s], ".4f") for n in names)) for s in servos]
    rows += [(f"max error {s}, fresh points (pu)",
              *(num(designs[n].get("max_error_pu_fresh_points", {}).get(s), ".4f") for n in names)) for s in servos]
    rows.append(("register bits", *(designs[n].get("register_bits", "–") for n in names)))
    targets = list(next(iter(designs.values())).get("synth", {}))
    for t in targets:
        for c in ("LUT", "FF", "carry", "DSP"):
            rows.append((f"{t} {c}", *(designs[n]["synth"][t]["counts"][c] for n in names)))
    lines = [f"Robot `{res['robot']}`, tolerance ±{res['tolerance_pu']:g} pu, errors on {res['points']:,} "
             "points (*fresh points*: a second, independent point set). Yosys cell counts per target.", "",
             *table(("", *names), rows)]
    for n in names:
        d = designs[n]
        if "design" in d:
            lines.append(f"- {n}: {d['sized']}; design {d['design']}")
    lines += [f"- note: {note}" for note in res["notes"]]
    return lines + [f"- whole run {res['seconds']:.1f} s", ""]


def point(at: dict | None) -> str:
    """An input point ``{name: value}`` as ``name = value, ...``."""
    return "–" if at is None else ", ".join(f"{k} = {v:g}" for k, v in at.items())


def exhaustive_accuracy(res: dict) -> list[str]:
    """Lines of the ``bench/exhaustive_accuracy.py`` section from its JSON ``res``."""
    rows = [(s, num(e["approximation"], ".4f"), num(e["quantization"], ".4f"), num(e["rounding"], ".4f"),
             num(e["total"], ".4f"), point(e["worst_at"])) for s, e in res["servos"].items()]
    head = ("servo", "approximation (pu)", "quantization (pu)", "output rounding (pu)", "total (pu)",
            "worst total at")
    grid = ("every representable value of each input" if res["stride"] == 1
            else f"every {res['stride']}th representable value of each input")
    return [f"Robot `{res['robot']}`: {res['points']:,} input points ({grid}), tolerance ±{res['tolerance_pu']:g} "
            f"pu, {res['seconds']:.1f} s.", "", *table(head, rows)]


def verilator_throughput(res: dict) -> list[str]:
    """Lines of the ``bench/verilator_throughput.py`` section from its JSON ``res``."""
    rows = []
    for name, p in res["passes"].items():
        rows.append((name.replace("_", " "), f"{p['outputs_checked']:,} / {p['targets']:,}", f"{p['cycles']:,}",
                     f"{p['targets_per_second']:,}", f"{p['cycles_per_second']:,}", p["mismatches"],
                     p["latency_errors"], f"{p['latency_cycles_min']}..{p['latency_cycles_max']}",
                     "yes" if p["passed"] else "**no**"))
    head = ("pass", "outputs checked / targets", "cycles", "targets/s", "cycles/s", "mismatches",
            "latency errors", "latency (cycles)", "passed")
    w = res["wall_seconds"]
    return [f"`{res['source']}`: {res['targets']:,} targets ({res['random_targets']:,} random, seed "
            f"{res['seed']}, and {res['corner_targets']:,} corners), latency {res['latency_cycles']} cycles, "
            f"a target every {res['initiation_interval']} cycles, model compiled with `{res['cxx_opt']}`. "
            "The rates are of the simulated hardware on this machine.", "", *table(head, rows),
            f"Wall time: Verilator build {w['verilator_build']:.1f} s, golden model {w['golden']:.1f} s.", ""]


def _pareto_row(r: dict) -> tuple:
    """One table row of a place-and-route record ``r``."""
    placed = r["status"] == "placed"
    if placed:
        seeds = r.get("fmax_by_seed") or {}
        status = num(r["fmax_mhz"], ".1f") + (" (" + " / ".join(num(v, ".1f") for v in seeds.values()) + ")"
                                              if len(seeds) > 1 else "")
    elif r["overflow"]:
        status = "does not fit: " + ", ".join(f"{k} {o['used']} of {o['available']}" for k, o in r["overflow"].items())
    else:
        status = f"{r['status']}: {r['error']}"
    latency = f"{r['latency_cycles']} / {num(r['latency_ns'], '.1f')}" if placed else f"{r['latency_cycles']} / –"
    rate = num(r["throughput_per_s"] / 1e6, ".3g") if placed and r["throughput_per_s"] else "–"
    return (r["design"], r["device"], status, num(r["LC"], "d"), num(r["LUT"], "d"), num(r["FF"], "d"),
            num(r["DSP"], "d"), num(r["BRAM"], "d"), latency, r["initiation_interval"], rate,
            num(r["max_error_pu"], ".3f"))


def pareto(res: dict) -> list[str]:
    """Lines of the ``bench/pareto.py`` section from its JSON ``res``."""
    head = ("core", "device", "Fmax (MHz; per seed)", "LC (nextpnr)", "LUT", "FF", "DSP", "BRAM", "latency (cycles / ns)",
            "II", "M solutions/s", "max error (pu)")
    seeds = res["seeds"] if "seeds" in res else [res["seed"]]
    lines = [f"Robot `{res['robot']}` (the hexapod row: the hexapod preset's shared core), nextpnr seed"
             f"{'s' * (len(seeds) > 1)} {', '.join(map(str, seeds))} (each row the median seed's), `--freq` "
             f"{res['clock_target_mhz']:g} MHz, Fmax of the register-to-register paths. "
             "LUT, FF, DSP and BRAM from Yosys (ECP5 LUT: LUT4 cells plus the two LUT4s of every CCU2C), LC "
             "the logic cells nextpnr placed; cores with more port bits than the package has pins run inside "
             "a serial timing harness, whose flip-flops the LC and FF counts include.", "",
             *table(head, [_pareto_row(r) for r in res["records"]])]
    described = {r["design"]: r["description"] for r in res["records"]}    # one line per core, any device
    lines += [f"- {name}: {what}" for name, what in described.items()]
    lines.append("")
    for device, plot in res["plots"].items():
        front = ", ".join(plot["pareto_front"]) or "–"
        lines += [f"Area (LUT + FF without the harness) against latency on {device}; Pareto front: {front}.", "",
                  f"![{device}](results/{plot['png'].rsplit('/', 1)[-1]})", ""]
    lines += ["Verdicts on the design targets, as the bench prints them:", "", "```"]
    for verdict in res["verdicts"].values():
        lines += verdict + [""]
    return lines + ["```", ""]


def link_fuzz(res: dict) -> list[str]:
    """Lines of the ``bench/link_fuzz.py`` section from its JSON ``res``."""
    f, s = res["fuzz"], res["shape"]
    lines = [f"Shape {s['legs']} legs × {s['coords']} coordinates, {s['channels']} channels; seed {res['seed']}, "
             f"chunks of {res['chunk']:,} bytes, a receive-timeout pause before about one byte in "
             f"{res['pause_every']}. Every good frame and every counter of the simulated "
             "`FrameReceiver` compared with the host parser (`ikseries.host.protocol.FrameParser`).", "",
             *table(("bytes", "pauses", "good frames", "mismatching chunks", "simulation s", "bytes/s", "cycles/s"),
                    [(f"{f['bytes']:,}", f"{f['pauses']:,}", f"{f['frames']:,}", f["mismatches"],
                      num(f["seconds"], ".1f"), f"{f['bytes_per_s']:,}", f"{f['cycles_per_s']:,}")]),
             *table(tuple(f["counters"]), [tuple(f"{v:,}" for v in f["counters"].values())])]
    if res["area_ice40"]:
        lines += [f"Yosys `synth_ice40` counts, {res['clock_hz'] / 1e6:g} MHz clock at {res['baud'] / 1e6:g} Mbaud "
                  "(an iCE40 logic cell holds one LUT4, its carry and one flip-flop; a flip-flop whose input is no LUT "
                  "of its own still takes a cell, so the placed count below is the one to budget).", "",
                  *table(("design", "LUT", "FF", "carry", "BRAM"),
                         [(r["design"], r["counts"]["LUT"], r["counts"]["FF"], r["counts"]["carry"],
                           r["counts"]["BRAM"]) for r in res["area_ice40"]])]
    p = res.get("pnr_ice40")
    if p:
        lines += [f"`Link` placed and routed on {p['device']} (nextpnr) inside the timing harness, which adds "
                  f"{p['harness_ffs']} flip-flops: {p['LC']} logic cells ({p['LUT']} LUTs, {p['FF']} FFs), "
                  f"{p['BRAM']} block RAMs, Fmax {num(p['fmax_mhz'], '.1f')} MHz.", ""]
    return lines


def controller_fuzz(res: dict) -> list[str]:
    """Lines of the ``bench/controller_fuzz.py`` section from its JSON ``res``."""
    f = res["fuzz"] or {}
    c = f.get("counters", {})
    verdict = "passed" if res["passed"] else f"FAILED: {res['message']}"
    return [f"{res['legs']} legs, PWM period {res['period']} cycles, UART divisor "
            f"{round(res['clock_hz'] / res['baud'])}, {res['simulator']}, seed {res['seed']}: {verdict}. Every "
            "answer against the receiver model's good frames, every PWM period's widths against the model, "
            "the status counters against the model's.", "",
            *table(("bytes", "good frames", "after a bad piece", "periods checked", "cycles", "crc", "bad_length",
                    "unknown_command", "build s", "simulation s"),
                   [(f"{f.get('bytes', 0):,}", f"{f.get('good_frames', 0):,}", f"{f.get('after_bad', 0):,}",
                     f"{f.get('periods_checked', 0):,}", f"{f.get('cycles', 0):,}", c.get("crc", "–"),
                     c.get("bad_length", "–"), c.get("unknown_command", "–"), num(res["build_s"], ".1f"),
                     num(res["simulation_s"], ".1f"))])]


def link_rate(res: dict) -> list[str]:
    """Lines of the ``bench/link_rate.py`` section from its JSON ``res``."""
    s, r = res["summary"] or {}, res["rates"] or {}
    verdict = "passed" if res["passed"] else f"FAILED: {res['message']}"
    return [f"{res['legs']} legs, {s.get('channels', '–')} channels, {res['clock_hz'] / 1e6:g} MHz, "
            f"{res['baud']:,.0f} baud (UART divisor {s.get('divisor', '–')}), PWM period {res['period']:,} cycles, "
            f"{res['simulator']}: {verdict}. Full `move_legs` requests streamed back to back, then one at a "
            "time waiting for each answer; every one answered, none dropped, the pins then checked against "
            f"the model. Target: {res['target_hz']:,} full updates a second.", "",
            *table(("frame bytes", "line cycles", "streamed: cycles/update", "updates/s", "one at a time: "
                    "cycles/update", "updates/s"),
                   [(s.get("frame_bytes", "–"), s.get("line_cycles", "–"), num(s.get("streamed_cycles"), ".1f"),
                     num(r.get("streamed_hz"), ".0f"), num(s.get("lockstep_cycles"), ".1f"),
                     num(r.get("lockstep_hz"), ".0f"))])]


def board_tops(res: dict) -> list[str]:
    """Lines of the ``bench/board_tops.py`` section from its JSON ``res``."""
    rows = []
    for r in res["cases"]:
        if not r["ok"]:
            rows.append((r["preset"], r["board"], "FAILED: " + " ".join(r["error"]), *["–"] * 6))
            continue
        u = r["utilisation"]
        rows.append((r["preset"], r["board"], r["channels"], num(r["clock_hz"] / 1e6, ".3f"), num(r["fmax_mhz"], ".3f"),
                     "yes" if r["meets_clock"] else "**no**", *(f"{u[k]['used']:,} / {u[k]['available']:,}"
                                                                for k in ("LC", "BRAM", "DSP"))))
    return ["`ikseries build --preset P --board B`: the robot controller's whole top (PLL, reset, UART, link, "
            "dispatcher, IK core, servo controller) placed and routed, nextpnr seeds tried in turn until one "
            "meets the clock (the best one's Fmax otherwise).", "",
            *table(("preset", "board", "channels", "clock MHz", "Fmax MHz", "meets clock", "LC", "BRAM", "DSP"), rows)]


def servo_cells(res: dict) -> list[str]:
    """Lines of the ``bench/servo_cells.py`` section from its JSON ``res``."""
    rows = [(name, *(res[key].get(k, 0) for k in ("LUT", "FF", "carry", "BRAM")))
            for name, key in (("ServoController (with its pins' pulse counters)", "controller"),
                              ("ServoPWMCounters alone", "pwm_bank"),
                              ("controller without its pulse counters", "controller_without_bank"))]
    return [f"{res['channels']} channels, {res['width_bits']}-bit widths, period {res['period']:,} cycles; "
            "Yosys `synth_ice40 -dsp` counts.", "",
            *table(("design", "LUT", "FF", "carry", "BRAM"), rows)]


def controller_cells(res: dict) -> list[str]:
    """Lines of the ``bench/controller_cells.py`` section from its JSON ``res``: a table per family."""
    names = (("RobotController", "controller"), ("Link", "link"), ("Dispatcher", "dispatcher"),
             ("ServoController (with its PWM bank)", "servo"), ("ServoController without its bank", "servo_without_bank"),
             ("its PWM bank alone", "servo_bank"), ("RobotCore's PWM bank alone", "core_bank"),
             ("RobotCore without its unused bank", "core_without_bank"), ("beyond the bare core", "beyond_core"),
             ("beyond the core with its own PWM bank", "beyond_core_with_bank"))
    lines = [f"{res['legs']} legs, {res['channels']} channels, {res['width_bits']}-bit widths, period "
             f"{res['period']:,} cycles, UART divisor {res['divisor']}; Yosys counts per family (`synth_ice40 "
             "-dsp`, `synth_ecp5`; the budget: 600 iCE40 logic cells beyond the core). LC: iCE40 logic cells of "
             "the netlist packed by nextpnr (`--pack-only`), the budget's unit.",
             *([f"The servo controller's pins are pulse counters loaded by its pass (`ServoPWMCounters`): "
                f"pulses rise {res['lead']:,} cycles after each period start, at most {res['max_width']:,} "
                "cycles wide; the core's own bank is a `ServoPWMBank` (a width register, a pending register "
                "and a comparator per channel)."] if "lead" in res else []), ""]
    for fam, c in res["families"].items():
        # LC: the iCE40 netlist packed by nextpnr (older records have none)
        cols = (("LC",) if "LC" in c["controller"] else ()) + ("LUT", "FF", "carry", "DSP", "BRAM")
        rows = [(name, *(c[key].get(k, "–") if key in c else "–" for k in cols)) for name, key in names]
        lines += [f"**{fam}**", "", *table(("design", *cols), rows), ""]
    return lines[:-1]


def chain_fit(res: dict) -> list[str]:
    """Lines of the ``bench/chain_fit.py`` section from its JSON ``res``."""
    base = res["results"][0]["fit_cpu_s"]
    rows = [(r["robot"], num(r["fit_cpu_s"], ".1f"), num(r["certify_cpu_s"], ".1f"),
             num(r["fit_cpu_s"] - r["certify_cpu_s"], ".1f"), num(r["fit_cpu_s"] / base, ".2f"), r["plan_multipliers"],
             " / ".join(f"{s['evaluated']:,}" for s in r["servos"]),
             " / ".join(num(s["certified_total_pu"], ".4f") for s in r["servos"])) for r in res["results"]]
    head = ("description", "fit CPU s", "of which certify", "the rest", "÷ closed form", "plan mults",
            "cells evaluated (per servo)", "certified (pu)")
    return [f"Preset `{res['preset']}` fitted (and certified) as its closed form and as a generic serial chain, "
            "one after the other in one run, then each real robot's preset (a body's legs share one plan, "
            f"fitted once). Chain ÷ closed form: {res['ratio']:.2f}x CPU (target ≤ {res['target_ratio']:g}x, "
            "for every robot too).", "", *table(head, rows)]


def ice40_dsp(res: dict) -> list[str]:
    """Lines of the ``bench/ice40_dsp.py`` section from its JSON ``res``."""
    clk = res["clock_hz"]
    rows = []
    for r in res["rows"]:
        u, cp = r["median_run"]["utilisation"], r["median_run"]["critical_path"]
        rows.append(("SB_MAC16 primitive" if r["primitives"] else "fabric", num(r["median_fmax_mhz"], ".3f"),
                     f"{r['median_fmax_mhz'] * 1e6 / clk - 1:.1%}", " / ".join(num(x["fmax_mhz"], ".3f") for x in r["runs"]),
                     u["LC"]["used"], u["DSP"]["used"], u["BRAM"]["used"], r["latency_cycles"],
                     f"`{cp.get('from', '?')}` -> `{cp.get('to', '?')}`"))
    return [f"The `hexapod` preset's core (the shared folded evaluator) at {clk / 1e6:g} MHz on `{res['device']}` "
            f"(timing harness included in LC), nextpnr seeds {', '.join(map(str, res['seeds']))}, the median; the "
            f"target: {res['margin_target']:.0%} margin.", "",
            *table(("limb product registers", "Fmax MHz", "margin", "per seed", "LC", "DSP", "BRAM", "latency",
                    "critical path (median run)"), rows)]


SECTIONS = {
    "fit_benchmark": ("Fits of every preset", "Per preset and servo: what the fit costs and achieves.",
                      fit_benchmark),
    "lowering_latency": ("Horner against the Horner/Estrin mix", "Plan latency, multipliers and rounding "
                         "bounds of the servo polynomials under each lowering.", lowering_latency),
    "certify_bound": ("Certified against sampled error", "The certified bound over the continuous "
                      "workspace beside the sampled maximum.", certify_bound),
    "paper_baseline": ("The paper's procedure against ikseries", "Both fits lowered to plans and measured "
                       "on the same points.", paper_baseline),
    "divided_differences": ("Divided differences (planar-arm path mode)", "The Newton-cubic formula on the "
                            "planar arm's three tool paths.", divided_differences),
    "folded_area": ("Folded and shared evaluators", "Yosys resource counts of the folded evaluator and "
                    "of the shared hexapod core.", folded_area),
    "cordic_vs_poly": ("CORDIC against the polynomial core", "Accuracy and Yosys counts of the CORDIC "
                       "leg solver and the pipelined polynomial evaluator, measured in one run.",
                       cordic_vs_poly),
    "exhaustive_accuracy": ("Error at every representable input", "The built plan's error on the whole "
                            "input grid.", exhaustive_accuracy),
    "verilator_throughput": ("Verilator throughput", "Targets through the exported Verilog in Verilator, "
                             "every output compared bit for bit with the golden model.", verilator_throughput),
    "pareto": ("Every core placed and routed", "Place and route of the polynomial cores, the CORDIC "
               "baseline and the hexapod core on iCE40UP5K and ECP5-25F.", pareto),
    "link_fuzz": ("Host link: receiver fuzz and area", "The frame receiver against the protocol model on a "
                  "long seeded mix of good, corrupted and garbage bytes; Yosys counts of the link.", link_fuzz),
    "controller_fuzz": ("Robot controller: fuzz at the UART pin", "The exported controller in cocotb under a "
                        "long seeded mix of good, corrupted and garbage bytes.", controller_fuzz),
    "link_rate": ("Robot controller: link rate", "Full hexapod updates through the exported controller "
                  "at its UART pin.", link_rate),
    "board_tops": ("Board tops: bitstreams", "The whole robot controller top on each board, from the "
                   "build's own report.", board_tops),
    "servo_cells": ("Servo controller area", "Yosys iCE40 counts of the per-channel servo controller "
                    "(speed, acceleration, timed moves, failsafe) for a hexapod.", servo_cells),
    "controller_cells": ("Robot controller area", "Yosys counts of the hexapod robot controller, "
                         "its parts and what it adds beyond its IK core.", controller_cells),
    "ice40_dsp": ("The hexapod core at 48 MHz on the iCE40UP5K", "Place and route with the limb products' "
                  "registers in the fabric and on an instantiated SB_MAC16.", ice40_dsp),
    "chain_fit": ("A chain against its closed form", "The hexapod leg fitted and certified as formulas and "
                  "as a serial chain (numeric IK, Krawczyk enclosures), CPU seconds in one run.", chain_fit),
}
