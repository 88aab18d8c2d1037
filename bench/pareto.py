"""Benchmark: area vs latency per target, polynomial vs CORDIC, from real place and route.

For the cylinder-leg robot, the IK cores alone (no PWM), as flat-port stream tops
(``ikseries.hdl.flat.stream_verilog``):

``pipelined``  the fully pipelined polynomial evaluator (``PlanEvaluator``, 1 target/clock);
``folded1``    ``FoldedEvaluator`` with 1 multiplier of the device's DSP size
               (the family's ``Family.dsp`` in ``ikseries.constraints.devices``);
``folded2``    the same with 2 multipliers;
``moduloN``    ``ModuloEvaluator``: the dataflow pipelined, its multiplications shared by a modulo
               schedule, one target every N cycles (N = 4, 8, 12; products gathered by the device's
               DSP size);
``moduloNd``   on the ECP5 only (N = 1, 4, 7, 16; N = 1 is one solution per clock): the plan fitted with ``fit.products = "dsp"`` (every
               product's operands narrowed to the ECP5's DSP size, so each is one DSP block),
               modulo-scheduled, every product an instantiated ECP5 DSP primitive using its own
               input and output registers (``dsp_registers="ecp5"``; Yosys would leave them in the
               fabric); simulated in cocotb with the primitive's model (``Primitive.model_path``,
               tests); its
               accuracy column is that plan's own;
``pipelinedt``, ``modulo1dt``, ``modulo4dt``  on the ECP5 only: ``pipelined``, ``modulo1d`` and
               ``modulo4d`` of plans fitted with ``fit.table_entries = 1024`` (cells of computed
               features such as rho2: fewer products, longer coefficient tables);
``modulo16t``  on the iCE40 only: one target per 16 cycles, the plan fitted with
               ``fit.table_entries = 256`` (what the part's block RAMs hold);
``cordic``     ``CordicLegSolver``, sized with ``size_cordic(margin_pu=0.075)`` (about 1.5 min)
               unless ``--cordic-design JSON`` gives the design; fully pipelined;
``cordic_iter`` the same design iterative: each CORDIC and the square root on one set of
               registers, one target every ``longest_loop`` cycles (17 for the sized design),
               the same values at the same latency;

and ``hexapod``: the hexapod preset's shared robot core (``RobotCore``: one folded evaluator
for 6 legs, the configuration ``choose_architecture`` picks, iCE40 DSP size, plus the 18-channel
PWM bank) on the iCE40 only (``robot_verilog``).

Each is placed and routed (``ikseries.pnr.place_and_route``) with each nextpnr placer seed of
``--seeds`` (default 1, 2, 3) on each device
(each of ``ikseries.constraints.devices.PNR_DEVICES``) with nextpnr ``--freq`` = ``--clock-mhz`` (default 100 MHz).
nextpnr reports the Fmax it achieved whether or not it meets the target; the target only
steers its timing-driven placement and routing, so the default is above every core's expected
Fmax (not the robots' 48 MHz) in case a lower one would let it stop early. Measured with the
installed ECP5 nextpnr (seed 1): folded2 and CORDIC reach the same Fmax (64.671, 104.471 MHz)
with ``--clock-mhz`` 48, 100 and 200. A design that does not fit is recorded with Yosys' counts
and the overflow. Per design and device the record reported is the median seed's (the lower
median: the placed seeds sorted by Fmax, the middle one, the slower of two), with every seed's
Fmax beside it (``fmax_by_seed``).
Accuracy: the polynomial plan's max |error| on the >= 10**6 verification points
(``ikseries.accuracy.measure``; bit-exact for the pipelined and folded cores alike) and its
certified bound; the CORDIC design's on the same points (``measure_cordic``).

Writes JSON (default ``docs/results/pareto.json``), a plot per device next to it
(``pareto_<device>.png``: area = LUT + FF from Yosys (LUT including the LUTs that carry cells
occupy, ``Family.ripple_luts``) with the timing harness' FFs removed on x,
latency in ns at Fmax on y, Pareto front of the placed cylinder-leg cores marked), and prints a table and
verdicts: the targets of "one leg solution per clock on a small FPGA" (one solution per clock on
the ECP5 part within its DSP blocks and block RAMs at >= 200 MHz and <= 100 ns, certified; the
hexapod core at 48 MHz with >= 15 % Fmax margin on the iCE40 part; the smallest single-leg core there
at one solution per <= 16 cycles), then the earlier ones (the fastest core's Fmax, latency and
throughput; the hexapod within the iCE40 part; polynomial against CORDIC).

    python bench/pareto.py [--devices ice40,ecp5]
                           [--designs pipelined,modulo4,modulo8,modulo12,modulo4d,modulo7d,modulo16d,folded1,folded2,cordic,cordic_iter,hexapod]
                           [--jobs 2] [--seeds 1,2,3]
                           [--clock-mhz 100] [--cordic-design JSON] [--out docs/results/pareto.json]
                           [--work build/bench/pareto] [--cost multipliers|device] [--merge]

``--cost device`` fits the ECP5 DSP-sized plans (``moduloNd``, ``moduloNdt``) with the ECP5's
device cost model at one target per clock (``hardware.cost = "device"``,
:class:`ikseries.fit.cost.DeviceCost`) instead of the multiplier count.
``--merge`` re-measures only the given designs: the records of every other (design, device) in
the existing ``--out`` are kept (plots and verdicts are recomputed over all of them), and the
run records of the runs they came from are listed under ``earlier_runs``.
"""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import argparse
import dataclasses
import json
import runpy
import sys
import time
import warnings
from pathlib import Path

from ikseries.constraints.devices import PARTS, PNR_DEVICES, dsp_size, family_primitives
from ikseries.pareto import DesignSpec, plot_device, run_matrix

