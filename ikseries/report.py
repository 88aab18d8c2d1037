"""The build report: one object made from the build steps' results, writing its own
``report.json`` (:meth:`BuildReport.record`) and ``report.md`` (:func:`render_markdown` of that
record, so a report can be rendered again from its JSON)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

__all__ = ["BuildReport", "render_markdown"]


@dataclass(frozen=True)
class BuildReport:
    """What a build made and measured, from its steps (:mod:`ikseries.steps`).

    ``synthesis`` and ``cocotb`` are None when the build skipped them; ``manifest`` is the
    build's manifest.json data; ``error_map`` what :func:`ikseries.plots.error_map` returned.
    """
    robot: object
    fitted: object       # ikseries.steps.Fitted
    core: object         # ikseries.steps.Core
    manifest: dict
    simulation: object   # ikseries.steps.Simulation
    synthesis: object | None
    cocotb: object | None
    error_map: dict
    board: object | None = None     # ikseries.boardbuild.BoardBuild with --board

    @property
    def verilog_file(self) -> str:
        return f"{self.core.module}.v"

    @property
    def worst_error_pu(self) -> float:
        """The largest sampled total error over the servos (pu)."""
        return max(s["total"] for s in self.fitted.accuracy["servos"].values())

    def times(self) -> dict:
        """Seconds per step, in build order (skipped steps left out)."""
        t = {"fit_s": self.fitted.fit_s, "accuracy_s": self.fitted.accuracy_s, "verilog_s": self.core.verilog_s}
        if self.synthesis is not None:
            t["synth_s"] = self.synthesis.seconds
        if self.cocotb is not None:
            t["cocotb_s"] = self.cocotb.seconds
        if self.board is not None:
            t["bitstream_s"] = self.board.bitstream.seconds
        return t

    def record(self) -> dict:
        """JSON-ready data (report.json)."""
        robot, plan, man = self.robot, self.fitted.plan, self.manifest
        rec = {
            "robot": robot.name,
            "ikseries_version": plan.meta.get("ikseries_version"),
            "tolerance_pu": robot.fit.tolerance_pu,
            "clock_hz": robot.hardware.clock_hz,
            "ticks_per_pu": robot.ticks_per_pu,
            "verilog": self.verilog_file,
            "module": man["module"],
            "accuracy_points": self.fitted.accuracy["points"],
            "servos": [_servo_record(sf, o, plan, self.fitted.accuracy)
                       for sf, o in zip(self.fitted.servos, plan.outputs)],
            "plan": _plan_record(plan),
            "calibration": man["calibration"],
            "latency_cycles": man["latency_cycles"],
            "latency_ns": man["latency_ns"],
            "initiation_interval": man["initiation_interval"],
            "legs": man["legs"],
            "refresh_hz": man["refresh_hz"],
            "min_refresh_hz": robot.hardware.min_refresh_hz,
            "architecture": man["architecture"],
            "throughput_targets_per_s": man["throughput"]["targets_per_second_at_clock"],
            "simulation": self.simulation.record(),
            "cocotb": self.cocotb.record() if self.cocotb is not None else {},
            "cocotb_note": self.cocotb.note if self.cocotb is not None else None,
            "error_map": self.error_map,
            "resources": self.synthesis.targets if self.synthesis is not None else None,
            "times_s": self.times(),
        }
        if "primitives" in man:
            rec["primitives"] = man["primitives"]
        if "channels" in man:
            rec["channels"] = man["channels"]
        if self.board is not None:
            rec["board"] = _board_record(self.board, robot)
        return rec

    def markdown(self) -> str:
        """Human-readable report (report.md)."""
        return render_markdown(self.record())

    def write(self, directory: Path) -> None:
        """Write report.json and report.md into ``directory``."""
        rec = self.record()
        (Path(directory) / "report.json").write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
        (Path(directory) / "report.md").write_text(render_markdown(rec))


def _servo_record(sf, output, plan, accuracy: dict) -> dict:
    """One servo's fit (of plan output ``output``), coefficients, sampled error and certificate."""
    cone = plan.cone(output.node)
    return {
        "name": sf.name,
        "total_degree": sf.degree,
        "variables": sf.features.structure(),
        "piecewise": sf.features.piecewise_record(),
        "powers": dict(zip(sf.features.names, sf.features.allowed)),
        "terms": len(sf.poly),
        "accumulator_frac_bits": sf.frac,
        "multipliers": sum(1 for i in cone if plan.nodes[i].op == "mul"),
        "coefficients": [{"exponents": list(e), "integer": q, "value": sf.poly[e]}
                         for e, q in sf.integers().items()],
        "error_pu": accuracy["servos"][sf.name],
        "certified_rounding_bound_pu": sf.bound_pu,
        "certificate": next((c for c in plan.meta.get("certificate", {}).get("servos", [])
                             if c["name"] == sf.name), None),
    }


