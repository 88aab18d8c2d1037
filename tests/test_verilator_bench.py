"""The Verilator throughput bench (bench/verilator_throughput.py, ikseries.sim.verilator_bench) on
the tiny plan: one Verilator build, small N, and proof that it catches a wrong output or latency."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from helpers import tiny_plan
from ikseries.hdl.export import leg_verilog
from ikseries.hdl.leg import LegCore
from ikseries.sim import golden
from ikseries.sim.runner import simulator_available
from ikseries.sim.targets import corner_targets, random_targets
from ikseries.sim.verilator_bench import VerilatorTestbench, build_testbench, run_testbench, write_vectors

pytestmark = pytest.mark.skipif(not simulator_available("verilator")[0],
                                reason=simulator_available("verilator")[1] or "verilator")

BENCH = Path(__file__).resolve().parent.parent / "bench" / "verilator_throughput.py"
N = 3000


def _bench_main():
    spec = importlib.util.spec_from_file_location("verilator_throughput", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.main


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    """A fake build directory of the tiny plan's core, run through the bench script."""
    plan = tiny_plan(3, clamp=(0, 100))
    core = LegCore(plan, 1000)
    bdir = tmp_path_factory.mktemp("build")
    (bdir / "plan.json").write_text(plan.dumps())
    (bdir / "tiny_core.v").write_text(leg_verilog(core, "tiny_core"))
    (bdir / "manifest.json").write_text(json.dumps({"module": "tiny_core", "latency_cycles": core.latency}))
    wd = bdir / "work"
    code = _bench_main()([str(bdir), "-n", str(N), "--seed", "5", "--cxx-opt=-O0", "--workdir", str(wd),
                          "--json", str(bdir / "verilator_throughput.json")])
    return plan, core, bdir, wd, code, json.loads((bdir / "verilator_throughput.json").read_text())


def test_bench_passes_bit_exact(bench_run, capsys):
    plan, core, _, _, code, res = bench_run
    assert code == 0 and res["passed"]
    n_corners = len(next(iter(corner_targets(plan, port_extremes=True).values())))
    assert res["targets"] == N + n_corners and res["corner_targets"] == n_corners
    assert res["mismatches"] == 0 and res["latency_errors"] == 0 and res["latency_cycles"] == core.latency
    b2b, bp = res["passes"]["back_to_back"], res["passes"]["backpressure"]
    assert b2b["outputs_checked"] == bp["outputs_checked"] == res["targets"]
    assert b2b["latency_cycles_min"] == b2b["latency_cycles_max"] == core.latency
    assert b2b["cycles"] < res["targets"] + core.latency + 2          # one target per cycle
    assert bp["latency_cycles_max"] > core.latency and bp["cycles"] > 1.3 * res["targets"]   # it did stall
    assert res["rate_targets_per_second"] > 1000
    assert set(res["wall_seconds"]) == {"export_or_fit", "golden", "verilator_build", "run_back_to_back",
                                        "run_backpressure"}


def _testbench(plan, wd) -> VerilatorTestbench:
    return VerilatorTestbench(wd / "obj" / "Vtiny_core", ("a", "b"), ("y",), 0.0)


def test_detects_a_corrupted_expected_value(bench_run, tmp_path):
    plan, core, _, wd, _, _ = bench_run
    targets = random_targets(plan, 500, 9)
    exp = golden.outputs(plan, targets)
    exp["y"] = exp["y"].copy()
    exp["y"][123] ^= 1
    write_vectors(tmp_path / "bad.bin", plan, targets, exp)
    r = run_testbench(_testbench(plan, wd), tmp_path / "bad.bin", core.latency, stall=0.3, seed=2)
    assert not r["passed"] and r["mismatches"] == 1 and r["latency_errors"] == 0
    assert r["first_mismatches"] == [{"index": 123, "output": "y", "got": int(exp["y"][123] ^ 1),
                                      "expected": int(exp["y"][123])}]


def test_detects_a_wrong_latency(bench_run, tmp_path):
    plan, core, _, wd, _, _ = bench_run
    targets = random_targets(plan, 200, 3)
    write_vectors(tmp_path / "v.bin", plan, targets, golden.outputs(plan, targets))
    r = run_testbench(_testbench(plan, wd), tmp_path / "v.bin", core.latency + 1)
    assert not r["passed"] and r["mismatches"] == 0 and r["latency_errors"] == 200
    assert r["first_latency_errors"][0] == {"index": 0, "latency": core.latency, "cycles": core.latency}


def test_parameter_errors(bench_run, tmp_path):
    plan, core, _, wd, _, _ = bench_run
    with pytest.raises(ValueError, match=r"^stall must be a probability in \[0, 1\), not 1\.0$"):
        run_testbench(_testbench(plan, wd), tmp_path / "x.bin", core.latency, stall=1.0)
    with pytest.raises(ValueError, match=r"^latency must be a positive integer, not 0$"):
        run_testbench(_testbench(plan, wd), tmp_path / "x.bin", 0)
    with pytest.raises(ValueError, match=r"^initiation_interval must be a positive integer, not 0$"):
        run_testbench(_testbench(plan, wd), tmp_path / "x.bin", core.latency, initiation_interval=0)
    t = random_targets(plan, 5, 1)
    with pytest.raises(ValueError, match=r"^targets and expected outputs must have one length, not \[4, 5\]$"):
        write_vectors(tmp_path / "x.bin", plan, t, {"y": np.zeros(4, dtype=np.int64)})