FACTS = runpy.run_path(str(Path(__file__).with_name("facts.py")))   # run record, JSON writer

#: the place-and-route target of each family the verdicts are about
ICE40, ECP5 = (next(n for n, d in PNR_DEVICES.items() if d.family == f) for f in ("ice40", "ecp5"))
ECP5_PART = PARTS[PNR_DEVICES[ECP5].part].part
ECP5_PRIMITIVES = ", ".join(p.name for p in family_primitives("ecp5"))
MODULO_II = (4, 8, 12)
MODULO_DSP_II = (1, 4, 7, 16)   # ECP5 only: DSP-sized plan, DSP primitives with their own registers
#: the "t" designs: cores of plans fitted with long coefficient tables (cells of computed
#: features, fewer products): fit.table_entries per device family, as many as its block RAMs hold
LONG_TABLES = {"ecp5": 1024, "ice40": 256}
LONG_DESIGNS = ("pipelinedt", "modulo1dt", "modulo4dt", "modulo16t")
DESIGNS = ("pipelined", *(f"modulo{ii}" for ii in MODULO_II), *(f"modulo{ii}d" for ii in MODULO_DSP_II),
           *LONG_DESIGNS, "folded1", "folded2", "cordic", "cordic_iter", "hexapod")
CORDIC_DESIGNS = ("cordic", "cordic_iter")
DSP_DESIGNS = tuple(f"modulo{ii}d" for ii in MODULO_DSP_II)
POLY_DESIGNS = tuple(d for d in DESIGNS if d not in (*CORDIC_DESIGNS, "hexapod", *DSP_DESIGNS, *LONG_DESIGNS))
TARGET_FMAX_MHZ, TARGET_LATENCY_NS, TARGET_THROUGHPUT = 150.0, 200.0, 20e6
#: the hexapod target: within the iCE40 part's DSP blocks and logic cells, refreshing >= 1000/s
HEXAPOD_DSP, HEXAPOD_LC = (PARTS[PNR_DEVICES[ICE40].part].capacities[k] for k in ("DSP", "LUT"))
HEXAPOD_REFRESH_HZ = 1000.0
#: one solution per clock on the ECP5 part: its DSP blocks and block RAMs, Fmax, latency
ECP5_DSP, ECP5_BRAM = (PARTS[PNR_DEVICES[ECP5].part].capacities[k] for k in ("DSP", "BRAM"))
II1_FMAX_MHZ, II1_LATENCY_NS = 200.0, 100.0
#: the hexapod core on the iCE40 part: its clock and Fmax margin; the smallest single-leg core's
#: longest interval
HEXAPOD_CLOCK_MHZ, HEXAPOD_MARGIN = 48.0, 0.15
SMALL_CORE_II = 16


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _family(device: str) -> str:
    return PNR_DEVICES[device].family


# -- design specs ----------------------------------------------------------------------------------
def _spec(arch, plan, name: str, description: str, max_error_pu, extra: dict, devices=None) -> DesignSpec:
    """The spec of ``arch(dev)`` (an Architecture for a device) on ``plan``: its evaluator's
    Verilog, latency and interval from the architecture's timing."""
    from ikseries.hdl.flat import stream_verilog
    top = f"poly_{name}"
    kw = {"devices": devices} if devices else {}
    return DesignSpec(name, "polynomial", description,
                      lambda dev: (stream_verilog(arch(dev).evaluator(plan), top), top),
                      lambda dev: arch(dev).timing(plan).latency,
                      lambda dev: arch(dev).timing(plan).initiation_interval, max_error_pu, extra=dict(extra), **kw)


def polynomial_specs(plan, max_error_pu: float | None, names=POLY_DESIGNS,
                     extra: dict | None = None) -> list[DesignSpec]:
    """Specs of the pipelined, modulo-scheduled (II = MODULO_II) and folded (k = 1, 2) evaluators
    of ``plan``, multipliers of the device's DSP size."""
    from ikseries.hdl.architectures.modulo import Modulo
    from ikseries.hdl.architectures.pipelined import Pipelined

    extra = dict(extra or {})
    specs = []
    if "pipelined" in names:
        specs.append(_spec(lambda dev: Pipelined(), plan, "pipelined",
                           "polynomial, fully pipelined (PlanEvaluator)", max_error_pu, extra))
    for ii in MODULO_II:
        if f"modulo{ii}" in names:
            specs.append(_spec(lambda dev, ii=ii: Modulo(ii, _family(dev)), plan, f"modulo{ii}",
                               f"polynomial, modulo-scheduled, one target per {ii} cycles", max_error_pu, extra))
    return specs + folded_specs(plan, max_error_pu, names, extra)


def dsp_specs(plan, max_error_pu: float | None, names=DSP_DESIGNS, extra: dict | None = None) -> list[DesignSpec]:
    """Specs of the modulo-scheduled evaluators (II = MODULO_DSP_II) of a plan fitted with
    ``fit.products = "dsp"`` for the ECP5, every product on an instantiated DSP primitive."""
    from ikseries.hdl.architectures.modulo import Modulo

    return [_spec(lambda dev, ii=ii: Modulo(ii, "ecp5", primitives=True), plan, f"modulo{ii}d",
                  "polynomial, {}x{} products (fit.products = dsp), modulo-scheduled, ".format(*dsp_size("ecp5"))
                  + f"one target per {ii} cycles, {ECP5_PRIMITIVES} primitives with their registers",
                  max_error_pu, extra or {}, (ECP5,))
            for ii in MODULO_DSP_II if f"modulo{ii}d" in names]