def _plan_record(plan) -> dict:
    return {"nodes": len(plan.nodes), "multipliers": plan.count("mul"), "adders": plan.count("add"),
            "clamps": plan.count("clamp"), "lookup_tables": plan.count("lut"),
            "feature_frac_bits": plan.meta["features"]["frac_bits"],
            "max_width": max(n.width for n in plan.nodes)}


def _row(cells) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def _certified(c) -> str:
    if c is None:
        return "not run"
    if c["converged"]:
        return f"**certified ≤ {c['total_pu']:.4f}**"
    return f"not certified: bound {c['total_pu']:.4f} (cell budget spent)"


def _throughput_lines(r: dict) -> list[str]:
    ii = r.get("initiation_interval", 1)
    legs = r.get("legs", 1)
    if ii == 1:
        lines = [f"- Throughput: one target per cycle = {r['throughput_targets_per_s']:,.0f} leg solutions/s "
                 "at the configured clock."]
    else:
        lines = [f"- Throughput: one target every {ii} cycles (initiation interval"
                 + (f", measured: {r['simulation'].get('initiation_interval_measured')}"
                    if r['simulation'].get('initiation_interval_measured') else "")
                 + f") = {r['throughput_targets_per_s']:,.0f} leg solutions/s at the configured clock."]
    if "refresh_hz" in r:
        lines.append(f"- Refresh rate: every leg's servos re-evaluated **{r['refresh_hz']:,.0f} times per second** "
                     + (f"({legs} legs addressed round-robin) " if legs > 1 else "")
                     + f"(required: {r['min_refresh_hz']:g})." )
    a = r.get("architecture")
    if a:
        lines.append(f"- Architecture: **{a['description']}**. Why: {a['reason']}.")
        if a.get("fit_device"):
            lines += ["", _row(["configuration tried (fastest first)", "II", "refresh Hz",
                                *(f"{k} (of {v:,})" for k, v in a["fit_device"]["capacity"].items()), "result"]),
                      _row(["---"] * (4 + len(a["fit_device"]["capacity"])))]
            for t in a["tried"]:
                c = t.get("counts")
                lines.append(_row([t["description"], t["initiation_interval"], f"{t['refresh_hz']:,.0f}",
                                   *(f"{c.get(k, 0):,}" if c else "-" for k in a["fit_device"]["capacity"]),
                                   t.get("rejected") or "**chosen**"]))
        elif len(a["tried"]) > 1:
            lines.append("  Tried: " + "; ".join(f"{t['description']}: II {t['initiation_interval']}, "
                                                  f"{t['refresh_hz']:,.0f} Hz" for t in a["tried"]) + ".")
    return lines


def _values(v, fmt: str) -> str:
    """One coefficient, or a piecewise one's values per cell."""
    return ", ".join(fmt.format(x) for x in v) if isinstance(v, (list, tuple)) else fmt.format(v)


def _carry_note(families: dict) -> str:
    """What carry and LUT count on each family (the registry's carry cells and their LUTs)."""
    bits = [f"{f.carry_bits} bit{'s' if f.carry_bits != 1 else ''} ({f.label})" for f in families.values()]
    text = f"carry cells are {', '.join(bits[:-1])} or {bits[-1]} each."
    for f in families.values():
        if f.ripple_luts:
            text += (f" {f.label} LUT includes the {f.ripple_luts} LUTs of every {f.carry_cell} carry cell "
                     "(a slice in ripple mode), as the vendor counts LUTs against the device.")
    return text


def _header(r: dict) -> list[str]:
    return [f"# ikseries report: {r['robot']}", "",
            f"ikseries {r['ikseries_version']}; Verilog module `{r['module']}` in `{r['verilog']}`; "
            f"clock {r['clock_hz'] / 1e6:g} MHz ({r['ticks_per_pu']:g} ticks per pulse unit).", ""]


