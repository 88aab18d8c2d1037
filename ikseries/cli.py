"""Command-line interface: ``ikseries presets | build | fit | eval | report | program | serve``."""
from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
import time
from pathlib import Path

__all__ = ["main"]


class CliError(Exception):
    pass


def _robot(args):
    from .robot import load_preset, load_robot
    if getattr(args, "robot", None) and getattr(args, "preset", None):
        raise CliError("give either a robot description file or --preset, not both")
    if getattr(args, "robot", None):
        return load_robot(args.robot)
    return load_preset(args.preset or "cylinder-leg")


def _jobs(args) -> int:
    """``--jobs``: processes for the servos of a fit (default: every core this process may use)."""
    from .fit.parallel import check_jobs, usable_cores
    if args.jobs is None:
        return usable_cores()
    try:
        return check_jobs(int(args.jobs))
    except ValueError:      # not an integer, or not positive: the rule is check_jobs'
        raise CliError(f"--jobs must be a positive integer (processes for the servos), not {args.jobs!r}") from None


def _progress(quiet):
    t0 = time.perf_counter()

    def say(msg):  # one write per line: synthesis reports progress from several threads
        if not quiet:
            sys.stderr.write(f"[{time.perf_counter() - t0:6.1f}s] {msg}\n")
            sys.stderr.flush()
    return say


def cmd_presets(args):
    from .robot import load_preset, preset_names
    for n in preset_names():
        print(f"{n}\t{load_preset(n).description}")


def _positive_int(text: str, option: str) -> int:
    """``text`` as an integer >= 1, or a CliError naming ``option`` and the value."""
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise CliError(f"{option} must be an integer >= 1, not {text!r}")
    return v


def _table_entries(text: str) -> int:
    from .robot_parts import MAX_TABLE_ENTRIES, TABLE_ENTRIES
    try:
        v = int(text)
    except ValueError:
        v = 0
    if not TABLE_ENTRIES <= v <= MAX_TABLE_ENTRIES:
        raise CliError(f"--table-entries must be an integer from {TABLE_ENTRIES} to {MAX_TABLE_ENTRIES}, not {text!r}")
    return v


def _hardware_overrides(robot, args):
    """``robot`` with the build's --architecture / --multipliers / --interval / --dsp / --fit-device /
    --products / --table-entries applied
    (validated). --fit-device also sets the DSP size to the device's family unless --dsp is given;
    --architecture other than fastest drops the description's hardware.fit_device."""
    from .constraints.devices import FIT_DEVICES
    from .fit.cost import COSTS
    from .robot import ARCHITECTURES, DSP_CHOICES, PRODUCTS, check_architecture_options, with_fit, with_hardware
    opts = {}
    if args.architecture is not None:
        if args.architecture not in ARCHITECTURES:
            raise CliError(f"--architecture must be one of {', '.join(ARCHITECTURES)}, not {args.architecture!r}")
        opts["architecture"] = args.architecture
        if args.architecture != "fastest" and args.fit_device is None:
            opts["fit_device"] = None
    if args.fit_device is not None:
        if args.fit_device not in FIT_DEVICES:
            raise CliError(f"--fit-device must be one of {', '.join(FIT_DEVICES)}, not {args.fit_device!r}")
        opts["fit_device"] = args.fit_device
        if args.dsp is None:
            opts["dsp"] = FIT_DEVICES[args.fit_device]
    for key in ("multipliers", "interval"):
        text = getattr(args, key, None)
        if text is not None:
            opts[key] = _positive_int(text, f"--{key}")
    if args.dsp is not None:
        if args.dsp not in DSP_CHOICES:
            raise CliError(f"--dsp must be one of {', '.join(DSP_CHOICES)}, not {args.dsp!r}")
        opts["dsp"] = args.dsp
    if getattr(args, "dsp_primitives", False):
        opts["dsp_primitives"] = True
    if getattr(args, "cost", None) is not None:
        if args.cost not in COSTS:
            raise CliError(f"--cost must be one of {', '.join(COSTS)}, not {args.cost!r}")
        opts["cost"] = args.cost
    if getattr(args, "products", None) is not None:
        if args.products not in PRODUCTS:
            raise CliError(f"--products must be one of {', '.join(PRODUCTS)}, not {args.products!r}")
        opts["products"] = args.products
    if getattr(args, "table_entries", None) is not None:
        opts["table_entries"] = _table_entries(args.table_entries)
    labels = {"architecture": "--architecture", "multipliers": "--multipliers", "interval": "--interval",
              "dsp": "--dsp", "fit_device": "--fit-device", "dsp_primitives": "--dsp-primitives", "cost": "--cost"}
    given = {k for k in ("architecture", "multipliers", "interval", "dsp", "fit_device")
             if getattr(args, k, None) is not None}
    if "dsp_primitives" in opts:        # its error names --dsp too
        given |= {"dsp_primitives", "dsp"}
    if "cost" in opts:                  # its errors name --architecture and --dsp too
        given |= {"cost", "architecture", "dsp"}
    if given & {"architecture", "fit_device"}:   # either names the other in the error
        given |= {"architecture", "fit_device"}
    fit = {k: opts.pop(k) for k in ("products", "table_entries") if k in opts}
    new = with_hardware(robot, {k: v for k, v in labels.items() if k in given}, **opts) if opts else robot
    check_architecture_options(new, set(opts), labels)
    return with_fit(new, **fit) if fit else new


