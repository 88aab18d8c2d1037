"""Place-and-route reports: achieved Fmax and placed utilisation from Yosys + nextpnr.

:func:`place_and_route` synthesises a Verilog design with YoWASP Yosys (via
:func:`ikseries.synth.synth_counts`, the family's :attr:`~ikseries.constraints.facts.Family.yosys`
command) and places and routes it with YoWASP nextpnr for one of
:data:`ikseries.constraints.devices.PNR_DEVICES` (each names its nextpnr arguments, the
package's user I/O pins and a clock pin of a common board).

nextpnr runs with ``--freq`` = the requested clock, a fixed ``--seed`` (the result is
deterministic for a given design, seed and tool version) and ``--timing-allow-fail`` (a design
that misses the clock still reports the Fmax it achieved; :attr:`PnrResult.meets_clock` says
whether it met it). Fmax is nextpnr's achieved frequency of the clock net driven by the clock
port: register-to-register paths only (paths from input pins and to output pins are not part
of a clock domain in nextpnr's analysis).

Pin placement: only the clock is constrained (the family's pin file,
:meth:`~ikseries.constraints.facts.Nextpnr.clock_constraint`), to a global-buffer-capable pin of
a common board; every other pin is placed by nextpnr (the file's ``...-allow-unconstrained``
argument).

Timing harness
--------------
A core with more port bits than the package has user I/O pins cannot be placed as it is. With
``harness=True`` (the default when the core's port bits exceed the device's user I/O) the core is
wrapped in a generated module, :data:`HARNESS_TOP`, with five pins: ``clk``, ``rst`` (both
passed to the core), ``din``, ``load`` and ``dout``. While ``load`` is low, ``din`` shifts into
a register chain whose bits drive every core input (stream payloads and the valid/ready handshake
included) and a second chain shifts the captured outputs out on ``dout``; while ``load`` is high
the inputs hold and every core output is captured into the second chain. Every core input
therefore comes from a register and every output ends in one, nothing can be optimised away, and
nextpnr reports the core's own register-to-register paths (the harness adds only one-LUT paths).
The harness costs one FF per core input bit and one FF plus about one LUT per output bit, included
in the reported utilisation (:attr:`PnrResult.harness_ffs`).

Does-not-fit
------------
Yosys' cell counts are compared with the device's ``cell_limits`` before nextpnr runs (hard
blocks exactly; LUTs and FFs each against the logic cells, a necessary condition); nextpnr's
own "Device utilisation" is parsed if it still fails to place. Either way
:class:`DoesNotFitError` names each exceeded resource with used, available and the excess.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from .constraints.devices import PNR_DEVICES, PnrDevice, family as device_family, pnr_families
from .synth import SynthError, synth_counts
from .wasm_cache import warm_nextpnr

__all__ = ["HARNESS_TOP", "PnrError", "DoesNotFitError", "PnrResult", "Port",
           "verilog_ports", "harness_verilog", "nextpnr_command", "place_and_route"]

HARNESS_TOP = "ikseries_pnr_harness"


class PnrError(RuntimeError):
    """Synthesis or place-and-route failed (the message quotes the end of the tool's log)."""


class DoesNotFitError(PnrError):
    """The design needs more of some resource than the device has.

    ``overflow`` maps each exceeded resource to ``(used, available)``.
    """

    def __init__(self, device: str, top: str, overflow: dict[str, tuple[int, int]], stage: str):
        self.device = device
        self.top = top
        self.overflow = dict(overflow)
        self.stage = stage
        parts = [f"{k} {u} used of {a} available ({u - a} over)" for k, (u, a) in self.overflow.items()]
        super().__init__(f"design {top!r} does not fit {device}: " + ", ".join(parts) + f" ({stage})")


@dataclasses.dataclass(frozen=True)
class Port:
    name: str
    direction: str   # "input" | "output" | "inout"
    width: int


@dataclasses.dataclass(frozen=True)
class PnrResult:
    """Outcome of one place-and-route run (only designs that fit produce one).

    ``utilisation`` maps a resource to ``{"used": n, "available": m}``: the device's ``bels``
    columns (``LC``: :attr:`~ikseries.constraints.facts.Family.lc_note`) are from nextpnr's
    placed design, ``FF`` from Yosys where nextpnr reports none; ``LUT`` and ``carry`` are Yosys
    counts (:func:`ikseries.synth.categorise`: ``LUT`` includes the LUTs carry cells occupy;
    carry: cells of :attr:`~ikseries.constraints.facts.Family.carry_bits` bits each).
    """
    device: str
    top: str
    clock_hz: int
    seed: int
    harness: bool
    port_bits: int
    harness_ffs: int
    fmax_mhz: float
    utilisation: dict
    synth_cells: dict
    nextpnr_utilisation: dict
    critical_path: dict
    seconds: dict

    @property
    def fits(self) -> bool:
        return True

    @property
    def meets_clock(self) -> bool:
        return self.fmax_mhz * 1e6 >= self.clock_hz

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d.update(fits=True, meets_clock=self.meets_clock)
        return d


# -- Verilog ports and the harness -----------------------------------------------------------------

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_$]*")
_DECL = re.compile(r"\b(input|output|inout)\b\s*(?:wire\b|reg\b|logic\b)?\s*(?:signed\b)?\s*"
                   r"(?:\[\s*(-?\d+)\s*:\s*(-?\d+)\s*\])?\s*([A-Za-z_][\w$]*(?:\s*,\s*(?!input|output|inout)"
                   r"[A-Za-z_][\w$]*)*)")


