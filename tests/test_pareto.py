"""The Pareto bench's machinery (ikseries.pareto, bench/pareto.py) on the tiny plan, iCE40 only.

Two real place-and-route runs of small folded evaluators (a few seconds each once the YoWASP tools
are cached) and one does-not-fit run that stops after Yosys.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import pytest

from helpers import tiny_plan
from ikseries.constraints.devices import PNR_DEVICES
from ikseries.pareto import pareto_front, plot_device, run_design, run_matrix

ICE40 = "ice40-up5k-sg48"
BENCH = Path(__file__).resolve().parent.parent / "bench" / "pareto.py"


def _bench():
    spec = importlib.util.spec_from_file_location("pareto_bench", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# -- the Pareto front: pure function on hand-made points ---------------------------------------------
@pytest.mark.parametrize("points, front", [
    ([], []),
    ([(1, 1)], [0]),
    ([(1, 5), (2, 3), (3, 4), (4, 1), (5, 5)], [0, 1, 3]),   # (3,4) by (2,3); (5,5) by all
    ([(2, 2), (2, 2), (3, 3)], [0, 1]),                      # equal points both stay
    ([(1, 3), (1, 2)], [1]),                                 # equal x, smaller y dominates
    ([(3, 1), (2, 1)], [1]),                                 # equal y, smaller x dominates
    ([(1, 3), (2, 2), (3, 1)], [0, 1, 2]),                   # a trade-off curve: all on it
])
def test_pareto_front(points, front):
    assert pareto_front(points) == front


# -- real runs on the tiny plan -------------------------------------------------------------------
@pytest.fixture(scope="module")
def records(tmp_path_factory):
    bench = _bench()
    plan = tiny_plan(3, clamp=(0, 100), degree=2)
    specs = bench.polynomial_specs(plan, 0.25, ("folded1", "folded2"), {"max_error_pu_per_servo": {"y": 0.25}})
    work = tmp_path_factory.mktemp("pareto")
    return run_matrix(specs, [ICE40], 48_000_000, work, jobs=2), bench


def test_placed_records_have_every_field(records):
    recs, bench = records
    assert [r["design"] for r in recs] == ["folded1", "folded2"]
    for r in recs:
        assert r["status"] == "placed", r
        assert r["device"] == ICE40 and r["kind"] == "polynomial"
        assert r["fmax_mhz"] > 0 and isinstance(r["meets_clock"], bool)
        assert r["latency_cycles"] > 2 and r["initiation_interval"] == r["latency_cycles"]   # folded
        assert r["latency_ns"] == pytest.approx(r["latency_cycles"] * 1e3 / r["fmax_mhz"], rel=1e-3)
        assert r["throughput_per_s"] == pytest.approx(r["fmax_mhz"] * 1e6 / r["initiation_interval"], rel=1e-3)
        assert 1 <= r["DSP"] <= 8 and r["LUT"] > 0 and r["FF"] > 0 and r["carry"] >= 0 and r["BRAM"] >= 0
        assert 0 < r["LC"] <= r["LC_available"] == 5280
        assert r["area"] == r["LUT"] + r["FF"] - r["harness_ffs"]
        assert r["max_error_pu"] == 0.25 and r["overflow"] is None and r["error"] is None
        json.dumps(r)
    assert recs[1]["latency_cycles"] <= recs[0]["latency_cycles"]   # two multipliers: no slower
    text = bench.table(recs)
    assert "folded1" in text and "folded2" in text and f"{recs[0]['fmax_mhz']:.1f}" in text


def test_plot_marks_the_front(records, tmp_path):
    recs, _ = records
    png = tmp_path / "p.png"
    front = plot_device(recs, ICE40, png)
    assert png.stat().st_size > 1000
    expected = [recs[i]["design"] for i in pareto_front([(r["area"], r["latency_ns"]) for r in recs])]
    assert front == expected and front


def test_does_not_fit_is_recorded(records, tmp_path, monkeypatch):
    _, bench = records
    dev = PNR_DEVICES[ICE40]
    small = dataclasses.replace(dev, cell_limits=tuple((n, rx, 1 if n == "DSP" else cap)
                                                       for n, rx, cap in dev.cell_limits))
    monkeypatch.setitem(PNR_DEVICES, ICE40, small)
    spec = bench.polynomial_specs(tiny_plan(3, clamp=(0, 100), degree=2), None, ("pipelined",))[0]
    r = run_design(spec, ICE40, 48_000_000, tmp_path / "w")
    assert r["status"] == "does-not-fit"
    assert r["overflow"]["DSP"]["available"] == 1 and r["overflow"]["DSP"]["over"] == r["DSP"] - 1 >= 1
    assert r["LUT"] is not None and r["area"] == r["LUT"] + r["FF"]
    assert r["fmax_mhz"] is None and r["latency_ns"] is None and r["latency_cycles"] > 0
    assert "overflow: DSP" in bench.table([r])
    lines = bench.verdict_poly_vs_cordic([r])
    assert "not decided" in lines[0]


def test_a_tool_past_its_timeout_is_an_error_record(records, tmp_path):
    """A run that outlasts ``timeout`` (a router that does not converge, say) is recorded as an
    error of that seed, naming the timeout, and the matrix goes on."""
    _, bench = records
    spec = bench.polynomial_specs(tiny_plan(3, clamp=(0, 100), degree=2), None, ("folded1",))[0]
    (r,) = run_matrix([spec], [ICE40], 48_000_000, tmp_path / "w", timeout=0.01)
    assert r["status"] == "error" and "timed out after 0.01 s" in r["error"] and r["fmax_mhz"] is None


def test_verdicts_on_hand_made_records(records):
    _, bench = records
    base = {"kind": "polynomial", "status": "placed", "overflow": None, "error": None, "max_error_pu": 0.4}
    poly = {**base, "design": "folded2", "device": bench.ECP5, "fmax_mhz": 100.0, "latency_ns": 300.0,
            "throughput_per_s": 3.3e6, "LUT": 900, "DSP": 4, "FF": 800, "BRAM": 5}
    cordic = {**base, "kind": "cordic", "design": "cordic", "device": bench.ECP5, "fmax_mhz": 160.0,
              "latency_ns": 250.0, "throughput_per_s": 160e6, "LUT": 5000, "DSP": 2, "FF": 600, "BRAM": 0}
    speed = bench.verdict_ecp5_speed([poly, cordic])     # the target is the polynomial core's
    assert speed[0].endswith("polynomial cores): folded2")
    assert any("latency 300 ns <= 200 ns: NOT MET (by 100 ns, 50%)" in s for s in speed)
    assert any(s.startswith("  verdict: NOT MET") for s in speed)
    assert speed[-1].startswith("  nearest polynomial core: folded2: Fmax 100.0 MHz (67% of the target)")
    fast = {**poly, "design": "modulo4d", "fmax_mhz": 151.0, "latency_ns": 199.0, "throughput_per_s": 37e6}
    speed = bench.verdict_ecp5_speed([poly, fast, cordic])
    assert speed[-1] == "  verdict: MET; placed cores meeting all three: modulo4d"
    pv = bench.verdict_poly_vs_cordic([poly, cordic])
    assert "loses on DSP, latency" in pv[1] and pv[-2] == "  verdict: NOT MET (LUT and DSP each, latency no worse)"
    assert pv[-1].startswith("  read as the sum LUT + DSP (5002 for CORDIC), latency no worse: not met")
    pv = bench.verdict_poly_vs_cordic([{**poly, "DSP": 2, "latency_ns": 200.0}, cordic])
    assert pv[-2] == "  verdict: MET by folded2 (LUT and DSP each, latency no worse)"
    # where the winner still loses is said, with the ratio
    assert pv[1].endswith("-> wins; also loses on FF 800 vs 600 (1.3x); BRAM 5 vs 0; Fmax 100.0 vs 160.0 MHz (0.62x); "
                         "throughput 3.3 vs 160 M/s (0.021x)")
    assert pv[-1].startswith("  read as the sum LUT + DSP (5002 for CORDIC), latency no worse: met by folded2")
    # an iterative CORDIC, when placed, gets the same comparison after the target's verdict
    it = {**cordic, "design": "cordic_iter", "initiation_interval": 17, "LUT": 800, "DSP": 2, "FF": 500,
          "latency_ns": 900.0, "throughput_per_s": 9e6, "fmax_mhz": 90.0}
    pv = bench.verdict_poly_vs_cordic([{**poly, "DSP": 2, "latency_ns": 200.0}, cordic, it])
    assert pv[2] == "  verdict: MET by folded2 (LUT and DSP each, latency no worse)"
    assert pv[4].startswith("against the iterative CORDIC (a target every 17 cycles: 800 LUT, 2 DSP, 900.0 ns")
    assert "-> loses on LUT; also loses on FF 800 vs 500 (1.6x); BRAM 5 vs 0; throughput 3.3 vs 9 M/s (0.37x)" in pv[5]
    assert pv[6] == "  verdict: not met (LUT and DSP each, latency no worse)"
    # when the placed LUT slots disagree with Yosys' LUT count, the line says so
    pv = bench.verdict_poly_vs_cordic([{**poly, "DSP": 2, "latency_ns": 200.0, "LC": 5200}, {**cordic, "LC": 5100}])
    assert pv[1].endswith("; nextpnr's placed LUT slots say the opposite on LUT: LC 5200 vs 5100")


def test_jobs_must_be_one_or_two(tmp_path):
    with pytest.raises(ValueError, match=r"^jobs must be 1 or 2 \(two cores, at most two tool processes\), not 3$"):
        run_matrix([], [ICE40], 1, tmp_path, jobs=3)


def test_bench_dsp_designs_are_ecp5_modulo_cores_on_mult18x18d_primitives():
    from helpers import tiny_plan
    bench = _bench()
    specs = bench.dsp_specs(tiny_plan(1, operand_bits=(18, 18)), 0.3)
    assert [s.name for s in specs] == [f"modulo{ii}d" for ii in bench.MODULO_DSP_II]
    for s, ii in zip(specs, bench.MODULO_DSP_II):
        assert s.devices == (bench.ECP5,) and s.initiation_interval(bench.ECP5) == ii
        text, top = s.verilog(bench.ECP5)
        assert top == f"poly_{s.name}" and "MULT18X18D" in text
    assert not set(bench.DSP_DESIGNS) & set(bench.POLY_DESIGNS)


def test_bench_iterative_cordic_spec(robot):
    """``cordic_iter``: the same CORDIC design, iterative, a target every ``longest_loop`` cycles,
    at the pipelined one's latency."""
    from test_cordic import SIZED

    from ikseries.hdl.cordic import CordicLegSolver
    bench = _bench()
    pipe, it = (bench.cordic_spec(robot, SIZED, 0.4, {}, iterative=i) for i in (False, True))
    assert (pipe.name, it.name) == ("cordic", "cordic_iter") and it.kind == pipe.kind == "cordic"
    assert pipe.initiation_interval(bench.ECP5) == 1
    assert it.initiation_interval(bench.ECP5) == CordicLegSolver(robot, SIZED).longest_loop == 17
    assert it.latency_cycles(bench.ECP5) == pipe.latency_cycles(bench.ECP5)
    text, top = it.verilog(bench.ECP5)
    assert top == "cordic_iterative" and f"module {top}" in text and "phase" in text