# -- the CORDIC baseline's exported Verilog, pipelined and iterative -------------------------------
@pytest.fixture(scope="module")
def cordic_benches(robot, tmp_path_factory):
    """Both CORDIC cores of the sized test design built into Verilator testbenches, and 3000
    random targets plus every corner with the golden model's outputs."""
    from ikseries.hdl.cordic import CordicLegSolver
    from ikseries.hdl.flat import stream_verilog
    from ikseries.sim import cordic_golden
    from test_cordic import SIZED
    wd = tmp_path_factory.mktemp("cordic_tb")
    pipe = CordicLegSolver(robot, SIZED)
    it = CordicLegSolver(robot, SIZED, pipe.longest_loop)
    tbs = {name: (core, build_testbench(core.plan, stream_verilog(core, name), name, wd / name, cxx_opt="-O0",
                                        advance="i_ready" if core.initiation_interval == 1 else "enable"))
           for name, core in (("cordic_pipelined", pipe), ("cordic_iterative", it))}
    c, r = corner_targets(pipe.plan, port_extremes=True), random_targets(pipe.plan, 3000, 4)
    targets = {k: np.concatenate([c[k], r[k]]) for k in c}
    write_vectors(wd / "v.bin", pipe.plan, targets, cordic_golden.outputs(robot, pipe.plan, targets))
    return tbs, wd / "v.bin", targets


@pytest.mark.parametrize("name", ["cordic_pipelined", "cordic_iterative"])
@pytest.mark.parametrize("stall, bubble", [(0.0, 0.0), (0.3, 0.2)])
def test_cordic_verilog_bit_exact_on_verilator(cordic_benches, name, stall, bubble):
    tbs, vectors, targets = cordic_benches
    core, tb = tbs[name]
    n = len(targets["r"])
    r = run_testbench(tb, vectors, core.latency, stall=stall, bubble=bubble, seed=7,
                      initiation_interval=core.initiation_interval)
    assert r["passed"] and r["outputs_checked"] == n, r     # latency counted in advancing cycles
    assert r["latency_cycles_min"] >= core.latency
    if stall == 0 and bubble == 0:     # back to back: one target every initiation_interval cycles
        assert r["latency_cycles_min"] == r["latency_cycles_max"] == core.latency
        assert r["cycles"] <= n * core.initiation_interval + core.latency + 8


def test_iterative_cordic_latency_needs_the_enable_count(cordic_benches, tmp_path):
    """Counting only the cycles with i_ready high (right for one target per cycle) makes the
    iterative core's latency look wrong: the bench can fail."""
    tbs, vectors, targets = cordic_benches
    core, _ = tbs["cordic_iterative"]
    from ikseries.hdl.flat import stream_verilog
    tb = build_testbench(core.plan, stream_verilog(core, "cordic_iterative"), "cordic_iterative", tmp_path,
                         cxx_opt="-O0", advance="i_ready")
    r = run_testbench(tb, vectors, core.latency, initiation_interval=core.initiation_interval)
    assert not r["passed"] and r["mismatches"] == 0 and r["latency_errors"] == len(targets["r"])
    with pytest.raises(ValueError, match=r"^advance must be one of \['enable', 'i_ready'\], not 'ready'$"):
        build_testbench(core.plan, "", "x", tmp_path, advance="ready")


def _fake_build(bdir, plan, core):
    from ikseries.hdl.export import stream_rule
    (bdir / "plan.json").write_text(plan.dumps())
    (bdir / "tiny_core.v").write_text(leg_verilog(core, "tiny_core"))
    (bdir / "manifest.json").write_text(json.dumps({
        "module": "tiny_core", "latency_cycles": core.latency, "initiation_interval": core.initiation_interval,
        "architecture": {"architecture": core.architecture}, "stream_rule": stream_rule(core)}))


def test_bench_runs_a_modulo_build(tmp_path):
    """A modulo-scheduled build (a target every 3 cycles) passes, latency counted in cycles of
    the pipeline enable; a folded build and a buffered one (never stalls) are refused with a
    message."""
    plan = tiny_plan(3, clamp=(0, 100))
    core = LegCore(plan, 1000, interval=3)
    _fake_build(tmp_path, plan, core)
    jpath = tmp_path / "out.json"
    code = _bench_main()([str(tmp_path), "-n", "600", "--cxx-opt=-O0", "--workdir", str(tmp_path / "w"),
                          "--json", str(jpath)])
    res = json.loads(jpath.read_text())
    assert code == 0 and res["passed"] and res["initiation_interval"] == 3
    b2b = res["passes"]["back_to_back"]
    assert b2b["latency_cycles_min"] == b2b["latency_cycles_max"] == core.latency
    assert b2b["cycles"] >= 3 * res["targets"]
    folded = tmp_path / "folded"
    folded.mkdir()
    _fake_build(folded, plan, LegCore(plan, 1000, multipliers=1, dsp=(16, 16)))
    with pytest.raises(SystemExit, match=r"whole pipeline stalls .* \(stream rules pipelined, modulo\), not a 'folded' build"):
        _bench_main()([str(folded), "-n", "10", "--json", str(jpath)])
    buffered = tmp_path / "buffered"
    buffered.mkdir()
    _fake_build(buffered, plan, LegCore(plan, 1000, interval=1))
    with pytest.raises(SystemExit, match="not a 'buffered' build"):
        _bench_main()([str(buffered), "-n", "10", "--json", str(jpath)])