def dsp_robot(robot, cost: str = "multipliers"):
    """``robot`` with ``fit.products = "dsp"`` on the ECP5 (the ``moduloNd`` plans); with
    ``cost`` "device" fitted by the ECP5's device model at one target per clock
    (``hardware.cost``, :class:`ikseries.fit.cost.DeviceCost` of its reference part, interval 1:
    the rate of ``modulo1d``)."""
    from ikseries.robot import with_fit, with_hardware
    r = with_fit(with_hardware(robot, dsp="ecp5"), products="dsp")
    return with_hardware(r, architecture="pipelined", cost="device") if cost == "device" else r


def long_table_specs(robot, names, fitted, cost: str = "multipliers") -> list[DesignSpec]:
    """The "t" designs of ``names``: on the ECP5, ``pipelined``, ``modulo1d`` and ``modulo4d``
    (``pipelinedt``, ...) of plans fitted (``fitted(robot, what, **extra)``) with
    ``fit.table_entries = LONG_TABLES["ecp5"]``; on the iCE40, ``modulo16t``: one target per 16
    cycles on multipliers of its DSP size, of the plan fitted with ``LONG_TABLES["ice40"]``."""
    from ikseries.hdl.architectures.modulo import Modulo
    from ikseries.robot import with_fit

    def note(family):
        return f"fit.table_entries = {LONG_TABLES[family]} (cells of computed features)"
    ecp5 = with_fit(robot, table_entries=LONG_TABLES["ecp5"])
    specs = []
    if "pipelinedt" in names:
        plan, worst, extra = fitted(ecp5, "ECP5 long-table plan", table_entries=LONG_TABLES["ecp5"])
        specs += [dataclasses.replace(sp, devices=(ECP5,), description=f"{sp.description}; {note('ecp5')}")
                  for sp in polynomial_specs(plan, worst, ("pipelined",), extra)]
    dsp = [n[:-1] for n in names if n[:-1] in DSP_DESIGNS]
    if dsp:
        plan, worst, extra = fitted(dsp_robot(ecp5, cost), "ECP5 long-table DSP-sized plan", products="dsp ({}x{})".format(*dsp_size("ecp5")),
                                    table_entries=LONG_TABLES["ecp5"])
        specs += [dataclasses.replace(sp, description=f"{sp.description}; {note('ecp5')}")
                  for sp in dsp_specs(plan, worst, dsp, extra)]
    if "modulo16t" in names:
        plan, worst, extra = fitted(with_fit(robot, table_entries=LONG_TABLES["ice40"]), "iCE40 long-table plan",
                                    table_entries=LONG_TABLES["ice40"])
        specs.append(_spec(lambda dev: Modulo(16, _family(dev)), plan, "modulo16",
                           f"polynomial, modulo-scheduled, one target per 16 cycles; {note('ice40')}", worst, extra,
                           (ICE40,)))
    return [dataclasses.replace(sp, name=sp.name + "t") for sp in specs]


def folded_specs(plan, max_error_pu: float | None, names, extra: dict) -> list[DesignSpec]:
    """Specs of the folded evaluators (k = 1, 2 multipliers of the device's DSP size)."""
    from ikseries.hdl.architectures.folded import Folded

    return [_spec(lambda dev, k=k: Folded(k, _family(dev)), plan, f"folded{k}",
                  f"polynomial, folded, {k} multiplier{'s' * (k > 1)} (device DSP size)", max_error_pu, extra)
            for k in (1, 2) if f"folded{k}" in names]


def cordic_spec(robot, design, max_error_pu: float, extra: dict, iterative: bool = False) -> DesignSpec:
    """Spec of the CORDIC leg solver of ``design``: pipelined, or iterative (each loop on one
    set of registers, a target every ``longest_loop`` cycles)."""
    from ikseries.hdl.cordic import CordicLegSolver
    from ikseries.hdl.flat import stream_verilog

    ii = CordicLegSolver(robot, design).longest_loop if iterative else 1
    name, top = ("cordic_iter", "cordic_iterative") if iterative else ("cordic", "cordic_solver")
    what = f"iterative, a target every {ii} cycles" if iterative else "fully pipelined"
    return DesignSpec(name, "cordic", f"CORDIC, {what} (CordicLegSolver, margin 0.075 pu)",
                      lambda dev: (stream_verilog(CordicLegSolver(robot, design, ii), top), top),
                      lambda dev: CordicLegSolver(robot, design, ii).latency, lambda dev: ii, max_error_pu,
                      extra=extra)


def hexapod_spec(clock_hz_for_refresh=None) -> DesignSpec:
    """Spec of the hexapod preset's shared core (the configuration ``choose_architecture`` picks)."""
    from ikseries.accuracy import measure
    from ikseries.architecture import build_target, choose_architecture
    from ikseries.fit.fitter import fit_robot
    from ikseries.hdl.export import robot_verilog
    from ikseries.robot import load_preset

    robot = load_preset("hexapod")
    plan, _ = fit_robot(robot)
    choice = choose_architecture(robot, plan)
    core = choice.core
    m = measure(robot, plan)
    cert = plan.meta.get("certificate", {})
    return DesignSpec(
        "hexapod", "robot", f"hexapod shared core: {choice.candidate.describe()}, {core.legs} legs, "
        f"{core.legs * len(core.servos)} PWM",
        lambda dev: (robot_verilog(choice.candidate.build(plan, build_target(robot)), "hexapod_core"),
                     "hexapod_core"),
        lambda dev: core.latency, lambda dev: core.initiation_interval,
        max(e["total"] for e in m["servos"].values()), devices=(ICE40,),
        extra={"legs": core.legs, "servos": core.legs * len(core.servos),
               "robot_clock_mhz": robot.hardware.clock_hz / 1e6, "multipliers": choice.candidate.multipliers,
               "architecture_reason": choice.reason,
               "max_error_pu_per_servo": {s: e["total"] for s, e in m["servos"].items()},
               "certified_pu": _certified(cert)})