def cmd_build(args):
    from .build import build, default_output_dir
    from .sim.runner import SIMULATORS
    robot = _hardware_overrides(_robot(args), args)
    out = Path(args.output) if args.output else default_output_dir(robot)
    if args.cocotb == "auto":
        sims = "auto"
    else:
        sims = [x for x in args.cocotb.split(",") if x and x != "none"]
        bad = [x for x in sims if x not in SIMULATORS]
        if bad:
            raise CliError(f"--cocotb must be auto, none or a list from {','.join(SIMULATORS)}, not {bad[0]!r}")
    board = _board_spec(robot, args)
    rep = build(robot, out, synth=not args.no_synth, vcd=args.vcd, cocotb=sims, progress=_progress(args.quiet),
                board=board, jobs=_jobs(args))
    choice = rep.core.choice
    print(f"{robot.name}: max error {rep.worst_error_pu:.3f} pu (tolerance {robot.fit.tolerance_pu:g}), "
          f"latency {choice.core.latency} cycles, {choice.candidate.describe()}, "
          f"every leg refreshed {choice.refresh_hz:,.0f} times/s, output in {out}/")
    if rep.board is not None:
        bits = rep.board.bitstream
        print(f"{bits.board}: bitstream {out}/bitstream/{bits.path.name}, Fmax {bits.fmax_mhz:g} MHz "
              f"(clock {rep.board.spec.clock_hz / 1e6:g} MHz); load it with `ikseries program {out}`")


def _board_spec(robot, args):
    """The validated ``--board`` part of a build (None without it), before any fit."""
    if args.board is None:
        for opt, given in (("--servo-pins", args.servo_pins), ("--baud", args.baud)):
            if given is not None:
                raise CliError(f"{opt} needs --board (a board to put the controller on), not {given!r} alone")
        return None
    from .boardbuild import DEFAULT_BAUD, BoardBuildError, board_spec
    pins = None if args.servo_pins is None else [p.strip() for p in args.servo_pins.split(",") if p.strip()]
    baud = DEFAULT_BAUD
    if args.baud is not None:
        try:
            baud = int(args.baud)
        except ValueError:
            raise CliError(f"--baud must be a positive integer (bits per second), not {args.baud!r}") from None
    try:
        return board_spec(robot, args.board, pins, baud)
    except BoardBuildError as e:
        raise CliError(str(e)) from None


def _eval_plan(robot, args, say):
    """(plan, line saying which plan it is) for ``ikseries eval`` (:func:`ikseries.plancache.find_plan`)."""
    from .plancache import PlanLookupError, find_plan
    try:
        return find_plan(robot, None if args.plan is None else Path(args.plan), say, _jobs(args))
    except PlanLookupError as e:
        raise CliError(str(e)) from None


