"""``ikseries build``: robot description -> fit -> plan -> Verilog, manifest, report."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from . import steps
from .channels import channel_records
from .boardbuild import BITSTREAM_DIR, BoardBuildError, BoardSpec, board_build, controller_module, robot_on_board
from .buildrecord import (BuildRecordError, OutputDirError, check_output_dir, recorded_files, staging,
                          write_record)
from .constraints.timing import clock_sdc
from .hdl.export import manifest, module_name
from .plots import error_map
from .report import BuildReport
from .sim.runner import SIMULATORS, primitive_models

__all__ = ["BuildError", "build", "default_output_dir"]


#: files every build writes, besides ``<module>.v`` and ``<module>.sdc``
FIXED_ARTIFACTS = ("plan.json", "manifest.json", "report.json", "report.md", "error_map.png")


def default_output_dir(robot) -> Path:
    """Where ``ikseries build`` writes when no ``-o`` is given."""
    return Path("build") / robot.name


class BuildError(RuntimeError):
    """The build cannot produce a design that meets the robot's requirements."""


def planned_outputs(robot, *, vcd: bool, cocotb, board: BoardSpec | None = None) -> set[str]:
    """Every name a build of ``robot`` with these options may write into its directory."""
    name = module_name(robot.name)
    out = {f"{name}.v", f"{name}.sdc", *FIXED_ARTIFACTS}
    if board is not None:
        out |= {f"{controller_module(name)}.v", BITSTREAM_DIR}
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


def build(robot, out_dir, *, synth: bool = True, vcd: bool = False, cocotb="auto", progress=print,
          board: BoardSpec | None = None, jobs: int = 1) -> BuildReport:
    """Run the whole pipeline (:mod:`ikseries.steps`) and write every artifact into ``out_dir``.

    Files are written to a hidden temporary directory inside ``out_dir`` and moved into
    place at the end, so a failed or interrupted build leaves nothing half-written. Only
    entries of the directory's build record (:mod:`ikseries.buildrecord`) are replaced or
    removed; a build that would replace any other file is refused before the fit. ``vcd`` also
    writes the waveform of the verification simulation (``sim.vcd``); ``cocotb``
    names simulators ("icarus", "verilator") that also run the exported Verilog
    ("auto": every installed one; empty: none). With ``board``
    (:func:`ikseries.boardbuild.board_spec`) the robot runs at the clock the board's PLL makes,
    and the build also writes the robot controller's Verilog and its bitstream
    (:mod:`ikseries.boardbuild`). ``jobs`` > 1 fits the servos in that many processes at a
    time (the plan is the same). Returns the build's report.
    """
    out_dir = Path(out_dir)
    try:
        created = check_output_dir(out_dir)
    except OutputDirError as e:
        raise BuildError(str(e)) from None
    if board is not None:
        on_board = robot_on_board(robot, board)
        if on_board is not robot:
            progress(f"{board.board.name}: the core clock is {board.clock.describe()}; fitting for it")
        robot = on_board
    _check_foreign(out_dir, planned_outputs(robot, vcd=vcd, cocotb=cocotb, board=board))
    try:
        fitted = steps.fit(robot, progress, jobs)
        core = steps.core(robot, fitted.plan, progress)
        with staging(out_dir, created, ".ikseries-tmp-", BuildError, "build output") as tmp:
            report = _write_outputs(robot, fitted, core, tmp, synth=synth, vcd=vcd, cocotb=cocotb,
                                    progress=progress, board=board)
            written = _install(tmp, out_dir)
    except (steps.StepError, BoardBuildError) as e:
        raise BuildError(str(e)) from None
    progress(f"wrote {out_dir}/: " + ", ".join(written))
    return report


def _write_outputs(robot, fitted, core, tmp: Path, *, synth, vcd, cocotb, progress, board=None) -> BuildReport:
    """Verify the core and write every output of the build into ``tmp``."""
    plan, component, name = fitted.plan, core.component, core.module
    sim = steps.simulate(component, plan, progress, vcd=str(tmp / "sim.vcd") if vcd else None)
    vfile = tmp / f"{name}.v"
    vfile.write_text(core.verilog)
    for model in primitive_models(core.verilog):   # vendor primitives: our simulation model
        (tmp / "sim_models").mkdir(exist_ok=True)
        shutil.copyfile(model, tmp / "sim_models" / model.name)
    (tmp / f"{name}.sdc").write_text(clock_sdc(name, robot.hardware.clock_hz))
    synthesis = None
    if synth:
        family = getattr(component, "dsp_registers", None)   # the family of its primitives, if any
        synthesis = steps.synthesise(vfile, name, family, tmp / "synth", progress)
        shutil.rmtree(tmp / "synth", ignore_errors=True)
    (tmp / "plan.json").write_text(plan.dumps())
    progress("plotting the error map")
    emap = error_map(robot, plan, tmp / "error_map.png")
    man = manifest(robot, plan, component, name, core.choice.record())
    man["channels"] = channel_records(robot, {c: p["port"] for c, p in enumerate(man["pwm"])})
    if board is not None:
        man["board"] = {**board.record(robot), "controller_module": controller_module(name)}
    man_text = json.dumps(man, indent=1, sort_keys=True) + "\n"
    (tmp / "manifest.json").write_text(man_text)
    on_board = None
    if board is not None:
        on_board = board_build(robot, plan, board, name, man_text, tmp, progress)
        (tmp / f"{on_board.module}.v").write_text(on_board.verilog)
    cocotb_runs = None
    if cocotb:
        cocotb_runs = steps.cocotb(tmp / "plan.json", robot.hardware.pwm_period_ticks, cocotb, tmp / "cocotb", tmp,
                                   progress, component, manifest_file=tmp / "manifest.json")
        shutil.rmtree(tmp / "cocotb", ignore_errors=True)
    report = BuildReport(robot, fitted, core, man, sim, synthesis, cocotb_runs, emap, on_board)
    report.write(tmp)
    return report