def _certified(cert: dict) -> dict | None:
    """Certified |error| bound per servo (pu) from ``plan.meta["certificate"]``, if any."""
    servos = cert.get("servos") if isinstance(cert, dict) else None
    if not isinstance(servos, list):
        return None
    return {c["name"]: c["total_pu"] for c in servos if "name" in c and "total_pu" in c}


# -- verdicts --------------------------------------------------------------------------------------
def _by(records, device, kind=None):
    """Records of ``device`` (and ``kind``)."""
    return [r for r in records if r["device"] == device and (kind is None or r["kind"] == kind)]


def _check(name, v, op, t, unit) -> tuple[bool, str]:
    ok = v <= t if op == "<=" else v >= t
    u = f" {unit}" if unit else ""
    return ok, f"{name} {v:.4g}{u} {op} {t:g}{u}" + ("" if ok else f" (NOT MET by {abs(v - t):.4g}{u})")


def verdict_one_per_clock(records, tolerance_pu: float) -> list[str]:
    """One solution per clock (II = 1) on the ECP5 part: within its DSP blocks and block RAMs,
    Fmax and latency targets, certified within the tolerance; every II = 1 core's line."""
    cores = [r for r in _by(records, ECP5, "polynomial") if r["initiation_interval"] == 1]
    if not cores:
        return [f"one solution per clock on the {ECP5_PART}: no II = 1 core run - not decided"]
    lines, met = [f"one solution per clock on the {ECP5_PART} (DSP <= {ECP5_DSP}, BRAM <= {ECP5_BRAM}, "
                  f"Fmax >= {II1_FMAX_MHZ:g} MHz, latency <= {II1_LATENCY_NS:g} ns, certified <= "
                  f"{tolerance_pu:g} pu):"], []
    for r in cores:
        if r["status"] != "placed":
            over = ", ".join(f"{k} {o['used']}/{o['available']} ({o['used'] / o['available']:.1f}x)"
                             for k, o in (r["overflow"] or {}).items())
            lines.append(f"  {r['design']}: {r['status']} {over or r['error']} - NOT MET")
            continue
        cert = max((r.get("certified_pu") or {}).values(), default=None)
        checks = [_check("DSP", r["DSP"], "<=", ECP5_DSP, ""), _check("BRAM", r["BRAM"], "<=", ECP5_BRAM, ""),
                  _check("Fmax", r["fmax_mhz"], ">=", II1_FMAX_MHZ, "MHz"),
                  _check("latency", r["latency_ns"], "<=", II1_LATENCY_NS, "ns"),
                  (False, "not certified") if cert is None else _check("certified", cert, "<=", tolerance_pu, "pu")]
        ok = all(c[0] for c in checks)
        met += [r["design"]] if ok else []
        lines.append(f"  {r['design']}: " + "; ".join(c[1] for c in checks) + f" -> {'met' if ok else 'NOT MET'}")
    lines.append(f"  verdict: {'MET by ' + ', '.join(met) if met else 'NOT MET'}")
    return lines


def verdict_hexapod_margin(records) -> list[str]:
    """The hexapod core on the iCE40 part at 48 MHz with the Fmax margin."""
    hx = [r for r in records if r["design"] == "hexapod" and r["device"] == ICE40 and r["status"] == "placed"]
    if not hx:
        return [f"hexapod at {HEXAPOD_CLOCK_MHZ:g} MHz on the iCE40 part: not placed - not decided"]
    need = HEXAPOD_CLOCK_MHZ * (1 + HEXAPOD_MARGIN)
    ok, line = _check("Fmax", hx[0]["fmax_mhz"], ">=", round(need, 3), "MHz")
    return [f"hexapod core at {HEXAPOD_CLOCK_MHZ:g} MHz with >= {HEXAPOD_MARGIN:.0%} margin on the iCE40 part "
            f"({hx[0]['description']}): {line}, margin {hx[0]['fmax_mhz'] / HEXAPOD_CLOCK_MHZ - 1:+.1%} -> "
            f"{'MET' if ok else 'NOT MET'}"]


def verdict_small_core(records) -> list[str]:
    """A single-leg core on the iCE40 part at one solution per at most ``SMALL_CORE_II`` cycles:
    the smallest placed one (the part has too few DSP blocks for one solution per clock)."""
    cores = [r for r in _by(records, ICE40) if r["kind"] in ("polynomial", "cordic")
             and r["initiation_interval"] <= SMALL_CORE_II]
    placed = [r for r in cores if r["status"] == "placed"]
    head = f"single-leg core on the iCE40 part at one solution per <= {SMALL_CORE_II} cycles"
    if not placed:
        tried = ", ".join(f"{r['design']} ({r['status']})" for r in cores) or "none run"
        return [f"{head}: none placed ({tried}) - NOT MET"]
    r = min(placed, key=lambda r: (r["LC"], r["initiation_interval"]))
    return [f"{head}: the smallest placed is {r['design']}: {r['LC']} LC, {r['DSP']} DSP, {r['BRAM']} BRAM, "
            f"one solution per {r['initiation_interval']} cycles at {r['fmax_mhz']:.1f} MHz "
            f"({r['throughput_per_s'] / 1e6:.3g} M/s) -> MET"]