def cmd_fit(args):
    from .fitcmd import FitCommandError, default_fit_dir, run_fit
    robot = _robot(args)
    out = Path(args.output) if args.output else default_fit_dir(robot, args.method)
    try:
        rec = run_fit(robot, args.method, out, progress=_progress(args.quiet), jobs=_jobs(args))
    except FitCommandError as e:
        raise CliError(str(e)) from None
    if args.method == "ikseries":
        worst = max(s["sampled_max_pu"] for s in rec["servos"])
        print(f"{robot.name}: ikseries fit, max error {worst:.3f} pu (tolerance {robot.fit.tolerance_pu:g}), "
              f"output in {out}/")
    elif args.method == "paper":
        worst = {m: max(s["max_error_pu"] for s in f["servos"].values()) for m, f in rec["methods"].items()}
        print(f"{robot.name}: paper max error {worst['paper']:.3f} pu, ikseries {worst['ikseries']:.3f} pu "
              f"(tolerance {robot.fit.tolerance_pu:g}), output in {out}/")
    else:
        print(f"{robot.name}: divided differences on {len(rec['cases'])} paths, output in {out}/")


def cmd_eval(args):
    import numpy as np

    from .kinematics import UnreachableError
    from .sim import golden
    robot = _robot(args)
    vals = args.values
    if len(vals) != len(robot.workspace.inputs):
        names = ", ".join(i.name for i in robot.workspace.inputs)
        raise CliError(f"eval needs {len(robot.workspace.inputs)} values ({names}) for {robot.name}, not {len(vals)}")
    if args.leg is not None or args.body:
        return _eval_leg(robot, args)
    for v, spec in zip(vals, robot.workspace.inputs):
        if not np.isfinite(v) or not spec.min <= v <= spec.max:
            raise CliError(f"{spec.name} must be within [{spec.min:g}, {spec.max:g}] {spec.unit}, not {v:g}")
    plan, which = _eval_plan(robot, args, _progress(args.quiet))
    ints = golden.quantize_inputs(plan, dict(zip([i.name for i in robot.workspace.inputs], [[v] for v in vals])))
    q = [float(ints[i.name][0]) * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]
    try:
        ref_q = robot.pulses_pu(*q)   # the reference at the input the hardware sees
    except UnreachableError as e:
        raise CliError(str(e)) from None
    outs = golden.outputs(plan, ints)
    print(which)
    print("input (port integers): " + ", ".join(f"{i.name}={int(ints[i.name][0])}" for i in robot.workspace.inputs)
          + "  = " + ", ".join(f"{i.name}={v:g} {i.unit}" for i, v in zip(robot.workspace.inputs, q)))
    print(f"{'servo':6} {'reference pu':>14} {'golden ticks':>13} {'golden pu':>11} {'error pu':>9}")
    for k, o in enumerate(plan.outputs):
        pu = outs[o.name][0] / o.ticks_per_pu
        print(f"{o.name:6} {float(ref_q[k]):14.4f} {int(outs[o.name][0]):13d} {pu:11.4f} {pu - float(ref_q[k]):+9.4f}")


