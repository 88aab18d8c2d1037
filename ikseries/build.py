"""``ikseries build``: robot description -> fit -> plan -> Verilog, manifest, report."""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import __version__
from .accuracy import measure
from .architecture import ArchitectureError, choose_architecture
from .buildrecord import (BuildRecordError, OutputDirError, check_output_dir, recorded_files, remove_created,
                          write_record)
from .constraints.timing import clock_sdc
from .fit.fitter import FitError, fit_robot
from .hdl.export import leg_verilog, manifest, module_name, robot_verilog
from .hdl.shared import RobotCore
from .plots import error_map
from .report import render_markdown
from .robot import robot_record
from .sim import golden
from .sim.amaranth_sim import simulate_leg, simulate_robot
from .sim.runner import SIMULATORS, primitive_models
from .sim.targets import corner_targets, random_targets

__all__ = ["BuildError", "build", "default_output_dir"]


#: files every build writes, besides ``<module>.v`` and ``<module>.sdc``
FIXED_ARTIFACTS = ("plan.json", "manifest.json", "report.json", "report.md", "error_map.png")


def default_output_dir(robot) -> Path:
    """Where ``ikseries build`` writes when no ``-o`` is given."""
    return Path("build") / robot.name


class BuildError(RuntimeError):
    """The build cannot produce a design that meets the robot's requirements."""


#: simulated cycles the verification run aims at for a core taking one target per
#: ``initiation_interval`` cycles (random targets: between 64 and 1000, plus the corners)
SIM_CYCLE_BUDGET = 40_000


