"""Verilate an exported design with a C++ ``main`` into one executable: the build shared by the
throughput bench (:mod:`ikseries.sim.verilator_bench`) and the served simulation
(:mod:`ikseries.sim.serve`).

The build writes ``<top>.v``, the C++ file and ``obj/`` in its work directory and nothing else.
Verilator and the make and g++ it runs are one process group of their own, ended whole if the
build is interrupted, so no compiler outlives it.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

from .runner import primitive_models, verilator_make_fixes, verilator_path, verilator_tools

__all__ = ["check_identifier", "verilate"]


def check_identifier(name: str, what: str = "top") -> None:
    """Refuse a ``name`` that is no plain Verilog identifier (it becomes a C++ class name too)."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ValueError(f"{what} must be a plain Verilog identifier, not {name!r}")


#: seconds an interrupted build's processes get to remove their own temporary files (g++ and
#: make do on SIGTERM) before they are killed
TERMINATE_GRACE_S = 5.0


def _end_group(proc: subprocess.Popen) -> None:
    """SIGTERM to ``proc``'s process group, SIGKILL to what is left after :data:`TERMINATE_GRACE_S`."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + TERMINATE_GRACE_S
        while time.monotonic() < deadline:
            proc.poll()               # reaped, the leader no longer counts as a member
            os.killpg(proc.pid, 0)
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:        # the group is gone
        pass


def _run_group(argv, cwd, env) -> subprocess.CompletedProcess:
    """``argv`` in a new process group, its output captured; any exception (an interrupt
    included) ends the whole group before it propagates."""
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate()
    except BaseException:
        _end_group(proc)
        proc.wait()
        raise
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def verilate(verilog: str, top: str, cpp: str, cpp_name: str, workdir, *, cxx_opt: str = "-O2",
             jobs: int = 2) -> tuple[Path, float]:
    """Build ``workdir/obj/V<top>`` from ``verilog`` (module ``top``) and the C++ source ``cpp``
    (written as ``workdir/<cpp_name>``); returns (executable, build seconds).

    Raises ``ValueError`` on a bad ``top`` or ``cxx_opt``, ``RuntimeError`` if Verilator is
    unavailable or the build fails (quoting the end of its output).
    """
    check_identifier(top)
    if not re.fullmatch(r"-O[0-3s]", cxx_opt):
        raise ValueError(f"cxx_opt must be one of -O0, -O1, -O2, -O3, -Os, not {cxx_opt!r}")
    ok, why = verilator_tools()
    if not ok:
        raise RuntimeError(why)
    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / f"{top}.v").write_text(verilog)
    (workdir / cpp_name).write_text(cpp)
    path = verilator_path()
    env = dict(os.environ, PATH=path)
    # run-once code at -O0 (see runner.run)
    fixes = [verilator_make_fixes(path), f"OPT_FAST={cxx_opt}", "OPT_SLOW=-O0", f"OPT_GLOBAL={cxx_opt}"]
    env["MAKEFLAGS"] = " ".join(x for x in (os.environ.get("MAKEFLAGS", ""), *fixes) if x)
    argv = [shutil.which("verilator", path=path), "--cc", "--exe", "--build", "-j", str(jobs), "--no-timing",
            "-Wno-fatal", "-Wno-lint", "-Wno-style", "--top-module", top, "--Mdir", "obj",
            "-o", f"V{top}", f"{top}.v", *map(str, primitive_models(verilog)), cpp_name]
    t0 = time.perf_counter()
    proc = _run_group(argv, workdir, env)
    build_s = round(time.perf_counter() - t0, 2)
    binary = workdir / "obj" / f"V{top}"
    if proc.returncode != 0 or not binary.is_file():
        tail = "\n".join((proc.stdout + proc.stderr).rstrip().splitlines()[-25:])
        raise RuntimeError(f"Verilator build of {top} failed (status {proc.returncode}):\n{tail}")
    return binary, build_s