def test_issue_targets_verdicts_on_hand_made_records():
    bench = _bench()
    base = {"kind": "polynomial", "status": "placed", "overflow": None, "error": None, "max_error_pu": 0.4,
            "device": bench.ECP5, "initiation_interval": 1, "BRAM": 10, "certified_pu": {"s1": 0.5, "s2": 0.49}}
    fast = {**base, "design": "modulo1d", "fmax_mhz": 210.0, "latency_ns": 95.0, "DSP": 28}
    lines = bench.verdict_one_per_clock([fast], 0.5)
    assert lines[1].endswith("-> met") and lines[-1] == "  verdict: MET by modulo1d"
    slow = {**fast, "design": "pipelined", "fmax_mhz": 150.0, "DSP": 30}
    lines = bench.verdict_one_per_clock([slow, {**fast, "certified_pu": {"s1": 0.51}}], 0.5)
    assert "DSP 30 <= 28 (NOT MET by 2)" in lines[1] and "Fmax 150 MHz >= 200 MHz (NOT MET by 50 MHz)" in lines[1]
    assert "certified 0.51 pu <= 0.5 pu (NOT MET by 0.01 pu)" in lines[2]
    assert lines[-1] == "  verdict: NOT MET"
    over = {**fast, "status": "does-not-fit", "overflow": {"DSP": {"used": 84, "available": 28, "over": 56}}}
    assert bench.verdict_one_per_clock([over], 0.5)[1] == "  modulo1d: does-not-fit DSP 84/28 (3.0x) - NOT MET"
    assert "not decided" in bench.verdict_one_per_clock([{**fast, "initiation_interval": 4}], 0.5)[0]

    hx = {**base, "kind": "robot", "design": "hexapod", "device": bench.ICE40, "description": "folded",
          "fmax_mhz": 56.0}
    assert bench.verdict_hexapod_margin([hx])[0].endswith("margin +16.7% -> MET")
    assert bench.verdict_hexapod_margin([{**hx, "fmax_mhz": 50.0}])[0].endswith("margin +4.2% -> NOT MET")

    small = {**base, "device": bench.ICE40, "design": "modulo12", "initiation_interval": 12, "LC": 3000,
             "DSP": 6, "fmax_mhz": 40.0, "throughput_per_s": 40e6 / 12}
    folded = {**small, "design": "folded1", "initiation_interval": 70, "LC": 1500}
    line = bench.verdict_small_core([folded, small, {**small, "design": "modulo8", "initiation_interval": 8,
                                                     "LC": 3500}])[0]
    assert "the smallest placed is modulo12: 3000 LC, 6 DSP" in line and line.endswith("-> MET")
    assert bench.verdict_small_core([folded])[0].endswith("none placed (none run) - NOT MET")