def _accuracy_section(r: dict) -> list[str]:
    out = ["## Accuracy", "",
           f"Max |error| in pulse units (pu; tolerance ±{r['tolerance_pu']:g} pu) over "
           f"{r['accuracy_points']:,} representable workspace points (dense grid, random, every face). "
           "approximation: the fitted series in exact arithmetic vs the reference IK; quantization: "
           "integer arithmetic vs exact; rounding: the emitted PWM tick count vs the value before "
           "rounding; total: emitted pulse vs exact pulse. The certified rounding bound is a proof, for "
           "every in-range input, on quantization + rounding inside the datapath before the last "
           "rounding; the certified total bounds |emitted - exact pulse| over the whole continuous "
           "workspace box (interval arithmetic with derivatives on adaptive cells).", "",
           _row(["servo", "approximation", "quantization", "rounding", "total", "worst at",
                 "certified rounding bound", "certified total"]),
           _row(["---"] * 8)]
    for s in r["servos"]:
        e = s["error_pu"]
        at = ", ".join(f"{k}={v:g}" for k, v in (e.get("at") or {}).items())
        out.append(_row([s["name"], f"{e['approximation']:.4f}", f"{e['quantization']:.4f}",
                         f"{e['rounding']:.4f}", f"**{e['total']:.4f}**", at,
                         f"{s['certified_rounding_bound_pu']:.4f}", _certified(s.get("certificate"))]))
    if r.get("error_map"):
        g = r["error_map"]["grid"]
        out += ["", "Where the error lies: total error on a " + " x ".join(f"{v} ({k})" for k, v in g.items())
                + " grid of representable inputs, maximum over the last coordinate:", "",
                f"![error map]({r['error_map']['file']})"]
    return out


def _series_section(r: dict) -> list[str]:
    out = ["", "## Series", "",
           "Variables: *radial* = (x² + y², z), *cartesian* = (x, y, z) in the servo-axis frame, "
           "*direct* = the input ports; total-degree terms unless marked *tensor terms* (a degree per "
           "variable); chosen per servo as the fewest multipliers that meet the approximation budget.", "",
           _row(["servo", "variables", "total degree", "powers", "terms", "multipliers (incl. coordinate stage)",
                 "coefficient frac bits"]), _row(["---"] * 7)]
    for s in r["servos"]:
        p = s["powers"]
        out.append(_row([s["name"], s["variables"], s["total_degree"],
                         ", ".join(f"{k} {v}" for k, v in p.items()), s["terms"],
                         s["multipliers"], s["accumulator_frac_bits"]]))
    pl = r["plan"]
    out += ["", f"Whole plan: {pl['nodes']} operations, {pl['multipliers']} multipliers "
            f"(the coordinate stage is shared by all servos), {pl['adders']} adders, "
            + (f"{pl['lookup_tables']} coefficient tables, " if pl.get("lookup_tables") else "") +
            f"features with {pl['feature_frac_bits']} fractional bits, widest intermediate "
            f"{pl['max_width']} bits.", ""]
    return out


def _calibration_section(r: dict) -> list[str]:
    """Each servo's angle -> pulse map (reports written before it have none)."""
    if not r.get("calibration"):
        return []
    out = ["## Calibration", "",
           "Servo angle -> pulse per servo, trim included; outputs are clamped to the pulse limits.", "",
           _row(["servo", "map", "neutral angle (deg)", "neutral pulse (us)", "pulse at 0 deg (us)",
                 "us per deg", "trim (us)", "limits (us)"]), _row(["---"] * 8)]
    for c in r["calibration"]:
        table = c["map"] == "table"
        out.append(_row([c["servo"], "table " + ", ".join(f"{a:g}:{p:g}" for a, p in c["table"]) if table else "linear",
                         f"{c['neutral_angle_deg']:.4f}", f"{c['neutral_pulse_us']:.4f}",
                         "" if table else f"{c['zero_pulse_us']:.4f}", "" if table else f"{c['us_per_degree']:g}",
                         f"{c['trim_us']:g}", f"{c['pulse_min_us']:g} .. {c['pulse_max_us']:g}"]))
    return out + [""]


def _cocotb_line(sim: str, c: dict) -> str:
    return (f"- cocotb on {sim} (exported Verilog): {', '.join(c['tests'])} passed"
            + (f" ({c['random_targets']} random targets plus the corners)" if "random_targets" in c else "")
            + f", latency {c['latency_cycles_measured']} cycles"
            + (f", a target every {c['initiation_interval']} cycles" if "initiation_interval" in c else "")
            + f" (build {c['build_s']} s, simulation {c['test_s']} s).")


def _timing_section(r: dict) -> list[str]:
    return ["## Timing", "",
            f"- Latency: **{r['latency_cycles']} cycles** ({r['latency_ns']:.1f} ns at the configured clock), "
            f"measured in the Amaranth simulation: {r['simulation']['latency_cycles_measured']} cycles "
            f"({r['simulation']['targets']} targets, {r['simulation']['mismatches']} mismatches against "
            "the golden model).",
            *[_cocotb_line(sim, c) for sim, c in (r.get("cocotb") or {}).items()],
            *([f"- {r['cocotb_note']}."] if r.get("cocotb_note") else []),
            *_throughput_lines(r), ""]


