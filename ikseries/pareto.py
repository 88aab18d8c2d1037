"""Area/latency records of IK cores from real place and route, and their Pareto front.

A :class:`DesignSpec` describes one core (how to emit its Verilog for a device, its latency,
initiation interval and measured accuracy); :func:`run_design` places and routes it with
:func:`ikseries.pnr.place_and_route` and returns one JSON-serialisable record, also when the
design does not fit (then with Yosys' counts and the overflow) or a tool fails (then with the
error). :func:`run_matrix` runs every spec on every device it allows, ``jobs`` at a time.

Record fields (``None`` when not measured):

``design``, ``device``, ``kind``, ``description``, ``top``
    Identification.
``status``
    ``"placed"``, ``"does-not-fit"`` or ``"error"``.
``latency_cycles``, ``initiation_interval``
    From the built component's properties.
``fmax_mhz``, ``meets_clock``, ``clock_target_mhz``
    nextpnr's achieved Fmax of the clock net (register to register).
``latency_ns``, ``throughput_per_s``
    ``latency_cycles / Fmax`` and ``Fmax / initiation_interval``.
``LUT``, ``FF``, ``carry``, ``DSP``, ``BRAM``
    Yosys cell counts of what was synthesised (the timing harness included when used).
``LC``, ``LC_available``
    nextpnr's placed logic cells (the device's ``LC`` BEL type) and the device's.
``harness``, ``harness_ffs``
    Whether the core is wrapped in the timing harness (its port bits exceed the package's
    pins, as :func:`~ikseries.pnr.place_and_route` decides) and the FFs that harness adds;
    known from the ports, so also for a design that does not fit.
``area``
    The plotted area: ``LUT + FF - harness_ffs`` (Yosys counts, the harness' shift-register
    FFs removed; its one-LUT-per-output-bit capture mux, if any, remains).
``overflow``
    For ``does-not-fit``: resource -> ``{"used", "available", "over"}``.
``max_error_pu``, ``error``
    Largest measured |error| over the servos (pu); ``error`` is a tool failure message.
"""
from __future__ import annotations

import dataclasses
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, Sequence

from .constraints.devices import PNR_DEVICES, family as device_family
from .pnr import DoesNotFitError, PnrError, place_and_route, verilog_ports

__all__ = ["DesignSpec", "pareto_front", "run_design", "run_matrix", "plot_device"]


