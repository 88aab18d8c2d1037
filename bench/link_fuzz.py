"""The frame receiver against the protocol model on a long seeded mix, and the link's area.

Feeds ``--bytes`` of valid, corrupted (flipped bit, truncated, other length, unknown command)
and garbage request traffic (``ikseries.linkcheck.mixed_stream``), with a receive-timeout pause
before about one byte in ``--pause-every``, to the simulated ``FrameReceiver`` of the hexapod
shape, in chunks of ``--chunk`` bytes (one simulation each, seeded per chunk), and compares
every frame and counter with the host parser's verdict (``FrameParser.pause`` at the pauses). Then
synthesises ``Link`` (and its parts) for iCE40 with Yosys, and places and routes ``Link`` in the
timing harness on an iCE40UP5K (logic cells, Fmax). Prints a table and writes JSON.

    python bench/link_fuzz.py [--bytes 100000] [--chunk 5000] [--pause-every 64] [--seed 1] [--no-synth]
                              [--out docs/results/link_fuzz.json]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import random
import runpy
import sys
import tempfile
import time
from pathlib import Path

from amaranth.back import verilog

from ikseries.hdl import protocol as P
from ikseries.hdl.link import FrameReceiver, FrameTransmitter, Link
from ikseries.hdl.uart import UARTRx, UARTTx, uart_divisor
from ikseries.linkcheck import mixed_stream, model_receiver, random_pauses, simulate_receiver
from ikseries.pnr import place_and_route
from ikseries.synth import synth_counts

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer
SHAPE = P.Shape(legs=6, coords=3, channels=18)
CLOCK_HZ, BAUD = 48e6, 1e6
PNR_DEVICE = "ice40-up5k-sg48"


def fuzz(nbytes: int, chunk: int, seed: int, pause_every: int) -> dict:
    totals = {"bytes": 0, "pauses": 0, "cycles": 0, "frames": 0, "mismatches": 0,
              "counters": dict.fromkeys(P.RECEIVER_COUNTERS, 0)}
    t0 = time.perf_counter()
    for k in range(-(-nbytes // chunk)):
        rng = random.Random(f"{seed}/{k}")
        data = mixed_stream(rng, SHAPE, min(chunk, nbytes - k * chunk))
        pauses = random_pauses(rng, len(data), pause_every)
        frames, counters = model_receiver(SHAPE, data, pauses)
        got = simulate_receiver(SHAPE, data, pauses=pauses)
        totals["pauses"] += len(pauses)
        expect = {**counters, "framing": 0, "overrun": 0, "dropped": 0}
        bad = (got["frames"] != frames) + (got["counters"] != expect)
        totals["mismatches"] += bad
        totals["bytes"] += len(data)
        totals["cycles"] += got["cycles"]
        totals["frames"] += len(frames)
        for name, v in got["counters"].items():
            totals["counters"][name] += v
        print(f"chunk {k}: {len(data)} bytes, {len(frames)} frames, {'ok' if not bad else 'MISMATCH'}", flush=True)
    seconds = time.perf_counter() - t0
    return {**totals, "seconds": round(seconds, 1), "bytes_per_s": round(totals["bytes"] / seconds),
            "cycles_per_s": round(totals["cycles"] / seconds)}


def area(workdir: Path) -> list[dict]:
    divisor = uart_divisor(CLOCK_HZ, BAUD)
    designs = {"Link": Link(SHAPE, divisor), "UARTRx": UARTRx(divisor), "UARTTx": UARTTx(divisor),
               "FrameReceiver": FrameReceiver(SHAPE), "FrameTransmitter": FrameTransmitter(),
               "Link, 8-bit counters": Link(SHAPE, divisor, counter_bits=8)}
    rows = []
    for k, (name, design) in enumerate(designs.items()):
        d = workdir / f"d{k}"
        d.mkdir(parents=True)
        (d / "top.v").write_text(verilog.convert(design, name="top", emit_src=False))
        r = synth_counts(d / "top.v", "top", ["ice40"], workdir=d / "synth")["ice40"]
        rows.append({"design": name, "counts": r["counts"], "seconds": r["seconds"]})
        print(rows[-1], flush=True)
    return rows


def link_pnr(workdir: Path) -> dict:
    """``Link`` placed and routed in the timing harness (its ports exceed the package's pins)."""
    v = verilog.convert(Link(SHAPE, uart_divisor(CLOCK_HZ, BAUD)), name="top", emit_src=False)
    r = place_and_route(v, "top", PNR_DEVICE, int(CLOCK_HZ), workdir, harness=True)
    u = r.utilisation
    out = {"device": PNR_DEVICE, "fmax_mhz": r.fmax_mhz, "harness_ffs": r.harness_ffs,
           **{k: u[k]["used"] for k in ("LC", "LUT", "FF", "BRAM")}}
    print(out, flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bytes", type=int, default=100_000)
    ap.add_argument("--chunk", type=int, default=5_000)
    ap.add_argument("--pause-every", type=int, default=64)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-synth", action="store_true")
    ap.add_argument("--out", default=FACTS["default_json"]("link_fuzz"))
    args = ap.parse_args(argv)
    for name in ("bytes", "chunk", "pause_every"):
        if getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be a positive integer, not {getattr(args, name)}")
    run = FACTS["run_facts"]("link_fuzz", argv)
    result = fuzz(args.bytes, args.chunk, args.seed, args.pause_every)
    rows, pnr = [], None
    if not args.no_synth:
        with tempfile.TemporaryDirectory() as tmp:
            rows = area(Path(tmp))
            pnr = link_pnr(Path(tmp) / "pnr")
    print()
    print(f"{result['bytes']} bytes, {result['pauses']} pauses, {result['frames']} good frames, {result['mismatches']} mismatching chunks, "
          f"{result['seconds']} s ({result['bytes_per_s']} bytes/s, {result['cycles_per_s']} cycles/s simulated)")
    print("counters: " + ", ".join(f"{k} {v}" for k, v in result["counters"].items()))
    if rows:
        print(f"\n{'design':24} {'LUT':>5} {'FF':>5} {'carry':>5} {'BRAM':>5}")
        for r in rows:
            c = r["counts"]
            print(f"{r['design']:24} {c['LUT']:5} {c['FF']:5} {c['carry']:5} {c['BRAM']:5}")
    payload = {"shape": {"legs": SHAPE.legs, "coords": SHAPE.coords, "channels": SHAPE.channels},
               "seed": args.seed, "chunk": args.chunk, "pause_every": args.pause_every, "fuzz": result, "clock_hz": CLOCK_HZ, "baud": BAUD,
               "area_ice40": rows, "pnr_ice40": pnr}
    out = FACTS["write_result"](args.out, payload, run)
    print(f"wrote {out}")
    return 1 if result["mismatches"] else 0


if __name__ == "__main__":
    sys.exit(main())
