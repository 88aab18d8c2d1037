"""Throughput bench: millions of targets through the exported leg core in a C++ Verilator testbench.

cocotb drives every cycle from Python (~25k cycles/s); this bench moves the whole loop into C++.
The expected outputs come from the golden integer model (:func:`ikseries.sim.golden.outputs`),
computed in numpy and written with the targets to a binary vectors file; the testbench streams
the targets into the exported Verilog (:func:`ikseries.hdl.export.leg_verilog` ports ``i_valid``,
``i_ready``, ``i_<input>``, ``o_valid``, ``o_ready``, ``o_<servo>``), compares every output
transfer bit-exactly with the expected record and checks the latency of every target.

Vectors file: little-endian int64 records, one per target, ``[input..., expected output...]``
in plan order (:func:`write_vectors`).

Latency check: with ``stall`` (random ``o_ready`` low) the pipeline holds, so the bench counts
the cycles in which the pipeline advanced between a target's input transfer and its output
transfer; that count must equal ``latency`` for every target. Without stalls it is the plain
cycle count. "Advanced" is ``i_ready`` high for a core that takes a target every cycle, or
``advance="enable"``: ``~o_valid | o_ready``, the pipeline enable of any core with the
global-stall handshake, also one that takes a target every N cycles (the iterative CORDIC).

Besides the polynomial leg core, the tests run both CORDIC cores' flat stream tops through it
(:class:`~ikseries.fit.baselines.cordic.CordicPlan` gives the same stream fields).

Example::

    tb = build_testbench(plan, verilog_text, "leg_core", workdir)
    write_vectors(workdir / "v.bin", plan, targets, golden.outputs(plan, targets))
    res = run_testbench(tb, workdir / "v.bin", latency=core.latency, stall=0.25)
    assert res["mismatches"] == 0 and res["latency_errors"] == 0
"""
from __future__ import annotations

import dataclasses
import json
import string
import subprocess
import time
from pathlib import Path

import numpy as np

from ..fit.baselines.cordic import CordicPlan
from ..fit.plan import Plan, bits_for
from .runner import simulator_available
from .verilator_build import check_identifier, verilate

__all__ = ["VerilatorTestbench", "write_vectors", "testbench_cpp", "build_testbench", "run_testbench"]

MAX_REPORTED = 10   # mismatches / latency errors listed individually


@dataclasses.dataclass(frozen=True)
class VerilatorTestbench:
    """A built Verilator testbench for one plan's exported core."""
    binary: Path
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    build_s: float


def _fields(plan) -> tuple[list[tuple[str, int]], list[tuple[str, int]]]:
    """(name, width) of the stream's input and output fields: a :class:`Plan`'s, or those of a
    :class:`~ikseries.fit.baselines.cordic.CordicPlan` (the CORDIC core has the same stream fields)."""
    ins = [(i.name, i.width) for i in plan.inputs]
    if isinstance(plan, Plan):
        outs = [(o.name, plan.nodes[o.node].width) for o in plan.outputs]
    else:
        outs = [(s, bits_for(*plan.limits[s])[0]) for s in plan.servos]
    for n, w in ins + outs:
        if w > 64:
            raise ValueError(f"port widths must be <= 64 bits for this bench, not {w} (field {n!r})")
    return ins, outs


def write_vectors(path, plan: Plan | CordicPlan, targets: dict, expected: dict) -> int:
    """Write the vectors file; returns the number of records."""
    ins, outs = _fields(plan)
    cols = [np.asarray(targets[n], dtype=np.int64) for n, _ in ins] \
        + [np.asarray(expected[n], dtype=np.int64) for n, _ in outs]
    lens = {len(c) for c in cols}
    if len(lens) != 1:
        raise ValueError(f"targets and expected outputs must have one length, not {sorted(lens)}")
    np.column_stack(cols).astype("<i8").tofile(path)
    return lens.pop()


#: when the pipeline advances, per ``advance`` (C++ over the top's ports): "i_ready" for a core
#: that takes a target every cycle; "enable" for any core with the global-stall handshake (its
#: pipeline enable is ``~o_valid | o_ready``), such as one that takes a target every N cycles
ADVANCE = {"i_ready": "t->i_ready", "enable": "!t->o_valid || t->o_ready"}


#: the C++ testbench with ``string.Template`` placeholders: ``top`` (Verilog module), ``nin`` /
#: ``nout`` (input / output fields), ``max_reported``, ``drive`` (one line per input field),
#: ``check`` (one block per output field) and ``advance`` (an :data:`ADVANCE` expression)
TEMPLATE = Path(__file__).parent / "templates" / "verilator_bench.cpp"