@dataclasses.dataclass
class DesignSpec:
    """One core to place and route.

    Parameters
    ----------
    name : str
        Short name (also the work directory).
    kind : str
        ``"polynomial"``, ``"cordic"`` or ``"robot"``.
    description : str
        One line for the table.
    verilog : callable
        ``verilog(device) -> (verilog_text, top)``; the device decides e.g. the DSP size.
    latency_cycles, initiation_interval : callable
        ``f(device) -> int`` (from the component built for that device).
    max_error_pu : float or None
        Largest measured |error| over the servos, in pulse units.
    devices : tuple of str or None
        Devices this design is run on (None: every requested one).
    extra : dict
        Copied into the record (e.g. per-servo errors, the CORDIC design).
    """
    name: str
    kind: str
    description: str
    verilog: Callable[[str], tuple[str, str]]
    latency_cycles: Callable[[str], int]
    initiation_interval: Callable[[str], int]
    max_error_pu: float | None = None
    devices: tuple[str, ...] | None = None
    extra: dict = dataclasses.field(default_factory=dict)


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point dominates, both coordinates minimised.

    A point dominates another if it is no larger in both coordinates and smaller in at
    least one; equal points do not dominate each other (both stay on the front).

    Parameters
    ----------
    points : sequence of (float, float)

    Returns
    -------
    list of int
        Sorted indices of the non-dominated points.
    """
    pts = [(float(x), float(y)) for x, y in points]
    front = []
    for i, (xi, yi) in enumerate(pts):
        if not any(xj <= xi and yj <= yi and (xj < xi or yj < yi) for j, (xj, yj) in enumerate(pts) if j != i):
            front.append(i)
    return front


def _counts_from_workdir(workdir: Path, family: str) -> dict | None:
    stat = Path(workdir) / family / "stat.json"
    try:
        cells = json.loads(stat.read_text())["design"]["num_cells_by_type"]
    except (OSError, ValueError, KeyError):
        return None
    return device_family(family).categorise(cells)[0]


def run_design(spec: DesignSpec, device: str, clock_hz: int, workdir: Path, *, seed: int = 1,
               timeout: float | None = None) -> dict:
    """Place and route ``spec`` on ``device``; one record (see the module docstring).

    A design that does not fit, or a tool failure, is recorded, never raised.
    """
    if device not in PNR_DEVICES:
        raise ValueError(f"device must be one of {list(PNR_DEVICES)}, not {device!r}")
    family = PNR_DEVICES[device].family
    t0 = time.perf_counter()
    rec = {"design": spec.name, "device": device, "kind": spec.kind, "description": spec.description,
           "top": None, "status": None, "latency_cycles": spec.latency_cycles(device),
           "initiation_interval": spec.initiation_interval(device), "max_error_pu": spec.max_error_pu,
           "clock_target_mhz": clock_hz / 1e6, "fmax_mhz": None, "meets_clock": None,
           "latency_ns": None, "throughput_per_s": None,
           "LUT": None, "FF": None, "carry": None, "DSP": None, "BRAM": None, "LC": None,
           "LC_available": None, "harness": None, "harness_ffs": 0, "area": None,
           "overflow": None, "stage": None, "error": None, **spec.extra}
    verilog, top = spec.verilog(device)
    rec["top"] = top
    workdir = Path(workdir)
    # the harness place_and_route adds by default (port bits > package pins): one FF per
    # port bit except the clock and reset, known before any tool runs
    ports = verilog_ports(verilog, top)
    if sum(p.width for p in ports) > PNR_DEVICES[device].user_io:
        rec["harness"] = True
        rec["harness_ffs"] = sum(p.width for p in ports if p.name not in ("clk", "rst"))
    try:
        res = place_and_route(verilog, top, device, clock_hz, workdir, seed=seed, timeout=timeout)
    except DoesNotFitError as e:
        rec.update(status="does-not-fit", stage=e.stage,
                   overflow={k: {"used": u, "available": a, "over": u - a} for k, (u, a) in e.overflow.items()})
        counts = _counts_from_workdir(workdir, family)
        if counts:
            rec.update({k: counts[k] for k in ("LUT", "FF", "carry", "DSP", "BRAM")})
    except PnrError as e:
        rec.update(status="error", error=str(e).splitlines()[0])
        counts = _counts_from_workdir(workdir, family)
        if counts:
            rec.update({k: counts[k] for k in ("LUT", "FF", "carry", "DSP", "BRAM")})
    else:
        counts = device_family(family).categorise(res.synth_cells)[0]
        rec.update({k: counts[k] for k in ("LUT", "FF", "carry", "DSP", "BRAM")})
        fmax = res.fmax_mhz
        rec.update(status="placed", fmax_mhz=fmax, meets_clock=res.meets_clock,
                   LC=res.utilisation["LC"]["used"], LC_available=res.utilisation["LC"]["available"],
                   harness=res.harness, harness_ffs=res.harness_ffs,
                   latency_ns=round(rec["latency_cycles"] * 1e3 / fmax, 2),
                   throughput_per_s=round(fmax * 1e6 / rec["initiation_interval"], 1),
                   critical_path=res.critical_path, seconds=res.seconds)
    if rec["LUT"] is not None:
        rec["area"] = rec["LUT"] + rec["FF"] - rec["harness_ffs"]
    rec["wall_seconds"] = round(time.perf_counter() - t0, 1)
    return rec


def run_matrix(specs: Sequence[DesignSpec], devices: Sequence[str], clock_hz: int, workdir: Path, *,
               jobs: int = 1, seed: int = 1, timeout: float | None = None,
               progress: Callable[[str], None] = lambda m: None) -> list[dict]:
    """:func:`run_design` for every spec on every device it allows, ``jobs`` (1 or 2) at a time,
    each tool run given ``timeout`` seconds (None: no limit).

    Returns the records in spec order, then device order (deterministic whatever ``jobs``).
    """
    if isinstance(jobs, bool) or not isinstance(jobs, int) or not 1 <= jobs <= 2:
        raise ValueError(f"jobs must be 1 or 2 (two cores, at most two tool processes), not {jobs!r}")
    for d in devices:
        if d not in PNR_DEVICES:
            raise ValueError(f"devices must be among {list(PNR_DEVICES)}, not {d!r}")
    work = [(s, d) for s in specs for d in devices if s.devices is None or d in s.devices]

    def one(item):
        s, d = item
        progress(f"{s.name} on {d} ...")
        rec = run_design(s, d, clock_hz, Path(workdir) / f"{s.name}_{d}", seed=seed, timeout=timeout)
        extra = f"Fmax {rec['fmax_mhz']} MHz" if rec["status"] == "placed" else \
            (json.dumps(rec["overflow"]) if rec["overflow"] else rec["error"])
        progress(f"{s.name} on {d}: {rec['status']}, {extra} ({rec['wall_seconds']} s)")
        return rec

    with ThreadPoolExecutor(jobs) as pool:
        return list(pool.map(one, work))


def plot_device(records: Sequence[dict], device: str, path: Path) -> list[str]:
    """Save the area/latency plot of ``device``'s placed records (area = ``LUT + FF -
    harness_ffs`` on x, latency in ns at Fmax on y, log scales), Pareto front marked; designs
    that did not fit are listed in the title. Returns the names on the front."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    placed = [r for r in records if r["device"] == device and r["status"] == "placed"]
    missing = [r["design"] for r in records if r["device"] == device and r["status"] != "placed"]
    front = [placed[i] for i in pareto_front([(r["area"], r["latency_ns"]) for r in placed])]
    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    for k, r in enumerate(placed):
        on = r in front
        ax.scatter(r["area"], r["latency_ns"], s=60, marker="o" if on else "s",
                   color="C3" if on else "C0", zorder=3)
        # points within 2 % of an earlier one on both axes: the label goes one line pair higher
        same = sum(abs(r["area"] / q["area"] - 1) < 0.02 and abs(r["latency_ns"] / q["latency_ns"] - 1) < 0.02
                   for q in placed[:k])
        ax.annotate(f"{r['design']}\n{r['fmax_mhz']:.0f} MHz, {r['DSP']} DSP, "
                    f"{r['throughput_per_s'] / 1e6:.3g} M/s", (r["area"], r["latency_ns"]),
                    textcoords="offset points", xytext=(6, 4 + 24 * same), fontsize=8)
    if front:
        f = sorted(front, key=lambda r: r["area"])
        ax.step([r["area"] for r in f], [r["latency_ns"] for r in f], where="post", color="C3",
                lw=1, ls="--", label="Pareto front")
        ax.legend(loc="upper right")
    if placed:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.margins(x=0.35, y=0.15)   # room for the labels right of the points
    ax.set_xlabel("area: LUT + FF (Yosys; LUT with the carry chains' LUTs; harness FFs excluded)")
    ax.set_ylabel("latency at Fmax (ns)")
    title = f"{device}: area vs latency"
    if missing:
        title += "\nnot placed (does not fit / failed): " + ", ".join(missing)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [r["design"] for r in front]