def _eval_leg(robot, args):
    """``ikseries eval --leg NAME [--body]``: one leg's channels, the target in its leg frame
    or (``--body``) in the body frame; the core takes it in the leg's mount frame."""
    import numpy as np

    from .body import body_to_leg, mirror
    from .channels import channel_pulses_pu, channel_table
    from .kinematics import UnreachableError
    from .robot import RobotError
    from .sim import golden
    if robot.body is None:
        raise CliError(f"--leg and --body need a robot with a [body], which {robot.name} has not")
    if args.leg is None:
        raise CliError(f"--body needs --leg (one of {', '.join(robot.body.names)})")
    try:
        k, leg = robot.body.leg(args.leg)
    except RobotError as e:
        raise CliError(f"--{e}") from None
    given = [float(v) for v in args.values]
    target = [float(v) for v in (body_to_leg(leg, *given) if args.body else given)]
    for v, spec in zip(target, robot.workspace.inputs):
        if not np.isfinite(v) or not spec.min <= v <= spec.max:
            raise CliError(f"{spec.name} must be within [{spec.min:g}, {spec.max:g}] {spec.unit} in the leg frame of "
                           f"{leg.name}, not {v:g}" + (" (from the body-frame target)" if args.body else ""))
    plan, which = _eval_plan(robot, args, _progress(args.quiet))
    names = [i.name for i in robot.workspace.inputs]
    ints = golden.quantize_inputs(plan, dict(zip(names, ([v] for v in mirror(leg, *target)))))
    q = mirror(leg, *(float(ints[i.name][0]) * 2.0 ** -i.frac_bits for i in robot.workspace.inputs))
    try:
        ref = channel_pulses_pu(robot, k, *q)
    except UnreachableError as e:
        raise CliError(str(e)) from None
    outs = golden.robot_outputs(plan, channel_table(robot), np.array([k]), ints)
    print(which)
    print(f"leg {leg.name} ({leg.side}): " + (f"body ({', '.join(f'{v:g}' for v in given)}) mm -> " if args.body else "")
          + "leg frame (" + ", ".join(f"{float(v):.4g}" for v in q) + ") mm; port integers (mount frame): "
          + ", ".join(f"{n}={int(ints[n][0])}" for n in names))
    print(f"{'channel':8} {'reference pu':>14} {'golden ticks':>13} {'golden pu':>11} {'error pu':>9}")
    for j, o in enumerate(plan.outputs):
        pu = outs[o.name][0] / o.ticks_per_pu
        ch = k * len(plan.outputs) + j
        print(f"{ch:<3}{o.name:5} {float(ref[j]):14.4f} {int(outs[o.name][0]):13d} {pu:11.4f} {pu - float(ref[j]):+9.4f}")


def cmd_report(args):
    from .build import default_output_dir
    from .pnr_report import NoBuildError, report_build
    if not args.pnr:
        raise CliError("report needs --pnr (place-and-route on every device), the only report it makes so far")
    if not 0 <= args.seed < 2 ** 31:
        raise CliError(f"--seed must be an integer in [0, 2**31), not {args.seed}")
    bdir = Path(args.build_dir) if args.build_dir else default_output_dir(_robot(args))
    from .buildrecord import BuildRecordError
    try:
        pnr = report_build(bdir, seed=args.seed, progress=_progress(args.quiet))
    except (NoBuildError, BuildRecordError) as e:
        raise CliError(str(e)) from None
    for dev, r in pnr["devices"].items():
        if r["fits"]:
            u = r["utilisation"]
            print(f"{dev}: Fmax {r['fmax_mhz']:.1f} MHz ({'meets' if r['meets_clock'] else 'misses'} "
                  f"{r['clock_hz'] / 1e6:g} MHz), {u['LC']['used']} LC, {u['FF']['used']} FF, "
                  f"{u['DSP']['used']} DSP" + (", timing harness" if r["harness"] else ""))
        else:
            print(f"{dev}: {r['error']}")
    print(f"wrote {bdir / 'pnr.json'} and the place-and-route section of {bdir / 'report.md'}")


def _program_target(args) -> tuple[str, Path]:
    """(board name or file, bitstream) of ``ikseries program``: as given, or from the manifest
    of a build directory made with ``--board``."""
    path = Path(args.bitstream)
    if not path.is_dir():
        if args.board is None:
            raise CliError(f"--board is needed with a bitstream file ({args.bitstream}); a build directory "
                           "made with --board names its board itself")
        return args.board, path
    try:
        man = json.loads((path / "manifest.json").read_text())
        board_rec = man["board"]
    except (OSError, ValueError, KeyError):
        raise CliError(f"{args.bitstream} must be a bitstream or a build directory made with --board "
                       "(its manifest.json names the board), not a directory without one") from None
    from .boardbuild import BITSTREAM_DIR
    from .constraints.boards import board
    suffix = board(args.board or board_rec["board"]).bitstream_suffix
    return args.board or board_rec["board"], path / BITSTREAM_DIR / f"{man['module']}{suffix}"