def test_median_records_take_the_median_seed():
    bench = _bench()

    def rec(fmax, status="placed"):
        return {"design": "d", "device": "x", "status": status, "fmax_mhz": fmax, "LC": fmax and int(fmax)}
    runs = [[rec(50.0), rec(None, "does-not-fit")], [rec(40.0), rec(None, "does-not-fit")],
            [rec(60.0), rec(None, "does-not-fit")]]
    med, nofit = bench.median_records(runs, [1, 2, 3])
    assert (med["fmax_mhz"], med["LC"], med["seed"]) == (50.0, 50, 1)
    assert med["fmax_by_seed"] == {"1": 50.0, "2": 40.0, "3": 60.0}
    assert nofit["status"] == "does-not-fit" and nofit["seed"] == 1
    two = bench.median_records([[rec(50.0)], [rec(40.0)]], [1, 2])[0]
    assert (two["fmax_mhz"], two["seed"]) == (40.0, 2)          # the slower of two
    one_placed = bench.median_records([[rec(None, "error")], [rec(45.0)]], [1, 2])[0]
    assert (one_placed["fmax_mhz"], one_placed["seed"]) == (45.0, 2)


def test_merge_keeps_the_other_designs_records(tmp_path):
    """--merge: the re-measured (design, device) records replace the old ones, every other
    record of the existing JSON stays, and the run that measured them is listed; other seeds
    are refused."""
    bench = _bench()
    out = tmp_path / "pareto.json"
    old = [{"design": "modulo1dt", "device": "x", "fmax_mhz": 134.0},
           {"design": "cordic", "device": "x", "fmax_mhz": 100.0},
           {"design": "cordic", "device": "y", "fmax_mhz": 50.0}]
    out.write_text(json.dumps({"run": {"command": "old"}, "seeds": [1, 2, 3], "records": old}))
    new = [{"design": "modulo1dt", "device": "x", "fmax_mhz": 212.0}]
    assert bench.merge_records(out, new, [1, 2, 3]) == [{"command": "old"}]
    assert new == [{"design": "modulo1dt", "device": "x", "fmax_mhz": 212.0}, *old[1:]]
    with pytest.raises(SystemExit, match=r"^--seeds must be those of .* \(\[1, 2, 3\]\) with --merge, not \[1\]$"):
        bench.merge_records(out, [], [1])
    assert bench.merge_records(tmp_path / "none.json", new, [1]) == []
