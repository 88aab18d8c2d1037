"""Whole board tops: ``ikseries build --preset P --board B`` per case, the bitstream's Fmax
against the board clock and the device utilisation, from the build's own report.

The issue's cases by default: the ``hexapod`` preset on the iCEBreaker (iCE40UP5K) and
``cylinder-leg`` on the ULX3S-25F (ECP5). Each build fits, verifies the core in Amaranth,
exports the robot controller and runs Yosys, nextpnr and the packer (cocotb and the core's
resource counts are skipped: they do not change the top). Prints a table and writes JSON.

    python bench/board_tops.py [--case hexapod:icebreaker --case cylinder-leg:ulx3s-25f]
                               [--json docs/results/board_tops.json]
"""
from __future__ import annotations

import argparse
import json
import runpy
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer
CASES = ("hexapod:icebreaker", "cylinder-leg:ulx3s-25f")


def build(preset: str, board: str, out: Path) -> dict:
    """One build's board record (its report's ``board``), with its wall time; or its error."""
    t0 = time.perf_counter()
    cmd = [str(Path(sys.executable).with_name("ikseries")), "build", "--preset", preset, "--board", board, "--cocotb", "none",
           "--no-synth", "-q", "-o", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    seconds = round(time.perf_counter() - t0, 1)
    if r.returncode:
        return {"preset": preset, "board": board, "ok": False, "seconds": seconds,
                "error": (r.stderr or r.stdout).strip().splitlines()[-1:]}
    rep = json.loads((out / "report.json").read_text())
    b = rep["board"]
    return {"preset": preset, "board": board, "ok": True, "seconds": seconds, "clock_hz": b["clock"]["achieved_hz"],
            "fmax_mhz": b["fmax_mhz"], "meets_clock": b["meets_clock"], "utilisation": b["utilisation"],
            "channels": len(b["channels"]), "core_architecture": rep["architecture"],
            "bitstream_bytes": (out / b["bitstream"]).stat().st_size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", action="append", metavar="PRESET:BOARD",
                    help=f"a preset and a board (repeatable; default {' '.join(CASES)})")
    ap.add_argument("--json", default=FACTS["default_json"]("board_tops"))
    a = ap.parse_args(argv)
    cases = a.case or list(CASES)
    for c in cases:
        if c.count(":") != 1 or not all(c.split(":")):
            ap.error(f"--case must be PRESET:BOARD, not {c!r}")
    run = FACTS["run_facts"]("board_tops", argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, c in enumerate(cases):
            rows.append(build(*c.split(":"), Path(tmp) / f"b{k}"))
            print(json.dumps(rows[-1]), flush=True)
    print(f"\n{'preset':<14} {'board':<11} {'clock MHz':>9} {'Fmax MHz':>9} {'margin':>7} {'LC':>13} {'BRAM':>7} "
          f"{'DSP':>5}")
    for r in rows:
        if not r["ok"]:
            print(f"{r['preset']:<14} {r['board']:<11} FAILED: {r['error']}")
            continue
        u = r["utilisation"]
        print(f"{r['preset']:<14} {r['board']:<11} {r['clock_hz'] / 1e6:9.3f} {r['fmax_mhz']:9.3f} "
              f"{r['fmax_mhz'] * 1e6 / r['clock_hz'] - 1:7.1%} {u['LC']['used']:>6}/{u['LC']['available']:<6} "
              f"{u['BRAM']['used']:>3}/{u['BRAM']['available']:<3} {u['DSP']['used']:>2}/{u['DSP']['available']:<2}")
    out = FACTS["write_result"](a.json, {"cases": rows}, run)
    print(f"wrote {out}")
    return 0 if all(r["ok"] and r["meets_clock"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