def cmd_program(args):
    from .constraints.boards import BoardError, board
    from .program import ProgramError, program
    try:
        name, bitstream = _program_target(args)
        b = board(name)
    except BoardError as e:
        raise CliError(str(e)) from None
    args.bitstream = str(bitstream)
    try:
        program(b, args.bitstream, flash=args.flash)
    except ProgramError as e:    # the board or the tool failed, not the command line: status 1
        print(f"ikseries: error: {e}", file=sys.stderr)
        return 1
    print(f"loaded {args.bitstream} into the {b.name}'s {'flash' if args.flash else 'FPGA'}")
    return 0


def _board_manifest(build_dir: str, command: str) -> dict:
    """The manifest of a build directory made with ``--board`` (one line when it is not one)."""
    try:
        man = json.loads((Path(build_dir) / "manifest.json").read_text())
        man["board"]["controller_module"]
    except (OSError, ValueError, KeyError, TypeError):
        raise CliError(f"{command} needs a build directory made with `ikseries build --board`, not {build_dir!r} "
                       "(no manifest.json naming a board there)") from None
    return man


def _serve_arguments(args) -> list:
    """verilog, top, channels, divisor, period, clock of ``ikseries serve``: from the build
    directory's manifest, each replaced by its option where given."""
    explicit = (args.verilog, args.top, args.channels, args.divisor, args.period, args.clock_hz)
    if args.build is None:
        missing = [o for o, v in zip(("--verilog", "--top", "--channels", "--divisor", "--period", "--clock-hz"),
                                     explicit) if v is None]
        if missing:
            raise CliError(f"serve needs a build directory made with --board, or {', '.join(missing)}")
        return list(explicit)
    man = _board_manifest(args.build, "serve")
    b = man["board"]
    found = (str(Path(args.build) / f"{b['controller_module']}.v"), b["controller_module"], str(len(b["channels"])),
             str(b["uart_divisor"]), str(man["pwm"][0]["period_cycles"]), str(b["clock"]["achieved_hz"]))
    return [e if e is not None else f for e, f in zip(explicit, found)]


def cmd_serve(args):
    from .servecmd import ServeError, ServeFailed, parse_options, serve
    try:
        opts = parse_options(*_serve_arguments(args), args.workdir)
    except ServeError as e:
        raise CliError(str(e)) from None
    try:
        serve(opts, lambda line: print(line, flush=True), _progress(args.quiet))
    except ServeFailed as e:     # the simulator, not the command line: status 1
        print(f"ikseries: error: {e}", file=sys.stderr)
        return 1
    return 0


def _host(args, need_build: bool):
    """(controller, build info) of a host command; its errors one line."""
    from .host.controller import ControllerError
    from .hostcmd import HostCommandError, build_info, open_controller
    if need_build and args.build is None:
        raise CliError(f"{args.cmd} needs --build DIR (the build directory of the controller on the port: "
                       "its inputs and units)")
    try:
        info = None if args.build is None else build_info(args.build)
        for name, v in (("--baud", args.baud), ("--timeout", args.timeout)):
            if not v > 0:
                raise HostCommandError(f"{name} must be a positive number, not {v!r}")
        return open_controller(args.port, args.baud, args.timeout, info), info
    except (HostCommandError, ControllerError, ValueError) as e:
        raise CliError(str(e)) from None
    except OSError as e:      # pyserial's SerialException is an OSError
        raise CliError(f"cannot open {args.port}: {e}") from None


def _channel_list(ctl, channels: list[str]) -> list[int]:
    for c in channels:
        if not c.isdigit() or not int(c) < ctl.shape.channels:
            raise CliError(f"a channel must be an integer in [0, {ctl.shape.channels - 1}], not {c!r}")
    return [int(c) for c in channels] if channels else list(range(ctl.shape.channels))


def cmd_host(args):
    from .host.controller import ControllerError
    from .hostcmd import HostCommandError, port_targets, status_lines
    ctl, info = _host(args, need_build=args.cmd == "move")
    try:
        if args.cmd == "move":
            if not 0 <= args.leg < ctl.shape.legs:
                raise CliError(f"leg must be in [0, {ctl.shape.legs - 1}], not {args.leg}")
            ctl.move(args.leg, port_targets(info, args.values))
            print(f"leg {args.leg} moving to {' '.join(args.values)}")
        elif args.cmd in ("enable", "relax"):
            getattr(ctl, args.cmd)(_channel_list(ctl, args.channels))
            print(f"{'enabled' if args.cmd == 'enable' else 'relaxed'} channels {' '.join(args.channels) or 'all'}")
        else:
            print("\n".join(status_lines(ctl, info)))
    except (HostCommandError, ValueError) as e:
        raise CliError(str(e)) from None
    except ControllerError as e:     # the controller refused or did not answer: status 1
        print(f"ikseries: error: {e}", file=sys.stderr)
        return 1
    return 0