def _module_text(verilog: str, top: str) -> str | None:
    m = re.search(rf"^\s*module\s+{re.escape(top)}\s*(?:#\s*\(.*?\)\s*)?\((.*?)^\s*endmodule\b",
                  verilog, re.M | re.S)
    return m.group(0) if m else None


def verilog_ports(verilog: str, top: str) -> list[Port]:
    """Ports of module ``top`` in ``verilog`` (ANSI or non-ANSI declarations, constant ranges).

    Raises ``ValueError`` if the module is missing, :class:`PnrError` if a port's declaration
    cannot be read.
    """
    text = _module_text(verilog, top)
    if text is None:
        found = re.findall(r"^\s*module\s+([A-Za-z_][\w$]*)", verilog, re.M)
        raise ValueError(f"top must be a module of the Verilog {found}, not {top!r}")
    text = re.sub(r"//[^\n]*|/\*.*?\*/|\(\*\s*[A-Za-z_].*?\*\)", " ", text, flags=re.S)
    header = re.match(r"\s*module\s+\S+\s*(?:#\s*\(.*?\)\s*)?\((.*?)\)\s*;", text, re.S)
    if header is None:
        raise PnrError(f"cannot read the port list of module {top!r}")
    decls: dict[str, Port] = {}
    for d, msb, lsb, names in _DECL.findall(text):
        width = abs(int(msb) - int(lsb)) + 1 if msb else 1
        for n in re.split(r"\s*,\s*", names.strip()):
            decls.setdefault(n, Port(n, d, width))
    # each comma-separated header item ends with its port name ("a" or "input [3:0] a")
    order = [_IDENT.findall(x)[-1] for x in header.group(1).split(",") if _IDENT.search(x)]
    ports = []
    for n in order:
        if n not in decls:
            raise PnrError(f"cannot find the direction and width of port {n!r} of module {top!r}")
        ports.append(decls[n])
    return ports


def harness_verilog(ports: list[Port], top: str, clock: str = "clk", reset: str | None = "rst") -> str:
    """Verilog of :data:`HARNESS_TOP`: five pins around an instance of ``top`` (see the module doc)."""
    if not any(p.name == clock for p in ports):
        raise ValueError(f"clock must be a port of module {top!r} {[p.name for p in ports]}, not {clock!r}")
    inouts = [p.name for p in ports if p.direction == "inout"]
    if inouts:
        raise PnrError(f"the timing harness cannot drive inout port {inouts[0]!r} of module {top!r}")
    passed = {clock} | ({reset} if reset and any(p.name == reset for p in ports) else set())
    ins = [p for p in ports if p.direction == "input" and p.name not in passed]
    outs = [p for p in ports if p.direction == "output"]
    if not outs:
        raise PnrError(f"module {top!r} has no outputs: nothing to time")
    ni, no = sum(p.width for p in ins), sum(p.width for p in outs)
    lines = [f"// Generated by ikseries.pnr: timing harness around {top} ({ni} input bits shifted in",
             f"// on din while load is low, {no} output bits captured while load is high and shifted",
             "// out on dout while it is low).",
             f"module {HARNESS_TOP}(clk, rst, din, load, dout);",
             "  input clk;", "  input rst;", "  input din;", "  input load;", "  output dout;"]
    if ni:
        shift = "din" if ni == 1 else f"{{in_sr[{ni - 2}:0], din}}"
        lines += [f"  reg [{ni - 1}:0] in_sr = {ni}'d0;", f"  always @(posedge clk) if (!load) in_sr <= {shift};"]
    lines += [f"  wire [{no - 1}:0] core_out;", f"  reg [{no - 1}:0] out_sr = {no}'d0;",
              "  always @(posedge clk)", "    if (load) out_sr <= core_out;",
              "    else out_sr <= " + ("1'b0;" if no == 1 else f"{{out_sr[{no - 2}:0], 1'b0}};"),
              f"  assign dout = out_sr[{no - 1}];"]
    conns = [f".{clock}(clk)"] + ([f".{reset}(rst)"] if len(passed) > 1 else [])
    pos = 0
    for p in ins:
        conns.append(f".{p.name}(in_sr[{pos + p.width - 1}:{pos}])")
        pos += p.width
    pos = 0
    for p in outs:
        conns.append(f".{p.name}(core_out[{pos + p.width - 1}:{pos}])")
        pos += p.width
    lines += [f"  {top} core (", "    " + ",\n    ".join(conns), "  );", "endmodule", ""]
    return "\n".join(lines)