def _simulate(core, plan, progress, vcd=None) -> dict:
    """Amaranth simulation: bit-exact against the golden model, latency measured, targets
    accepted back to back every ``initiation_interval`` cycles; a robot core gets each target
    addressed to a random leg and must return it with that leg."""
    ii = core.initiation_interval
    n_random = int(np.clip(SIM_CYCLE_BUDGET // ii, 64, 1000))
    targets = {k: np.concatenate([c, r]) for (k, c), r in
               zip(corner_targets(plan).items(), random_targets(plan, n_random, 7).values())}
    n = len(next(iter(targets.values())))
    t0 = time.perf_counter()
    leg_mismatches = 0
    if isinstance(core, RobotCore):
        legs = np.random.default_rng(11).integers(0, core.legs, n)
        res = simulate_robot(core, legs, targets, vcd=vcd)
        leg_mismatches = int(np.count_nonzero(res.legs != legs))
    else:
        res = simulate_leg(core.simulation_model(), targets, vcd=vcd)
    exp = golden.outputs(plan, targets)
    mismatches = int(sum(np.count_nonzero(res.outputs[s] != exp[s]) for s in exp))
    lat = sorted(set(int(x) for x in res.latencies))
    gaps = sorted(set(int(x) for x in np.diff(res.input_cycles)))
    progress(f"amaranth simulation: {n} targets, {mismatches} mismatches"
             + (f", {leg_mismatches} wrong legs" if isinstance(core, RobotCore) else "")
             + f", latency {lat} cycles, inputs every {gaps} cycles")
    if mismatches or leg_mismatches or lat != [core.latency] or gaps != [ii]:
        raise BuildError(f"simulation disagrees with the golden model ({mismatches} mismatches, "
                         f"{leg_mismatches} wrong legs, latency {lat} vs {core.latency}, inputs every "
                         f"{gaps} cycles vs {ii}): please report this as a bug")
    out = {"simulator": "amaranth", "targets": n, "mismatches": mismatches,
           "latency_cycles_measured": lat[0], "initiation_interval_measured": gaps[0] if gaps else None,
           "seconds": round(time.perf_counter() - t0, 2)}
    if isinstance(core, RobotCore):
        out["legs_addressed"] = sorted(set(int(x) for x in legs))
        out["leg_mismatches"] = leg_mismatches
    return out


@contextlib.contextmanager
def _output_to(log: Path):
    """Send this process's stdout/stderr file descriptors (and so the simulators') to ``log``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(log, "ab") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


#: random targets of the build's cocotb back-to-back test on a pipelined core (fewer for a core
#: with an initiation interval > 1, see :func:`ikseries.sim.runner.default_n_random`)
COCOTB_N_RANDOM = 1000


def _cocotb(plan_file: Path, period: int, simulators, workdir: Path, logdir: Path, progress,
            core=None, *, manifest_file: Path | None = None) -> tuple[dict, str | None]:
    """cocotb on the exported Verilog: bit-exact streaming with and without backpressure.

    ``simulators`` is a list of names, or "auto" for every installed one. The simulator
    output goes to ``logdir/cocotb_<simulator>.log``. ``core``: the leg or robot core to
    export (None: the pipelined ``LegCore``); ``manifest_file``: the build's manifest, which
    the bench reads the design from (None: the runner writes one). Returns (results per
    simulator, note naming the simulators "auto" skipped because they are not installed, or None).
    """
    from .sim.runner import SIMULATORS, default_n_random, run, simulator_available
    out, skipped = {}, []
    if simulators == "auto":
        simulators = [s for s in SIMULATORS if simulator_available(s)[0]]
        for s in sorted(set(SIMULATORS) - set(simulators)):
            skipped.append(f"{s} ({simulator_available(s)[1]})")
            progress(f"cocotb on {s}: skipped ({simulator_available(s)[1]})")
    ii = 1 if core is None else core.initiation_interval
    n_random = default_n_random(ii, COCOTB_N_RANDOM)
    for sim in simulators:
        ok, why = simulator_available(sim)
        if not ok:
            raise BuildError(f"cannot run cocotb on {sim}: {why}")
        progress(f"cocotb on {sim}: building and simulating the exported Verilog")
        log = logdir / f"cocotb_{sim}.log"
        with _output_to(log):
            res = run(plan_file, period, sim, workdir / sim, n_random=n_random,
                      testcase="test_back_to_back,test_backpressure", core=core, manifest=manifest_file)
        failed = {t: m for t, (ok_, m) in res.tests.items() if not ok_}
        if not res.ok or failed:
            raise BuildError(f"cocotb on {sim} failed (log: {log}): "
                             + "; ".join(f"{t}: {m}" for t, m in failed.items()).replace("\n", " "))
        progress(f"cocotb on {sim}: {', '.join(sorted(res.tests))} passed ({n_random} random targets "
                 f"plus corners back to back, half as many with backpressure), latency {res.latency} "
                 f"cycles, a target every {res.initiation_interval} cycles")
        out[sim] = {"tests": sorted(res.tests), "passed": True, "latency_cycles_measured": res.latency,
                    "initiation_interval": res.initiation_interval, "random_targets": n_random,
                    "build_s": round(res.build_s, 1), "test_s": round(res.test_s, 1)}
    note = f"cocotb skipped on {', '.join(skipped)}" if skipped else None
    return out, note


def planned_outputs(robot, *, vcd: bool, cocotb) -> set[str]:
    """Every name a build of ``robot`` with these options may write into its directory."""
    name = module_name(robot.name)
    out = {f"{name}.v", f"{name}.sdc", *FIXED_ARTIFACTS}
    if vcd:
        out.add("sim.vcd")
    out |= {f"cocotb_{s}.log" for s in (SIMULATORS if cocotb == "auto" else cocotb)}
    if robot.hardware.dsp_primitives:          # the only builds that instantiate vendor primitives
        out.add("sim_models")
    return out


def _check_foreign(out_dir: Path, names) -> set[str]:
    """The build record of ``out_dir``; fail if any of ``names`` exists there unrecorded (a
    file ikseries did not write, which a build must not replace)."""
    if not out_dir.is_dir():
        return set()
    try:
        recorded = recorded_files(out_dir)
    except BuildRecordError as e:
        raise BuildError(str(e)) from None
    foreign = sorted(n for n in names if os.path.lexists(out_dir / n) and n not in recorded)
    if foreign:
        raise BuildError(f"output directory {str(out_dir)!r} holds {', '.join(foreign)}, not written by an "
                         f"ikseries build there; a build would replace {'them' if len(foreign) > 1 else 'it'}: "
                         f"move {'them' if len(foreign) > 1 else 'it'} away or choose another -o")
    return recorded


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()


def _install(tmp: Path, out_dir: Path) -> list[str]:
    """Move every entry of ``tmp`` into ``out_dir``, removing what the previous build there
    recorded and this one did not write; entries not in the record are never touched."""
    written = sorted(f.name for f in tmp.iterdir())
    recorded = _check_foreign(out_dir, written)
    # recorded first: an interrupted move leaves only entries the record names
    write_record(out_dir, recorded | set(written))
    for stale in sorted(recorded - set(written)):
        _remove(out_dir / stale)
    for name in written:
        _remove(out_dir / name)
        shutil.move(tmp / name, out_dir / name)
    write_record(out_dir, written)
    return written


def _fit_and_measure(robot, progress, times: dict):
    """(plan, fits, accuracy) of ``robot``, refused unless the sampled error meets the tolerance."""
    t0 = time.perf_counter()
    progress(f"fitting {robot.name} (tolerance ±{robot.fit.tolerance_pu:g} pu)")
    try:
        plan, fits = fit_robot(robot, progress)
    except FitError as e:
        raise BuildError(str(e)) from None
    times["fit_s"] = round(time.perf_counter() - t0, 1)
    plan.meta["robot_description"] = robot_record(robot)
    plan.meta["ikseries_version"] = __version__

    t0 = time.perf_counter()
    acc = measure(robot, plan)
    times["accuracy_s"] = round(time.perf_counter() - t0, 1)
    plan.meta["accuracy"] = {"points": acc["points"],
                             "max_error_pu": {s: {k: v for k, v in w.items() if k != "at"}
                                              for s, w in acc["servos"].items()}}
    worst = max(acc["servos"].items(), key=lambda kv: kv[1]["total"])
    progress(f"accuracy on {acc['points']} points: worst {worst[0]} {worst[1]['total']:.3f} pu")
    if worst[1]["total"] > robot.fit.tolerance_pu:
        raise BuildError(f"servo {worst[0]} misses the tolerance: {worst[1]['total']:.4f} pu > "
                         f"{robot.fit.tolerance_pu:g} pu at {worst[1]['at']}")
    return plan, fits, acc


@contextlib.contextmanager
def _staging(out_dir: Path, created: Path | None):
    """A hidden temporary directory inside ``out_dir`` (made with it if need be) for the
    build's files; removed on leaving, and with it the directories the build created unless
    the body completed (a failure or an interrupt leaves nothing behind)."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".ikseries-tmp-", dir=out_dir))
    except OSError as e:
        remove_created(out_dir, created)
        raise BuildError(f"cannot create the output directory {str(out_dir)!r}: {e.strerror}") from None
    done = False
    try:
        yield tmp
        done = True
    except OSError as e:
        raise BuildError(f"cannot write the build output to {str(out_dir)!r}: {e}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            remove_created(out_dir, created)


def build(robot, out_dir, *, synth: bool = True, vcd: bool = False, cocotb="auto", progress=print) -> dict:
    """Run the whole pipeline and write every artifact into ``out_dir``.

    Files are written to a hidden temporary directory inside ``out_dir`` and moved into
    place at the end, so a failed or interrupted build leaves nothing half-written. Only
    entries of the directory's build record (:mod:`ikseries.buildrecord`) are replaced or
    removed; a build that would replace any other file is refused before the fit. ``vcd`` also
    writes the waveform of the verification simulation (``sim.vcd``); ``cocotb``
    names simulators ("icarus", "verilator") that also run the exported Verilog
    ("auto": every installed one; empty: none).
    """
    out_dir = Path(out_dir)
    try:
        created = check_output_dir(out_dir)
    except OutputDirError as e:
        raise BuildError(str(e)) from None
    _check_foreign(out_dir, planned_outputs(robot, vcd=vcd, cocotb=cocotb))
    times = {}
    plan, fits, acc = _fit_and_measure(robot, progress, times)
    name = module_name(robot.name)
    try:
        choice = choose_architecture(robot, plan, progress=progress)
    except ArchitectureError as e:
        raise BuildError(str(e)) from None
    core = choice.core
    arch = choice.record()
    progress(f"architecture: {arch['description']}: latency {core.latency} cycles, a target every "
             f"{core.initiation_interval} cycles, every leg refreshed {choice.refresh_hz:,.0f} times/s")
    t0 = time.perf_counter()
    progress("exporting Verilog")
    verilog_text = robot_verilog(core, name) if isinstance(core, RobotCore) else leg_verilog(core, name)
    times["verilog_s"] = round(time.perf_counter() - t0, 1)

    with _staging(out_dir, created) as tmp:
        sim = _simulate(core, plan, progress, vcd=str(tmp / "sim.vcd") if vcd else None)
        vfile = f"{name}.v"
        (tmp / vfile).write_text(verilog_text)
        for model in primitive_models(verilog_text):   # vendor primitives: our simulation model
            (tmp / "sim_models").mkdir(exist_ok=True)
            shutil.copyfile(model, tmp / "sim_models" / model.name)
        family = getattr(core, "dsp_registers", None)   # the family of those primitives, if any
        (tmp / f"{name}.sdc").write_text(clock_sdc(name, robot.hardware.clock_hz))
        resources = None
        if synth:
            from .constraints.devices import FAMILIES
            from .synth import synth_counts
            t0 = time.perf_counter()
            resources = synth_counts(tmp / vfile, name, (family,) if family else tuple(FAMILIES),
                                     workdir=tmp / "synth", progress=progress, jobs=2)
            times["synth_s"] = round(time.perf_counter() - t0, 1)
            shutil.rmtree(tmp / "synth", ignore_errors=True)
        (tmp / "plan.json").write_text(plan.dumps())
        progress("plotting the error map")
        emap = error_map(robot, plan, tmp / "error_map.png")
        man = manifest(robot, plan, core, name, arch)
        (tmp / "manifest.json").write_text(json.dumps(man, indent=1, sort_keys=True) + "\n")
        cocotb_res, cocotb_note = {}, None
        if cocotb:
            t0 = time.perf_counter()
            cocotb_res, cocotb_note = _cocotb(tmp / "plan.json", robot.hardware.pwm_period_ticks, cocotb,
                                              tmp / "cocotb", tmp, progress, core, manifest_file=tmp / "manifest.json")
            times["cocotb_s"] = round(time.perf_counter() - t0, 1)
            shutil.rmtree(tmp / "cocotb", ignore_errors=True)
        report = make_report(robot, plan, fits, acc, sim, cocotb_res, emap, man, resources, times, vfile)
        report["cocotb_note"] = cocotb_note
        (tmp / "report.json").write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
        (tmp / "report.md").write_text(render_markdown(report))
        written = _install(tmp, out_dir)
    progress(f"wrote {out_dir}/: " + ", ".join(written))
    return report


def make_report(robot, plan, fits, acc, sim, cocotb_res, emap, man, resources, times, vfile) -> dict:
    servos = []
    for sf, o in zip(fits, plan.outputs):
        cone = plan.cone(o.node)
        servos.append({
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
            "error_pu": acc["servos"][sf.name],
            "certified_rounding_bound_pu": sf.bound_pu,
            "certificate": next((c for c in plan.meta.get("certificate", {}).get("servos", [])
                                 if c["name"] == sf.name), None),
        })
    report = {
        "robot": robot.name,
        "ikseries_version": plan.meta.get("ikseries_version"),
        "tolerance_pu": robot.fit.tolerance_pu,
        "clock_hz": robot.hardware.clock_hz,
        "ticks_per_pu": robot.ticks_per_pu,
        "verilog": vfile,
        "module": man["module"],
        "accuracy_points": acc["points"],
        "servos": servos,
        "plan": {"nodes": len(plan.nodes), "multipliers": plan.count("mul"), "adders": plan.count("add"),
                 "clamps": plan.count("clamp"), "lookup_tables": plan.count("lut"),
                 "feature_frac_bits": plan.meta["features"]["frac_bits"],
                 "max_width": max(n.width for n in plan.nodes)},
        "latency_cycles": man["latency_cycles"],
        "latency_ns": man["latency_ns"],
        "initiation_interval": man["initiation_interval"],
        "legs": man["legs"],
        "refresh_hz": man["refresh_hz"],
        "min_refresh_hz": robot.hardware.min_refresh_hz,
        "architecture": man["architecture"],
        "throughput_targets_per_s": man["throughput"]["targets_per_second_at_clock"],
        "simulation": sim,
        "cocotb": cocotb_res,
        "error_map": emap,
        "resources": resources,
        "times_s": times,
    }
    if "primitives" in man:
        report["primitives"] = man["primitives"]
    return report