def verdict_ecp5_speed(records) -> list[str]:
    """Target 1: the fastest cylinder-leg configuration that fits the ECP5 part."""
    placed = [r for r in _by(records, ECP5) if r["kind"] != "robot" and r["status"] == "placed"]
    poly = [r for r in placed if r["kind"] == "polynomial"]
    if not poly:
        return [f"ECP5 speed target: no polynomial cylinder-leg core placed on the {ECP5_PART} - NOT MET"]
    # the target is ikseries' own core: the CORDIC baseline is compared in the third verdict
    best = max(poly, key=lambda r: (r["throughput_per_s"], -r["latency_ns"]))
    checks = [("Fmax", best["fmax_mhz"], ">=", TARGET_FMAX_MHZ, "MHz"),
              ("latency", best["latency_ns"], "<=", TARGET_LATENCY_NS, "ns"),
              ("throughput", best["throughput_per_s"] / 1e6, ">=", TARGET_THROUGHPUT / 1e6, "M/s")]
    lines = [f"ECP5 speed target (fastest = highest throughput among the placed polynomial cores): {best['design']}"]
    ok_all = True
    for name, v, op, t, unit in checks:
        ok = v >= t if op == ">=" else v <= t
        ok_all &= ok
        lines.append(f"  {name} {v:.4g} {unit} {op} {t:g} {unit}: "
                     + ("met" if ok else f"NOT MET (by {abs(v - t):.4g} {unit}, {abs(v - t) / t:.0%})"))
    nofit = [r for r in _by(records, ECP5) if r["kind"] != "robot" and r["status"] == "does-not-fit"]
    for r in nofit:
        lines.append(f"  {r['design']} does not fit: " + ", ".join(
            f"{k} {o['used']}/{o['available']} (+{o['over']}, {o['used'] / o['available']:.1f}x)"
            for k, o in r["overflow"].items()))
    also = [r["design"] for r in placed if r["fmax_mhz"] >= TARGET_FMAX_MHZ and r["latency_ns"] <= TARGET_LATENCY_NS
            and r["throughput_per_s"] >= TARGET_THROUGHPUT]
    lines.append(f"  verdict: {'MET' if ok_all else 'NOT MET'}; placed cores meeting all three: "
                 f"{', '.join(also) or 'none'}")
    if not ok_all:    # the polynomial core nearest to all three (its worst ratio to a target)
        def shortfall(r):
            return max(TARGET_FMAX_MHZ / r["fmax_mhz"], r["latency_ns"] / TARGET_LATENCY_NS,
                       TARGET_THROUGHPUT / r["throughput_per_s"])
        p = min(poly, key=shortfall)
        lines.append(f"  nearest polynomial core: {p['design']}: Fmax {p['fmax_mhz']:.1f} MHz "
                     f"({p['fmax_mhz'] / TARGET_FMAX_MHZ:.0%} of the target), latency {p['latency_ns']:.0f} ns "
                     f"({p['latency_ns'] / TARGET_LATENCY_NS:.2f}x the target), "
                     f"{p['throughput_per_s'] / 1e6:.3g} M/s ({p['throughput_per_s'] / TARGET_THROUGHPUT:.2f}x)")
    return lines


def verdict_hexapod(records) -> list[str]:
    """Target 2: the hexapod on one iCE40 part refreshing the whole robot >= 1000/s."""
    hx = [r for r in records if r["design"] == "hexapod" and r["device"] == ICE40]
    if not hx:
        return ["hexapod target: not run"]
    r = hx[0]
    if r["status"] != "placed":
        over = ", ".join(f"{k} {o['used']}/{o['available']} (+{o['over']})" for k, o in (r["overflow"] or {}).items())
        return [f"hexapod target: {r['status']} {over or r['error']} - NOT MET"]
    refresh = r["refresh_hz_at_fmax"]
    dsp_ok, lc_ok, hz_ok = r["DSP"] <= HEXAPOD_DSP, r["LC"] <= HEXAPOD_LC, refresh >= HEXAPOD_REFRESH_HZ
    core_lc = r["LC"] - r["harness_ffs"]
    return [f"hexapod target ({r['description']}):",
            f"  DSP {r['DSP']} <= {HEXAPOD_DSP}: {'met' if dsp_ok else 'NOT MET'}",
            f"  logic cells {r['LC']} <= {HEXAPOD_LC} (timing harness included; {r['harness_ffs']} harness "
            f"FFs, so about {core_lc} without it): {'met' if lc_ok else 'NOT MET'}",
            f"  whole-robot refresh at Fmax {r['fmax_mhz']:.1f} MHz: {refresh:,.0f} /s >= {HEXAPOD_REFRESH_HZ:g}: "
            f"{'met' if hz_ok else 'NOT MET'} ({refresh / HEXAPOD_REFRESH_HZ:.1f}x); at the robot's "
            f"{r['robot_clock_mhz']:g} MHz PWM clock: {r['refresh_hz_at_robot_clock']:,.0f} /s; Fmax "
            f"{'>=' if r['fmax_mhz'] >= r['robot_clock_mhz'] else '<'} {r['robot_clock_mhz']:g} MHz",
            f"  verdict: {'MET' if dsp_ok and lc_ok and hz_ok else 'NOT MET'}"]


