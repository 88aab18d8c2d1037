"""Yosys resource counts of the folded evaluator and of the shared hexapod core.

For the cylinder-leg plan: the FoldedEvaluator for a few multiplier counts (iCE40 and ECP5,
limbs of each family's DSP size), the fully pipelined PlanEvaluator for comparison (optional,
slow), and the 6-leg RobotCore (18 servos) on the iCE40's reference part. Prints a table and
writes JSON.

    .venv/bin/python bench/folded_area.py [--out docs/results/folded_area.json] [--ks 1 2 4] [--pipelined]
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import runpy
import time
from pathlib import Path

from amaranth.back import verilog

from ikseries.fit.fitter import fit_robot
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.hdl.folded import FoldedEvaluator, microcode_layout
from ikseries.hdl.limbmul import LimbMultiplier
from ikseries.hdl.pwm import ServoPWM
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.hdl.schedule import compile_program
from ikseries.hdl.shared import RobotCore
from ikseries.robot import load_preset
from ikseries.constraints.devices import dsp_size, reference_part
from ikseries.synth import synth_counts

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer


def measure(name, core, target, workdir: Path) -> dict:
    d = workdir / name
    d.mkdir(parents=True, exist_ok=True)
    v = d / "top.v"
    ports = None
    if isinstance(core, LimbMultiplier):   # its o.ready is a constant (always ready): list ports
        ports = [core.i.valid, core.i.ready, core.i.payload.as_value(), core.o.valid, core.o.payload]
    v.write_text(verilog.convert(core, name="top", emit_src=False, ports=ports))
    r = synth_counts(v, "top", [target], workdir=d / "synth")[target]
    row = {"design": name, "target": target, "counts": r["counts"], "seconds": r["seconds"]}
    for attr in ("latency", "initiation_interval", "refresh_hz"):
        if hasattr(core, attr):
            row[attr] = getattr(core, attr)
    ev = getattr(core, "evaluator", core)
    if isinstance(ev, FoldedEvaluator):
        p = ev.program
        row["program"] = {"steps": p.steps, "ops": len(p.ops), "muls": p.count("mul"),
                          "limbs": list(p.limbs), "store_width": p.store_width, "depth": p.depth,
                          "consts": p.n_consts, "acc_width": p.acc_width,
                          "microcode_bits": p.steps * microcode_layout(p).size}
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=FACTS["default_json"]("folded_area"))
    ap.add_argument("--work", default="build/folded_area")
    ap.add_argument("--ks", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--clock-mhz", type=float, nargs="+", default=[24.0, 48.0])
    ap.add_argument("--pipelined", action="store_true", help="also synthesise the pipelined PlanEvaluator")
    ap.add_argument("--only", nargs="+", help="synthesise only these designs (names as in the table)")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("folded_area", argv)
    work = Path(args.work).resolve()
    t0 = time.time()
    robot = load_preset("cylinder-leg")
    plan = fit_robot(robot)[0]
    print(f"plan: {len(plan.nodes)} nodes, {plan.count('mul')} mul, widest node "
          f"{max(n.width for n in plan.nodes)} bits (fit {time.time() - t0:.0f} s)")
    period = robot.hardware.pwm_period_ticks
    designs = {}
    for target in ("ice40", "ecp5"):
        for k in args.ks:
            designs[f"folded_k{k}_{target}"] = (target, lambda k=k, t=target: FoldedEvaluator(plan, k, dsp_size(t)))
    designs["hexapod_k2_ice40"] = ("ice40", lambda: RobotCore(plan, legs=6, period=period,
                                                              clock_hz=args.clock_mhz[0] * 1e6,
                                                              multipliers=2, dsp=dsp_size("ice40")))
    # parts of the hexapod core, to see where the area goes
    ref = compile_program(plan, 2, dsp_size("ice40"))
    width_bits = max(plan.nodes[o.node].width for o in plan.outputs)
    designs["part_limb_multiplier_ice40"] = ("ice40", lambda: LimbMultiplier(
        *ref.mul_widths, dsp_size("ice40"), ref.acc_width))
    designs["part_pwm_bank_6x3_ice40"] = ("ice40", lambda: ServoPWMBank(period, width_bits, 6, 3))
    designs["part_servo_pwm_x1_ice40"] = ("ice40", lambda: ServoPWM(period, width_bits))
    if args.pipelined:
        for target in ("ice40", "ecp5"):
            designs[f"pipelined_{target}"] = (target, lambda: PlanEvaluator(plan))
    rows = []
    for name, (target, make) in designs.items():
        if args.only and name not in args.only:
            continue
        core = make()
        rows.append(measure(name, core, target, work))
        if name.startswith("hexapod"):
            rows[-1]["refresh_hz_at"] = {f"{f:g} MHz": f * 1e6 / (6 * core.initiation_interval)
                                         for f in args.clock_mhz}
        print(rows[-1], flush=True)

    ice40 = reference_part("ice40")
    cap = ice40.capacities
    print()
    print(f"{'design':22} {'target':6} {'LUT':>6} {'FF':>6} {'carry':>6} {'DSP':>4} {'BRAM':>5} {'lat':>5} {'II':>5}")
    for r in rows:
        c = r["counts"]
        print(f"{r['design']:22} {r['target']:6} {c['LUT']:6} {c['FF']:6} {c['carry']:6} {c['DSP']:4} {c['BRAM']:5} "
              f"{r.get('latency', ''):>5} {r.get('initiation_interval', ''):>5}")
    for h in (r for r in rows if r["design"] == "hexapod_k2_ice40"):
        print(f"\nhexapod on {ice40.part}: {h['counts']['LUT']} LUT / {cap['LUT']}, {h['counts']['DSP']} DSP / {cap['DSP']}, "
              f"{h['counts']['BRAM']} BRAM / {cap['BRAM']}; refresh " +
              ", ".join(f"{v:.0f} Hz at {f}" for f, v in h["refresh_hz_at"].items()))
    out = FACTS["write_result"](args.out, {"plan_nodes": len(plan.nodes), "rows": rows}, run)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