def _resources_section(r: dict) -> list[str]:
    res = r.get("resources")
    out = ["## FPGA resources (Yosys, before place-and-route)", ""]
    if not res:
        return out + ["Synthesis was skipped (--no-synth)."]
    from .constraints.devices import FAMILIES, reference_part
    cats = ["LUT", "FF", "carry", "DSP", "BRAM"]
    out += [_row(["target", *cats, "fits reference device?", "synthesis time (s)"]),
            _row(["---"] * (len(cats) + 3))]
    for tgt, d in res.items():
        c = d["counts"]
        ref = reference_part(tgt)
        over = ref.overflows(c)
        fits = (f"{ref.part}: " + ("yes (by cell count)" if not over else
                "no: " + ", ".join(f"{k} {u}/{a}" for k, (u, a) in over.items())))
        out.append(_row([tgt, *(c.get(k, 0) for k in cats), fits, d.get("seconds", "")]))
    if r.get("primitives"):
        fam = FAMILIES[r["primitives"]["family"]].label
        out += ["", f"{fam} only: the Verilog instantiates {fam} "
                + ", ".join(r["primitives"]["cells"]) + " primitives."]
    out += ["", "Cell counts after synthesis, before place-and-route; " + _carry_note(FAMILIES) + " "
            + ("This fully pipelined, one-target-per-cycle design is sized for throughput, not area."
               if r.get("initiation_interval", 1) == 1 else
               "This design trades throughput for area: its multipliers are shared over "
               "several operations" + (" and every leg." if r.get("legs", 1) > 1 else "."))]
    return out


def _coefficients_section(r: dict) -> list[str]:
    out = ["", "## Coefficients", "",
           "Integer coefficient = round(value * 2**frac_bits); a term is the product of the "
           "servo's normalised variables (see plan.json `meta.features`) raised to the listed "
           "powers; value in PWM ticks.", ""]
    for s in r["servos"]:
        out += [f"### {s['name']}", "", _row(["powers of " + ", ".join(s["powers"]), "integer", "value"]),
                _row(["---"] * 3)]
        cut = s.get("piecewise")
        if cut:
            out[-2:-2] = [_piecewise_note(cut), ""]
        out += [_row([" ".join(map(str, c["exponents"])), _values(c["integer"], "{}"), _values(c["value"], "{:.10g}")])
                for c in s["coefficients"]]
        out.append("")
    return out


def _piecewise_note(cut: dict) -> str:
    """The coefficients' cells in words: one input's cells or a grid over two."""
    def one(c):
        if "feature" in c:
            return (f"cells of width {c['cell_width']:g} of the normalised variable {c['feature']} from -1 (computed "
                    f"and rounded in the plan), which becomes the offset inside the cell, normalised to [-1, 1)")
        var = (f"; variable {c['variable']} is the offset inside the cell, normalised to [-1, 1)"
               if c["variable"] is not None else f" ({c['input']} is no variable of the polynomial)")
        return f"cells of {c['port_values_per_cell']} port values of input {c['input']} from its lowest value{var}"
    if "grid" in cut:
        a, b = cut["grid"]
        return (f"Piecewise: one coefficient per cell of a {a['cells']} x {b['cells']} grid, cell i * {b['cells']} + j "
                f"in cell order for cell i of the first input and j of the second: {one(a)}; {one(b)}.")
    return f"Piecewise: one coefficient per cell, in cell order: {one(cut)}."


def _board_record(b, robot) -> dict:
    bits = b.bitstream
    return {**b.spec.record(robot), "controller_verilog": f"{b.module}.v", "controller_module": b.module,
            "bitstream": f"bitstream/{bits.path.name}", "fmax_mhz": bits.fmax_mhz, "meets_clock": bits.meets_clock,
            "utilisation": bits.utilisation, "controller_core": b.core, "servo_pulses": b.pulses}


def _controller_core(b: dict) -> list[str]:
    core = b.get("controller_core")
    if not core:
        return []
    return [f"The controller's IK core is the folded evaluator shared by its {core['legs']} "
            f"leg{'s' if core['legs'] > 1 else ''} ({core['latency_cycles']} cycles a leg), whatever the "
            "core built above: requests arrive at the line rate, thousands of cycles apart, so a faster "
            "core would only cost area.", ""]