# -- tools -----------------------------------------------------------------------------------------

def nextpnr_command(family: str) -> list[str]:
    """argv prefix that starts nextpnr for ``family``; the family's
    :attr:`~ikseries.constraints.facts.Nextpnr.env` variable (split on whitespace, e.g.
    ``$IKSERIES_NEXTPNR_ECP5``) overrides the YoWASP build."""
    names = [f.name for f in pnr_families()]
    if family not in names:
        raise ValueError(f"family must be one of {names}, not {family!r}")
    tool = device_family(family).nextpnr
    env = os.environ.get(tool.env)
    if env:
        return env.split()
    return [sys.executable, "-c",
            f"import sys, {tool.module} as m; sys.exit(m.{tool.runner}(sys.argv[1:]))"]


def _tail(path: Path, lines: int = 20) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").rstrip().splitlines()[-lines:])
    except OSError:
        return ""


# "Info: \t         <BEL type>:      10/      8   125%"
_UTIL_RE = re.compile(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+\d+%", re.M)


def _log_overflow(log: str, dev: PnrDevice) -> dict[str, tuple[int, int]]:
    idx = log.rfind("Device utilisation:")
    if idx < 0:
        return {}
    names = {bel: col for col, bel in dev.bels}
    over = {}
    for bel, used, avail in _UTIL_RE.findall(log[idx:]):
        if int(used) > int(avail):
            over[names.get(bel, bel)] = (int(used), int(avail))
    return over


def _check_args(verilog, top, device, clock_hz, workdir, harness, seed):
    if device not in PNR_DEVICES:
        raise ValueError(f"device must be one of {list(PNR_DEVICES)}, not {device!r}")
    if not isinstance(verilog, str):
        raise TypeError(f"verilog must be the Verilog source text (str), not {type(verilog).__name__}")
    if not isinstance(top, str) or not _IDENT.fullmatch(top):
        raise ValueError(f"top must be a plain Verilog identifier, not {top!r}")
    if isinstance(clock_hz, bool) or not isinstance(clock_hz, int) or clock_hz <= 0:
        raise ValueError(f"clock_hz must be a positive integer (Hz), not {clock_hz!r}")
    if harness not in (None, True, False):
        raise ValueError(f"harness must be True, False or None (automatic), not {harness!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 31:
        raise ValueError(f"seed must be an integer in [0, 2**31), not {seed!r}")
    if not isinstance(workdir, (str, os.PathLike)):
        raise TypeError(f"workdir must be a path, not {workdir!r}")


def place_and_route(verilog: str, top: str, device: str, clock_hz: int, workdir: Path, *,
                    harness: bool | None = None, seed: int = 1, clock: str = "clk",
                    reset: str | None = "rst", timeout: float | None = None) -> PnrResult:
    """Synthesise, place and route ``top`` for ``device``; Fmax and utilisation.

    Parameters
    ----------
    verilog : str
        Verilog source text containing module ``top`` (and everything it instantiates).
    top : str
        The design's top module.
    device : str
        One of :data:`PNR_DEVICES`.
    clock_hz : int
        Target clock (nextpnr ``--freq``); the result reports the achieved Fmax either way.
    workdir : path
        Directory for this run (created; use one per call): ``core.v``, ``harness.v``,
        ``<family>/`` with the Yosys log, ``netlist.json``, the pin constraints,
        ``nextpnr.log`` and nextpnr's ``report.json``.
    harness : bool or None
        Wrap the core in the timing harness; None: when its port bits exceed the package's
        user I/O pins.
    seed : int
        nextpnr placer seed.
    clock, reset : str
        Clock and (optional) reset port names of ``top``.
    timeout : float, optional
        Per tool, in seconds.

    Raises
    ------
    ValueError, TypeError
        Bad parameters.
    DoesNotFitError
        The design needs more of a resource than the device has.
    PnrError
        A tool failed (quoting its log) or produced no Fmax for the clock.
    """
    _check_args(verilog, top, device, clock_hz, workdir, harness, seed)
    dev = PNR_DEVICES[device]
    tool = device_family(dev.family).nextpnr
    if not os.environ.get(tool.env) and importlib.util.find_spec(tool.module) is None:
        raise PnrError(f"nextpnr for {device} is not installed (pip install {tool.package})")
    ports = verilog_ports(verilog, top)
    if not any(p.name == clock for p in ports):
        raise ValueError(f"clock must be a port of module {top!r} {[p.name for p in ports]}, not {clock!r}")
    port_bits = sum(p.width for p in ports)
    use_harness = port_bits > dev.user_io if harness is None else harness
    if not use_harness and port_bits > dev.user_io:
        raise DoesNotFitError(device, top, {"IO": (port_bits, dev.user_io)},
                              "port bits vs package pins; use harness=True for a timing-only run")
    workdir = Path(workdir).resolve()
    sources, synth_top, clock_pin_name = _write_sources(verilog, top, ports, workdir, use_harness, clock, reset)
    # the harness's shift registers: one flip-flop per core input bit (clock and reset aside)
    # and per output bit
    harness_ffs = (sum(p.width for p in ports if p.direction != "output" and p.name not in (clock, reset))
                   + sum(p.width for p in ports if p.direction == "output")) if use_harness else 0
    syn = _synthesise(sources, synth_top, device, top, workdir, timeout)
    pnr_s = _run_nextpnr(device, top, workdir / dev.family, clock_pin_name, clock_hz, seed, timeout)
    report, fmax_all, util = _read_report(workdir / dev.family, device)
    net, fmax = _clock_fmax(fmax_all, device, clock_pin_name)
    return PnrResult(
        device=device, top=top, clock_hz=clock_hz, seed=seed, harness=use_harness, port_bits=port_bits,
        harness_ffs=harness_ffs, fmax_mhz=round(fmax, 3), utilisation=_utilisation(dev, util, syn["counts"]),
        synth_cells=syn["cells"], nextpnr_utilisation={k: v for k, v in sorted(util.items()) if v.get("used")},
        critical_path=_critical_path(report, net), seconds={"yosys": syn["seconds"], "nextpnr": pnr_s})


def _write_sources(verilog, top, ports, workdir: Path, use_harness: bool, clock, reset):
    """``core.v`` (and with the harness ``harness.v``) in ``workdir``: the sources, the top
    module to synthesise and the name of its clock port."""
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "core.v").write_text(verilog)
    sources = [workdir / "core.v"]
    if not use_harness:
        (workdir / "harness.v").unlink(missing_ok=True)
        return sources, top, clock
    (workdir / "harness.v").write_text(harness_verilog(ports, top, clock, reset))
    sources.append(workdir / "harness.v")
    return sources, HARNESS_TOP, "clk"


def _synthesise(sources, synth_top, device, top, workdir: Path, timeout) -> dict:
    """Yosys run of ``synth_top`` for the device's family (with its netlist for nextpnr);
    raises DoesNotFitError when its cells exceed the device's limits."""
    dev = PNR_DEVICES[device]
    try:
        syn = synth_counts(sources, synth_top, targets=[dev.family], workdir=workdir, netlist=True,
                           timeout=timeout)[dev.family]
    except SynthError as e:
        raise PnrError(str(e)) from None
    cells = syn["cells"]
    over = {}
    for res, rx, cap in dev.cell_limits:
        used = syn["counts"][res] if rx is None else sum(n for c, n in cells.items() if re.fullmatch(rx, c))
        if used > cap:
            over[res] = (used, cap)
    if over:
        raise DoesNotFitError(device, top, over, "Yosys cell counts vs device capacity")
    return syn


def _run_nextpnr(device, top, tdir: Path, clock_pin_name, clock_hz, seed, timeout) -> float:
    """nextpnr on ``tdir/netlist.json`` (writing ``report.json``): its run time in seconds.
    Raises DoesNotFitError from its utilisation log, PnrError quoting its log when it fails."""
    dev = PNR_DEVICES[device]
    tool = device_family(dev.family).nextpnr
    for stale in ("report.json", "nextpnr.log"):
        (tdir / stale).unlink(missing_ok=True)
    (tdir / tool.pin_file).write_text(tool.clock_constraint(clock_pin_name, dev.clock_pin))
    cmd = nextpnr_command(dev.family)
    warm_nextpnr(dev.family, cmd)   # parallel first runs would race on YoWASP's cache
    argv = [*cmd, *dev.nextpnr_args, "--json", "netlist.json", "--report", "report.json",
            "--freq", f"{clock_hz / 1e6:.9g}", "--seed", str(seed), "--timing-allow-fail", *tool.pin_args,
            "-q", "-l", "nextpnr.log"]
    t0 = time.perf_counter()
    with open(tdir / "nextpnr.out", "wb") as out:
        try:
            proc = subprocess.run(argv, cwd=tdir, stdin=subprocess.DEVNULL, stdout=out,
                                  stderr=subprocess.STDOUT, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise PnrError(f"nextpnr for {device} timed out after {timeout} s\n"
                           + _tail(tdir / "nextpnr.log")) from None
    pnr_s = round(time.perf_counter() - t0, 2)
    log = (tdir / "nextpnr.log").read_text(errors="replace") if (tdir / "nextpnr.log").exists() else ""
    if proc.returncode != 0:
        over = _log_overflow(log, dev)
        if over:
            raise DoesNotFitError(device, top, over, "nextpnr device utilisation")
        tail = _tail(tdir / "nextpnr.log") or _tail(tdir / "nextpnr.out")
        raise PnrError(f"nextpnr for {device} exited with status {proc.returncode}\n"
                       f"--- last lines of the nextpnr log ---\n{tail}")
    return pnr_s


def _read_report(tdir: Path, device) -> tuple[dict, dict, dict]:
    """nextpnr's ``report.json``, its ``fmax`` by clock net and its ``utilization`` by BEL type."""
    try:
        report = json.loads((tdir / "report.json").read_text())
        return report, report["fmax"], report["utilization"]
    except (OSError, ValueError, KeyError) as e:
        raise PnrError(f"nextpnr for {device} wrote no usable report.json ({e})") from None


def _clock_fmax(fmax_all: dict, device, clock_pin_name) -> tuple[str, float]:
    """The clock net of port ``clock_pin_name`` among nextpnr's clock nets and its achieved
    Fmax (MHz)."""
    clocks = {k: v for k, v in fmax_all.items()
              if not k.startswith("$PACKER") and re.search(rf"(^|\$){re.escape(clock_pin_name)}(\$|$)", k)}
    if len(clocks) != 1:
        raise PnrError(f"nextpnr for {device} reported no single Fmax for clock port {clock_pin_name!r} "
                       f"(clock nets: {sorted(fmax_all)}); does the design have register-to-register paths?")
    net = next(iter(clocks))
    return net, float(clocks[net]["achieved"])


def _utilisation(dev: PnrDevice, util: dict, counts: dict) -> dict:
    """Used and available per resource: nextpnr's BELs, the LUTs and FFs (Yosys counts against
    the logic cells where nextpnr has no column) and the carry cells."""
    utilisation = {}
    for col, bel in dev.bels:
        u = util.get(bel, {"used": 0, "available": 0})
        utilisation[col] = {"used": int(u["used"]), "available": int(u["available"])}
    lc_cap = utilisation["LC"]["available"]
    utilisation["LUT"] = {"used": counts["LUT"], "available": lc_cap}
    utilisation.setdefault("FF", {"used": counts["FF"], "available": lc_cap})
    utilisation["carry"] = {"used": counts["carry"], "available": None}
    return utilisation


def _critical_path(report: dict, net: str) -> dict:
    """Start, end, total delay and logic/routing split of the clock's critical path."""
    def clock(end: str) -> str:          # "posedge clk" -> "clk" (a substring test would take
        return end.split(" ", 1)[-1]     # "$PACKER_GND_NET_$glb_clk" for "clk")
    for cp in report.get("critical_paths", []):
        if clock(cp.get("from", "")) != net or clock(cp.get("to", "")) != net:
            continue
        steps = cp.get("path", [])
        if not steps:
            break
        logic = sum(s["delay"] for s in steps if s.get("type") != "routing")
        routing = sum(s["delay"] for s in steps if s.get("type") == "routing")
        return {"from": steps[0]["from"]["cell"], "to": steps[-1]["to"]["cell"],
                "delay_ns": round(logic + routing, 3), "logic_ns": round(logic, 3),
                "routing_ns": round(routing, 3), "steps": len(steps)}
    return {}