def _against(poly, c) -> tuple[list[str], list[str]]:
    """One line per polynomial core against CORDIC record ``c`` (LUT, DSP, latency decide;
    where it still loses, FF, BRAM, Fmax, throughput, accuracy, is said with the ratio), and
    the winners."""
    lines, winners = [], []
    for p in sorted(poly, key=lambda r: r["latency_ns"]):
        lut, dsp, lat = p["LUT"] < c["LUT"], p["DSP"] <= c["DSP"], p["latency_ns"] <= c["latency_ns"]
        elsewhere = []
        if p["FF"] > c["FF"]:
            elsewhere.append(f"FF {p['FF']} vs {c['FF']} ({p['FF'] / c['FF']:.2g}x)")
        if p["BRAM"] > c["BRAM"]:
            elsewhere.append(f"BRAM {p['BRAM']} vs {c['BRAM']}")
        if p["fmax_mhz"] < c["fmax_mhz"]:
            elsewhere.append(f"Fmax {p['fmax_mhz']:.1f} vs {c['fmax_mhz']:.1f} MHz ({p['fmax_mhz'] / c['fmax_mhz']:.2g}x)")
        if p["throughput_per_s"] < c["throughput_per_s"]:
            elsewhere.append(f"throughput {p['throughput_per_s'] / 1e6:.4g} vs {c['throughput_per_s'] / 1e6:.4g} M/s "
                             f"({p['throughput_per_s'] / c['throughput_per_s']:.2g}x)")
        if p["max_error_pu"] > c["max_error_pu"]:
            elsewhere.append(f"max error {p['max_error_pu']:.4f} vs {c['max_error_pu']:.4f} pu")
        lines.append(f"  {p['design']}: LUT {p['LUT']} vs {c['LUT']} ({p['LUT'] - c['LUT']:+d}), DSP {p['DSP']} vs "
                     f"{c['DSP']} ({p['DSP'] - c['DSP']:+d}), latency {p['latency_ns']} vs {c['latency_ns']} ns "
                     f"({p['latency_ns'] / c['latency_ns']:.2f}x), FF {p['FF']} vs {c['FF']}, throughput "
                     f"{p['throughput_per_s'] / 1e6:.4g} vs {c['throughput_per_s'] / 1e6:.4g} M/s, max error "
                     f"{p['max_error_pu']:.4f} pu -> "
                     + ("wins" if lut and dsp and lat else "loses on " + ", ".join(
                         n for n, ok in (("LUT", lut), ("DSP", dsp), ("latency", lat)) if not ok))
                     + (f"; also loses on {'; '.join(elsewhere)}" if elsewhere else "")
                     + (f"; nextpnr's placed LUT slots say the opposite on LUT: LC {p['LC']} vs {c['LC']}"
                        if p.get("LC") and c.get("LC") and (p["LC"] < c["LC"]) != lut else ""))
        if lut and dsp and lat:
            winners.append(p["design"])
    return lines, winners


def _cordic_head(c) -> str:
    return (f"{c['LUT']} LUT, {c['DSP']} DSP, {c['latency_ns']} ns, {c['throughput_per_s'] / 1e6:.4g} M/s, "
            f"max error {c['max_error_pu']:.4f} pu")


def verdict_poly_vs_cordic(records) -> list[str]:
    """Target 3: polynomial < CORDIC in LUT and DSP on ECP5 at no worse latency, against the
    pipelined CORDIC (the issue's "CORDIC stages"); each core's line also says where else it
    loses and by how much. When the iterative CORDIC was placed too, the same comparison
    against it follows (a CORDIC at a throughput like the modulo cores')."""
    placed = [r for r in _by(records, ECP5, "cordic") if r["status"] == "placed"]
    cor = [r for r in placed if r["design"] == "cordic"]
    poly = [r for r in _by(records, ECP5, "polynomial") if r["status"] == "placed"]
    if not cor or not poly:
        return ["polynomial vs CORDIC on ECP5: needs a placed CORDIC and a placed polynomial core - not decided"]
    c = cor[0]
    lines = [f"polynomial vs CORDIC on ECP5 (pipelined CORDIC: {_cordic_head(c)}; LUT counts the LUTs of the "
             "carry chains):"]
    body, winners = _against(poly, c)
    lines += body
    lines.append(f"  verdict: {'MET by ' + ', '.join(winners) if winners else 'NOT MET'} (LUT and DSP each, "
                 "latency no worse)")
    summed = [p["design"] for p in poly if p["LUT"] + p["DSP"] < c["LUT"] + c["DSP"]
              and p["latency_ns"] <= c["latency_ns"]]
    lines.append(f"  read as the sum LUT + DSP ({c['LUT'] + c['DSP']} for CORDIC), latency no worse: "
                 + (f"met by {', '.join(summed)}" if summed else "not met")
                 + " (a DSP block counted as one LUT: this reading favours the DSP-heavy cores)")
    for it in (r for r in placed if r["design"] == "cordic_iter"):
        lines.append(f"against the iterative CORDIC (a target every {it['initiation_interval']} cycles: "
                     f"{_cordic_head(it)}):")
        body, winners = _against(poly, it)
        lines += body
        lines.append(f"  verdict: {'met by ' + ', '.join(winners) if winners else 'not met'} (LUT and DSP each, "
                     "latency no worse)")
    return lines


# -- table -----------------------------------------------------------------------------------------
COLUMNS = [("design", "{}", 10), ("device", "{}", 18), ("status", "{}", 12), ("Fmax", "{:.1f}", 7),
           ("LC", "{}", 6), ("LUT", "{}", 6), ("FF", "{}", 6), ("carry", "{}", 6), ("DSP", "{}", 4),
           ("BRAM", "{}", 4), ("area", "{}", 6), ("lat", "{}", 4), ("lat_ns", "{:.1f}", 8), ("II", "{}", 4),
           ("Msol/s", "{:.3g}", 7), ("err_pu", "{:.4f}", 7)]
KEYS = {"Fmax": "fmax_mhz", "lat": "latency_cycles", "lat_ns": "latency_ns", "II": "initiation_interval",
        "err_pu": "max_error_pu"}


def table(records) -> str:
    """Fixed-width table of the records; overflow listed below designs that did not fit."""
    lines = [" ".join(f"{n:>{w}}" for n, _, w in COLUMNS)]
    for r in records:
        cells = []
        for n, fmt, w in COLUMNS:
            v = r["throughput_per_s"] / 1e6 if n == "Msol/s" and r["throughput_per_s"] else r.get(KEYS.get(n, n))
            cells.append(f"{(fmt.format(v) if v is not None else '-'):>{w}}")
        lines.append(" ".join(cells))
        if r["overflow"]:
            lines.append(" " * 12 + "overflow: " + ", ".join(
                f"{k} {o['used']} of {o['available']} (+{o['over']}, {o['used'] / o['available']:.2f}x)"
                for k, o in r["overflow"].items())
                + (f" (LUT/FF counts include the timing harness: {r['harness_ffs']} FFs)" if r["harness"] else ""))
        if r["error"]:
            lines.append(" " * 12 + f"error: {r['error']}")
    return "\n".join(lines)