def _servo_pulses(b: dict) -> list[str]:
    p, hz = b.get("servo_pulses"), b["clock"]["achieved_hz"]
    if not p:
        return []
    return [f"Servo pulses: every period the servo controller updates all channels in one pass, then every "
            f"enabled channel's pulse rises at once, {p['lead_cycles']:,} cycles ({p['lead_cycles'] / hz * 1e6:.1f} µs) "
            f"after the period start; a pulse is at most {p['max_width_cycles']:,} cycles "
            f"({p['max_width_cycles'] / hz * 1e6:.1f} µs) wide.", ""]


def _board_section(r: dict) -> list[str]:
    b = r.get("board")
    if not b:
        return []
    clock = b["clock"]
    out = ["## Board", "",
           f"{b['board']}: bitstream `{b['bitstream']}` of the robot controller `{b['controller_module']}` "
           f"(host link, command dispatcher, IK core, servo controller; `{b['controller_verilog']}`). Core clock "
           f"{clock['achieved_hz'] / 1e6:.9g} MHz from the {clock['oscillator_hz'] / 1e6:g} MHz oscillator"
           f"{'' if clock['primitive'] is None else ' through ' + clock['primitive']}; Fmax of the whole top {b['fmax_mhz']:g} MHz "
           f"({'meets' if b['meets_clock'] else 'misses'} the clock). Host link {b['baud']:,} baud "
           f"(UART divisor {b['uart_divisor']}).", "", *_controller_core(b), *_servo_pulses(b),
           _row(["resource", "used", "available"]), _row(["---"] * 3),
           *(_row([k, str(v["used"]), str(v["available"])]) for k, v in b["utilisation"].items()), "",
           "Pin map:", "", _row(["pin", "package pin", "channel", "leg", "servo"]), _row(["---"] * 5),
           *(_row([c["pin"], c["package_pin"], str(c["channel"]), str(c["leg"]), c["servo"]]) for c in b["channels"]),
           ""]
    return out


def _channels_section(r: dict) -> list[str]:
    """Every channel: its leg, servo, side, mount, the per-channel calibration applied after the
    plan, its core port and, on a board, its pin."""
    chans = r.get("channels")
    if not chans:
        return []
    pins = {c["channel"]: c["pin"] for c in (r.get("board") or {}).get("channels", [])}
    gains = "scale" in chans[0]
    head = ["channel", "leg", "servo", "side", "mount x, y, z mm, yaw deg", "direction", "centre ticks",
            "trim ticks", "min ticks", "max ticks", "mirrored", *(["scale", "error ticks"] if gains else []),
            "port", *(["pin"] if pins else [])]
    why = ("a channel is scale x width + offset, the gain and offset rounded to fixed point: that rounding and "
           "the final one add the error column to its error, and the plan is fitted to the tolerance less it, "
           "over the largest scale" if gains else
           "a mirrored channel is 2 centre - width, 2 centre rounded to whole ticks: that rounding, at most half a "
           "tick, adds to its error")
    out = ["## Channels", "",
           f"The per-channel calibration is applied after the shared plan ({why}); changing it changes no "
           "fit.", "", _row(head), _row(["---"] * len(head))]
    for c in chans:
        m = c["mount"]
        mount = "-" if m is None else f"{m['x']:g}, {m['y']:g}, {m['z']:g}, {m['yaw']:g}"
        mirrored = ("yes" if c["mirrored"] else "no") if gains else \
            (f"yes ({c['mirror_error_ticks']:.3f} tick)" if c["mirrored"] else "no")
        out.append(_row([str(c["channel"]), f"{c['leg']} {c['leg_name']}", c["servo"], c["side"], mount,
                         f"{c['direction']:+d}", f"{c['centre_ticks']:.3f}", str(c["trim_ticks"]),
                         str(c["min_ticks"]), str(c["max_ticks"]), mirrored,
                         *([f"{c['scale']:.6f}", f"{c['error_ticks']:.3f}"] if gains else []), c.get("port", "-"),
                         *([pins.get(c["channel"], "-")] if pins else [])]))
    return out + [""]


def render_markdown(r: dict) -> str:
    """report.md from a build's report record (:meth:`BuildReport.record`, report.json)."""
    t = r["times_s"]
    out = [*_header(r), *_accuracy_section(r), *_series_section(r), *_calibration_section(r), *_timing_section(r),
           *_resources_section(r), *_channels_section(r), *_board_section(r), *_coefficients_section(r),
           "## Build times", "", ", ".join(f"{k[:-2]} {v:g} s" for k, v in t.items()), ""]
    return "\n".join(out)