def _mask(width: int) -> str:
    """C++ mask of the low ``width`` bits."""
    return "~0ULL" if width == 64 else f"0x{(1 << width) - 1:x}ULL"


def testbench_cpp(plan: Plan | CordicPlan, top: str, advance: str = "i_ready") -> str:
    """C++ source of the testbench for ``V<top>`` (see the module docstring): :data:`TEMPLATE`
    filled with the design's ports and widths; the latency is counted in cycles in which the
    pipeline advances (:data:`ADVANCE`)."""
    if advance not in ADVANCE:
        raise ValueError(f"advance must be one of {sorted(ADVANCE)}, not {advance!r}")
    ins, outs = _fields(plan)
    nin = len(ins)
    drive = "\n".join(f"        t->i_{n} = (uint64_t)rec[{k}] & {_mask(w)};" for k, (n, w) in enumerate(ins))
    check = "\n".join(
        f"            {{ uint64_t got = (uint64_t)t->o_{n}, exp = (uint64_t)rec[{nin + k}] & {_mask(w)};\n"
        f"              if (got != exp) mismatch(out_i, \"{n}\", got, exp); }}"
        for k, (n, w) in enumerate(outs))
    return string.Template(TEMPLATE.read_text()).substitute(
        top=top, nin=nin, nout=len(outs), max_reported=MAX_REPORTED, drive=drive, check=check,
        advance=ADVANCE[advance])


def build_testbench(plan: Plan | CordicPlan, verilog: str, top: str, workdir, *, cxx_opt: str = "-O2",
                    jobs: int = 2, advance: str = "i_ready") -> VerilatorTestbench:
    """Verilate ``verilog`` (module ``top``) with the testbench into ``workdir/obj/V<top>``.

    Raises ``RuntimeError`` if Verilator is unavailable or the build fails (quoting its output).
    """
    check_identifier(top)
    ok, why = simulator_available("verilator")
    if not ok:
        raise RuntimeError(why)
    ins, outs = _fields(plan)
    binary, build_s = verilate(verilog, top, testbench_cpp(plan, top, advance), "tb.cpp", workdir,
                               cxx_opt=cxx_opt, jobs=jobs)
    return VerilatorTestbench(binary, tuple(n for n, _ in ins), tuple(n for n, _ in outs), build_s)


def run_testbench(tb: VerilatorTestbench, vectors, latency: int, *, stall: float = 0.0, bubble: float = 0.0,
                  seed: int = 1, max_cycles: int | None = None, initiation_interval: int = 1) -> dict:
    """Run the testbench on a vectors file; returns its JSON result plus rates and wall time.

    ``stall``: probability of ``o_ready`` low in a cycle; ``bubble``: probability of
    ``i_valid`` low while targets remain. ``max_cycles`` (default: a generous bound from the
    record count and the core's ``initiation_interval``, cycles per target) stops a hung
    pipeline. Never raises on a mismatch: read ``mismatches``,
    ``latency_errors``, ``spurious_outputs`` and ``outputs_checked``.
    """
    for name, p in (("stall", stall), ("bubble", bubble)):
        if not 0.0 <= p < 1.0:
            raise ValueError(f"{name} must be a probability in [0, 1), not {p!r}")
    if isinstance(initiation_interval, bool) or not isinstance(initiation_interval, int) or initiation_interval < 1:
        raise ValueError(f"initiation_interval must be a positive integer, not {initiation_interval!r}")
    if isinstance(latency, bool) or not isinstance(latency, int) or latency < 1:
        raise ValueError(f"latency must be a positive integer, not {latency!r}")
    vectors = Path(vectors)
    rec = 8 * (len(tb.inputs) + len(tb.outputs))
    n = vectors.stat().st_size // rec
    if max_cycles is None:
        max_cycles = int((n * initiation_interval + latency + 16) / ((1 - stall) * (1 - bubble)) * 4) + 1000
    t0 = time.perf_counter()
    proc = subprocess.run([str(tb.binary), str(vectors), str(latency), repr(float(stall)), repr(float(bubble)),
                           str(seed), str(max_cycles)], stdin=subprocess.DEVNULL, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"testbench {tb.binary.name} failed (status {proc.returncode}): {proc.stderr.strip()}")
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    res["wall_seconds"] = round(wall, 3)
    res["targets_per_second"] = round(res["outputs_checked"] / res["loop_seconds"]) if res["loop_seconds"] else None
    res["cycles_per_second"] = round(res["cycles"] / res["loop_seconds"]) if res["loop_seconds"] else None
    res["complete"] = res["outputs_checked"] == res["targets"]
    res["passed"] = (res["complete"] and res["mismatches"] == 0 and res["latency_errors"] == 0
                     and res["spurious_outputs"] == 0)
    return res