def _host_parser(sub, name: str, help: str):
    h = sub.add_parser(name, help=help)
    h.add_argument("--port", required=True, help="the controller's serial port (a board's, or the pty of "
                   "`ikseries serve`)")
    h.add_argument("--build", metavar="DIR", help="the build directory of the controller (made with --board): "
                   "inputs and units, and a check that the controller is this build's")
    h.add_argument("--baud", type=float, default=1e6, help="line rate (default 1000000)")
    h.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for each answer (default 1; "
                   "multiply by the slowdown `ikseries serve` reports)")
    return h


_JOBS_HELP = ("fit and certify up to N servos at once, each in a process of its own (default: every "
              "core this process may use; the plan is the same whatever N)")


def _parser() -> argparse.ArgumentParser:
    from . import __version__
    from .constraints.devices import FAMILIES, FIT_DEVICES, PNR_DEVICES, PRIMITIVES, PARTS
    p = argparse.ArgumentParser(prog="ikseries", description=__doc__)
    p.add_argument("--version", action="version", version=f"ikseries {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("presets", help="list the built-in robot descriptions")
    b = sub.add_parser("build", help="fit, generate Verilog + manifest + report")
    b.add_argument("robot", nargs="?", help="robot description (TOML); default: --preset cylinder-leg")
    b.add_argument("--preset", help="built-in robot name (see `ikseries presets`)")
    b.add_argument("-o", "--output", help="output directory (default build/<robot>)")
    b.add_argument("--no-synth", action="store_true", help="skip Yosys resource counts")
    b.add_argument("--vcd", action="store_true", help="also write sim.vcd, the waveform of the verification run")
    b.add_argument("--cocotb", metavar="SIMS", default="auto",
                   help="verify the exported Verilog with cocotb on these simulators: auto (every "
                        "installed one, the default), none, or a list such as icarus,verilator")
    b.add_argument("--architecture", metavar="ARCH",
                   help="override hardware.architecture: auto (smallest that meets hardware.min_refresh_hz), "
                        "pipelined, folded, modulo (a pipeline whose multipliers are shared: one target every "
                        "--interval cycles) or fastest (the fastest whose Yosys cell counts fit --fit-device)")
    b.add_argument("--multipliers", metavar="K", help="override hardware.multipliers: multipliers of the folded evaluator (needs architecture "
                        "folded; auto picks 1 or 2 itself)")
    b.add_argument("--interval", metavar="N", help="override hardware.interval: initiation interval of the "
                   "modulo-scheduled evaluator (needs architecture modulo; default 8)")
    b.add_argument("--dsp", metavar="FAMILY",
                   help=f"override hardware.dsp: {', '.join(FAMILIES)} (DSP multiplier size) or none (full width)")
    b.add_argument("--fit-device", metavar="DEVICE",
                   help="override hardware.fit_device (with --architecture fastest): "
                        f"{', '.join(FIT_DEVICES)}; also sets --dsp to the device's family unless --dsp is given")
    b.add_argument("--dsp-primitives", action="store_true",
                   help="override hardware.dsp_primitives: put a modulo, folded or shared core's products on instantiated "
                        + ", ".join(f"{FAMILIES[p.family].label} {p.name}" for p in PRIMITIVES.values()
                                    if p.role == "multiplier")
                        + " blocks with their own registers, and a modulo core's tables of "
                        + ", ".join(f"{p.min_depth}+ words on {FAMILIES[p.family].label} {p.name}"
                                    for p in PRIMITIVES.values() if p.role == "table")
                        + " block RAMs with their output register (one more cycle per table read; needs --dsp "
                        + " or ".join(dict.fromkeys(p.family for p in PRIMITIVES.values())) + ")")
    b.add_argument("--cost", metavar="MODEL",
                   help="override hardware.cost: what the fit minimises per servo, multipliers (default) or device "
                        "(the share of the --dsp family's reference part the plan takes: DSP blocks, block RAM, "
                        "LUTs and FFs, each multiplier shared by --interval targets; needs architecture modulo "
                        "or pipelined)")
    b.add_argument("--products", metavar="MODE",
                   help="override fit.products: exact (default: every product as wide as it needs, split "
                        "into DSP-sized limbs in hardware) or dsp (operands narrowed to one --dsp block each)")
    b.add_argument("--table-entries", metavar="N",
                   help="override fit.table_entries: coefficient-table entries per servo, 16 (default) to 4096; from "
                        "64 cells of computed features (e.g. rho2) too: fewer products, longer tables")
    b.add_argument("--board", metavar="BOARD",
                   help="also build the robot controller (host link, IK, servo controller) and its bitstream for "
                        "this board: a name (icebreaker, ulx3s-25f, ulx3s-85f) or a board file (.toml)")
    b.add_argument("--servo-pins", metavar="PINS",
                   help="with --board: the servo pins of channels 0, 1, ... (comma-separated; default: the "
                        "board's servo pins in order)")
    b.add_argument("--baud", metavar="N", help="with --board: the host link's bit rate (default 1000000)")
    b.add_argument("-j", "--jobs", metavar="N", help=_JOBS_HELP)
    b.add_argument("-q", "--quiet", action="store_true")
    f = sub.add_parser("fit", help="fit only (no hardware) by one method, with a report")
    f.add_argument("robot", nargs="?", help="robot description (TOML); default: --preset cylinder-leg")
    f.add_argument("--preset", help="built-in robot name (see `ikseries presets`)")
    f.add_argument("--method", choices=["ikseries", "paper", "divided-differences"], default="ikseries",
                   help="ikseries (automatic fit), paper (the integer power series paper's procedure "
                        "beside it) or divided-differences (planar-arm path mode)")
    f.add_argument("-o", "--output", help="output directory (default build/<robot>/fit-<method>)")
    f.add_argument("-j", "--jobs", metavar="N", help=_JOBS_HELP)
    f.add_argument("-q", "--quiet", action="store_true")
    e = sub.add_parser("eval", help="pulse of each servo: reference IK vs golden integer model")
    e.add_argument("--preset")
    e.add_argument("--robot", help="robot description (TOML)")
    e.add_argument("--plan", help="use this plan.json instead of fitting")
    e.add_argument("-j", "--jobs", metavar="N", help=_JOBS_HELP + "; only when it has to fit")
    e.add_argument("-q", "--quiet", action="store_true")
    e.add_argument("--leg", metavar="NAME", help="a robot with a [body]: the leg the target is for (its channels "
                   "are shown: mirror and channel table applied); the target is in its leg frame (a left leg's "
                   "is mirrored, y -> -y)")
    e.add_argument("--body", action="store_true", help="with --leg: the target X Y Z is in the body frame")
    e.add_argument("values", type=float, nargs="+", metavar="VALUE",
                   help="the target, one value per robot input (cylinder-leg: R THETA Z)")
    r = sub.add_parser("report", help="extra reports on a finished build (--pnr: place-and-route)")
    r.add_argument("build_dir", nargs="?", metavar="BUILD_DIR",
                   help="directory of an `ikseries build` (default build/<preset>)")
    r.add_argument("--pnr", action="store_true",
                   help="Yosys + nextpnr on "
                        + " and ".join(dict.fromkeys(PARTS[d.part].part for d in PNR_DEVICES.values()))
                        + ": Fmax and utilisation into "
                        "pnr.json and report.md")
    r.add_argument("--preset", help="with no BUILD_DIR: this preset's default build directory")
    r.add_argument("--seed", type=int, default=1, help="nextpnr placer seed (default 1)")
    r.add_argument("-q", "--quiet", action="store_true")
    from .constraints.boards import BOARD_NAMES
    g = sub.add_parser("program", help="load a bitstream into a board with openFPGALoader")
    g.add_argument("bitstream", metavar="BITSTREAM", help="the .bin (iCE40) or .bit (ECP5) file, or a build "
                   "directory made with --board")
    g.add_argument("--board", help=f"{', '.join(BOARD_NAMES)} or a board file (.toml); default: the build "
                   "directory's board")
    g.add_argument("--flash", action="store_true", help="write the board's SPI flash (kept at power-off) "
                   "instead of the FPGA's configuration memory")
    v = sub.add_parser("serve", help="simulate a board-level design behind a pseudo-terminal: drive it with the "
                       "host tools before flashing, see its servo pulses")
    v.add_argument("build", nargs="?", metavar="BUILD_DIR", help="a build directory made with --board: its "
                   "robot controller, channels, UART divisor, PWM period and clock (each option below replaces one)")
    v.add_argument("--verilog", help="the design's exported Verilog (rx, tx, pwm, clk, rst ports)")
    v.add_argument("--top", help="its top module")
    v.add_argument("--channels", help="servo channels: the width of its pwm port")
    v.add_argument("--divisor", help="UART clock cycles per bit of the design")
    v.add_argument("--period", help="PWM period in clock cycles")
    v.add_argument("--clock-hz", help="the board's clock, for pulse widths in µs and the speed")
    v.add_argument("--workdir", help="build the model here and keep it (a rerun rebuilds only what changed); "
                   "default: a temporary directory removed at exit")
    v.add_argument("-q", "--quiet", action="store_true", help="no build progress or speed lines on stderr")
    m = _host_parser(sub, "move", "move one leg's tip to a target (values in the robot's units)")
    m.add_argument("leg", type=int, help="leg index")
    m.add_argument("values", nargs="+", metavar="VALUE", help="one value per robot input, in its unit")
    _host_parser(sub, "status", "the controller's identity, error counters and every channel's pulses")
    for name, what in (("enable", "start sending pulses"), ("relax", "stop sending pulses (servos go limp)")):
        e = _host_parser(sub, name, f"{what} on channels")
        e.add_argument("channels", nargs="*", metavar="CHANNEL", help="channel numbers (default: all)")
    return p


@contextlib.contextmanager
def _signals_interrupt():
    """Within this context SIGINT and SIGTERM raise KeyboardInterrupt (carrying the signal
    number) in the main thread, so every ``finally`` runs: an interrupted build removes its
    temporary directory. Signals after the first are ignored, so that cleanup finishes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    sigs = (signal.SIGINT, signal.SIGTERM)

    def interrupt(signum, frame):
        for s in sigs:
            signal.signal(s, signal.SIG_IGN)
        raise KeyboardInterrupt(signum)
    old = {s: signal.signal(s, interrupt) for s in sigs}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def main(argv=None):
    """The ``ikseries`` command; returns its exit status."""
    from .memory import keep_freed_memory
    from .threads import single_threaded_blas
    single_threaded_blas()       # before anything imports numpy
    keep_freed_memory()          # the fitter's arrays reuse freed memory, not fresh pages
    args = _parser().parse_args(argv)
    try:
        with _signals_interrupt():
            return _dispatch(args)
    except KeyboardInterrupt as e:
        signum = e.args[0] if e.args and isinstance(e.args[0], int) else signal.SIGINT
        print("ikseries: interrupted", file=sys.stderr)
        return 128 + int(signum)


def _dispatch(args) -> int:
    from .build import BuildError
    from .pnr import PnrError
    from .robot import RobotError
    try:
        status = {"presets": cmd_presets, "build": cmd_build, "fit": cmd_fit, "eval": cmd_eval,
                  "report": cmd_report, "program": cmd_program,
                  "serve": cmd_serve, "move": cmd_host, "status": cmd_host, "enable": cmd_host,
                  "relax": cmd_host}[args.cmd](args)
    except (CliError, RobotError) as exc:
        print(f"ikseries: error: {exc}", file=sys.stderr)
        return 2
    except (BuildError, PnrError) as exc:
        print(f"ikseries: error: {exc}", file=sys.stderr)
        return 1
    return status or 0


if __name__ == "__main__":
    sys.exit(main())