# -- seeds -----------------------------------------------------------------------------------------
def median_records(runs: list[list[dict]], seeds: list[int]) -> list[dict]:
    """One record per design and device from the runs of every seed (``runs[i]`` made with
    ``seeds[i]``, records in the same order): the median seed's, by Fmax among the seeds that
    placed it (the lower median), with ``fmax_by_seed`` (None where a seed did not place it);
    where no seed placed it, the first seed's record."""
    out = []
    for group in zip(*runs):
        placed = sorted(((r["fmax_mhz"], s, r) for s, r in zip(seeds, group) if r["status"] == "placed"),
                        key=lambda t: t[:2])
        _, seed, rec = placed[(len(placed) - 1) // 2] if placed else (None, seeds[0], group[0])
        out.append({**rec, "seed": seed, "fmax_by_seed": {str(s): r["fmax_mhz"] for s, r in zip(seeds, group)}})
    return out


# -- main ------------------------------------------------------------------------------------------
def _csv(value: str, allowed, what: str) -> list[str]:
    aliases = {"ice40": ICE40, "ecp5": ECP5}
    out = [aliases.get(v, v) for v in value.split(",") if v]
    for v in out:
        if v not in allowed:
            sys.exit(f"--{what} must be among {', '.join(allowed)}, not {v!r}")
    return out


def build_specs(designs, cordic_design: str | None, cost: str = "multipliers") -> tuple[list[DesignSpec], dict]:
    """Fit / size / measure what ``designs`` needs and return their specs and robot info."""
    from ikseries.accuracy import measure, verification_points
    from ikseries.fit.baselines.cordic import CordicDesign
    from ikseries.fit.baselines.cordic_sizing import measure_cordic, size_cordic
    from ikseries.architecture import cost_model
    from ikseries.fit.cost import DEFAULT_COST_MODEL
    from ikseries.fit.fitter import fit_robot
    from ikseries.robot import load_preset, with_fit

    robot = load_preset("cylinder-leg")
    info = {"robot": robot.name, "tolerance_pu": robot.fit.tolerance_pu}
    specs: list[DesignSpec] = []
    points = None

    def fitted(r, what: str, **extra):
        """Fit ``r``, measure it on the verification points; (plan, max error, spec extras)."""
        nonlocal points
        t0 = time.perf_counter()
        model = cost_model(r)       # the robot's: the multiplier count unless dsp_robot(..., "device")
        plan, _ = fit_robot(r, cost_model=model)
        if model != DEFAULT_COST_MODEL:
            extra = {**extra, "cost_model": model.record()}
        points = verification_points(robot) if points is None else points
        m = measure(r, plan, points)
        err = {s: e["total"] for s, e in m["servos"].items()}
        say(f"{what}: latency {plan.depth}, {plan.count('mul')} mul, max error "
            + ", ".join(f"{s} {e:.4f}" for s, e in err.items()) + f" pu ({time.perf_counter() - t0:.0f} s)")
        return plan, max(err.values()), {"max_error_pu_per_servo": err, "error_points": m["points"], **extra,
                                         "certified_pu": _certified(plan.meta.get("certificate", {}))}

    poly_names = [d for d in designs if d in POLY_DESIGNS]
    if poly_names:
        plan, worst, extra = fitted(robot, "polynomial plan")
        specs += polynomial_specs(plan, worst, poly_names, extra)
    dsp_names = [d for d in designs if d in DSP_DESIGNS]
    if dsp_names:
        plan, worst, extra = fitted(dsp_robot(robot, cost), "DSP-sized plan",
                                    products="dsp ({}x{})".format(*dsp_size("ecp5")))
        specs += dsp_specs(plan, worst, dsp_names, extra)
    long_names = [d for d in designs if d in LONG_DESIGNS]
    if long_names:
        specs += long_table_specs(robot, long_names, fitted, cost)
    cordic_names = [d for d in designs if d in CORDIC_DESIGNS]
    if cordic_names:
        points = verification_points(robot) if points is None else points
        if cordic_design:
            try:
                design = CordicDesign(**json.loads(cordic_design))
            except (ValueError, TypeError) as e:
                sys.exit(f"--cordic-design must be a JSON object of CordicDesign fields, not {cordic_design!r} ({e})")
            sized = "given with --cordic-design"
        else:
            say("sizing the CORDIC design (margin 0.075 pu, about 1.5 min) ...")
            design = size_cordic(robot, points, margin_pu=0.075, progress=say)
            sized = "size_cordic, margin 0.075 pu"
        m = measure_cordic(robot, design, points)
        err = {s: e["total"] for s, e in m["servos"].items()}
        say(f"CORDIC {design.as_dict()}: max error " + ", ".join(f"{s} {e:.4f}" for s, e in err.items()) + " pu")
        extra = {"cordic_design": design.as_dict(), "sized": sized, "max_error_pu_per_servo": err,
                 "error_points": m["points"]}
        specs += [cordic_spec(robot, design, max(err.values()), extra, iterative=n == "cordic_iter")
                  for n in cordic_names]
    if "hexapod" in designs:
        specs.append(hexapod_spec())
    return specs, info


def merge_records(out: Path, records: list[dict], seeds: list[int]) -> list[dict]:
    """Add to ``records`` (in place) those of the JSON ``out`` for every (design, device) not
    among them; the earlier run records those come from. Refuses other seeds (the table states
    one seed list for every row) or records of a design this script no longer has."""
    if not out.is_file():
        return []
    old = json.loads(out.read_text())
    if old.get("seeds") != seeds:
        sys.exit(f"--seeds must be those of {out} ({old.get('seeds')}) with --merge, not {seeds}")
    have = {(r["design"], r["device"]) for r in records}
    kept = [r for r in old["records"] if (r["design"], r["device"]) not in have]
    unknown = sorted({r["design"] for r in kept} - set(DESIGNS))
    if unknown:
        sys.exit(f"{out} holds records of designs this script does not have: {', '.join(unknown)}")
    records.extend(kept)
    return [old["run"], *old.get("earlier_runs", [])] if kept else []


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=f"{ICE40},{ECP5}", help="comma-separated (aliases: ice40, ecp5)")
    ap.add_argument("--designs", default=",".join(DESIGNS))
    ap.add_argument("--jobs", type=int, default=2, help="parallel place-and-route runs (1 or 2)")
    ap.add_argument("--clock-mhz", type=float, default=100.0, help="nextpnr --freq target")
    ap.add_argument("--cordic-design", default=None, help="CORDIC design as JSON (skips the sizing)")
    ap.add_argument("--seeds", default="1,2,3", help="nextpnr placer seeds (comma-separated); the median is reported")
    ap.add_argument("--out", default=FACTS["default_json"]("pareto"))
    ap.add_argument("--work", default="build/bench/pareto", help="place-and-route working directory")
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="seconds per tool run; a run that takes longer (nextpnr's router not converging "
                         "on a seed, say) is recorded as an error of that seed")
    ap.add_argument("--cost", default="multipliers", choices=("multipliers", "device"),
                    help="what the ECP5 DSP-sized plans (moduloNd, moduloNdt) are fitted to minimise: the "
                         "multipliers (default) or the ECP5's device model at one target per clock (dsp_robot)")
    ap.add_argument("--merge", action="store_true",
                    help="keep the other designs' records of the existing --out (re-measure only --designs)")
    args = ap.parse_args(argv)
    run = FACTS["run_facts"]("pareto", argv)
    # latency / initiation interval come from components that are built and never elaborated
    warnings.filterwarnings("ignore", message=".*created but never used")
    devices = _csv(args.devices, list(PNR_DEVICES), "devices")
    designs = _csv(args.designs, DESIGNS, "designs")
    if args.jobs not in (1, 2):
        sys.exit(f"--jobs must be 1 or 2, not {args.jobs}")
    if not args.timeout > 0:
        sys.exit(f"--timeout must be positive seconds, not {args.timeout}")
    if not args.clock_mhz > 0:
        sys.exit(f"--clock-mhz must be positive, not {args.clock_mhz}")
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or len(set(seeds)) != len(seeds):
        sys.exit(f"--seeds must be distinct integers separated by commas, not {args.seeds!r}")
    out = Path(args.out).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    specs, info = build_specs(designs, args.cordic_design, args.cost)
    if args.cost != "multipliers":
        info["cost"] = args.cost
    # the slowest runs first, so two jobs overlap well
    order = {"pipelined": 0, "cordic": 1, "hexapod": 2}
    specs.sort(key=lambda s: order.get(s.name, 3))
    clock_hz = int(round(args.clock_mhz * 1e6))
    runs = [run_matrix(specs, devices, clock_hz, Path(args.work).resolve() / f"seed{s}", jobs=args.jobs, seed=s,
                       timeout=args.timeout, progress=lambda m, s=s: say(f"seed {s}: {m}")) for s in seeds]
    records = median_records(runs, seeds)
    for r in records:
        if r["kind"] == "robot" and r["status"] == "placed":
            per = r["legs"] * r["initiation_interval"]
            r["refresh_hz_at_fmax"] = round(r["fmax_mhz"] * 1e6 / per, 1)
            r["refresh_hz_at_robot_clock"] = round(r["robot_clock_mhz"] * 1e6 / per, 1)
    earlier = merge_records(out, records, seeds) if args.merge else []
    devices = [d for d in PNR_DEVICES if d in devices or any(r["device"] == d for r in records)]
    rank = {d: i for i, d in enumerate(DESIGNS)}
    records.sort(key=lambda r: (devices.index(r["device"]), rank[r["design"]]))
    plots = {}
    for d in devices:
        png = out.with_name(f"{out.stem}_{d}.png")
        front = plot_device([r for r in records if r["kind"] != "robot"], d, png)
        plots[d] = {"png": str(png), "pareto_front": front}
    verdicts = {"one_per_clock": verdict_one_per_clock(records, info["tolerance_pu"]),
                "hexapod_margin": verdict_hexapod_margin(records), "small_core": verdict_small_core(records),
                "ecp5_speed": verdict_ecp5_speed(records), "hexapod": verdict_hexapod(records),
                "poly_vs_cordic": verdict_poly_vs_cordic(records)}
    result = {**info, "clock_target_mhz": args.clock_mhz, "seeds": seeds, "devices": devices,
              "area_metric": "LUT + FF - harness_ffs (Yosys counts)", "records": records, "plots": plots,
              "verdicts": verdicts, "seconds": round(time.perf_counter() - t0, 1),
              **({"earlier_runs": earlier} if earlier else {})}
    FACTS["write_result"](out, result, run)
    print(table(records))
    for d, p in plots.items():
        print(f"Pareto front on {d} (area, latency ns; cylinder-leg cores): {', '.join(p['pareto_front']) or '-'}")
    for lines in verdicts.values():
        print("\n".join(lines))
    print(f"wrote {out} and {', '.join(p['png'] for p in plots.values())}")
    return result


if __name__ == "__main__":
    main()
