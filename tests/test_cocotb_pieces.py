"""The cocotb bench's pieces outside the simulator: the run configuration, the manifest as the
bench reads it (stream_rule included), the timing rules catching i_ready violations, and the
runner's one-line errors. Fast: no simulator runs."""
from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import tiny_piecewise_plan
from ikseries.hdl.architectures import STREAM_RULES
from ikseries.hdl.export import stream_rule
from ikseries.hdl.leg import LegCore
from ikseries.hdl.shared import RobotCore
from ikseries.sim.cocotb_leg.config import Design, RunConfig
from ikseries.sim.cocotb_leg.monitor import Sample
from ikseries.sim.cocotb_leg.rules import RULES, Buffered, Folded, Modulo, Pipelined, timing_rule
from ikseries.sim.runner import bench_manifest, run


@pytest.fixture(scope="module")
def tiny():
    return tiny_piecewise_plan(1, clamp=(0, 100))


def test_a_timing_rule_for_every_stream_rule():
    assert set(RULES) == set(STREAM_RULES)


def test_stream_rule_of_each_core(tiny):
    assert stream_rule(LegCore(tiny, 64)) == "pipelined"
    assert stream_rule(LegCore(tiny, 512, multipliers=1, dsp=(16, 16))) == "folded"
    assert stream_rule(LegCore(tiny, 512, interval=2)) == "modulo"
    assert stream_rule(LegCore(tiny, 512, interval=1)) == "buffered"
    assert stream_rule(RobotCore(tiny, 2, 4096, 48e6, multipliers=1, dsp=(16, 16))) == "folded"


def test_design_read_from_the_manifest(tiny):
    core = LegCore(tiny, 64)
    man = bench_manifest(tiny, core, "tiny_core")
    d = Design.from_manifest(json.loads(json.dumps(man)))
    assert (d.module, d.latency, d.initiation_interval, d.period, d.stream_rule, d.legs, d.robot) == \
        ("tiny_core", core.latency, 1, 64, "pipelined", 1, False)
    assert [(f.name, f.port) for f in d.inputs] == [(i.name, f"i_{i.name}") for i in tiny.inputs]
    assert d.pwm == {s: f"pwm_{s}" for s in core.servos} and d.leg_in is None
    d.check_plan(tiny)


def test_robot_design_read_from_the_manifest(tiny):
    core = RobotCore(tiny, 3, 4096, 48e6, multipliers=1, dsp=(16, 16))
    d = Design.from_manifest(bench_manifest(tiny, core, "robot_core"))
    assert d.robot and d.legs == 3 and d.stream_rule == "folded" and d.period_start == "period_start"
    assert (d.leg_in.port, d.leg_in.width, d.leg_out.port) == ("i_leg", 2, "o_leg")
    assert d.pwm[(2, core.servos[0])] == f"pwm_l2_{core.servos[0]}"
    assert [f.name for f in d.inputs] == [i.name for i in tiny.inputs]      # the leg field kept apart


def test_bad_manifests_are_one_line_errors(tiny):
    man = bench_manifest(tiny, LegCore(tiny, 64), "tiny_core")
    with pytest.raises(ValueError, match=r"^manifest stream_rule must be one of pipelined, folded, modulo, buffered, "
                                         r"not 'systolic'$"):
        Design.from_manifest({**man, "stream_rule": "systolic"})
    with pytest.raises(ValueError, match=r"^manifest has no stream_rule$"):
        Design.from_manifest({k: v for k, v in man.items() if k != "stream_rule"})
    with pytest.raises(ValueError, match=r"^manifest latency_cycles must be a positive integer, not 0$"):
        Design.from_manifest({**man, "latency_cycles": 0})
    other = tiny_piecewise_plan(2, clamp=(0, 100))
    renamed = {**man, "outputs": {**man["outputs"], "fields": [{**f, "name": "z"} for f in man["outputs"]["fields"]]}}
    with pytest.raises(ValueError, match=r"^manifest fields \(inputs .*\) do not match the plan's"):
        Design.from_manifest(renamed).check_plan(other)


def test_run_config_round_trip(tmp_path):
    cfg = RunConfig("/m/manifest.json", "/m/plan.json", 7, 50, ("test_pwm",))
    assert RunConfig.read(cfg.write(tmp_path / "bench.json")) == cfg
    with pytest.raises(ValueError, match=r"^n_random must be a positive integer, not 0$"):
        RunConfig("m", "p", 1, 0)
    with pytest.raises(ValueError, match=r"^seed must be a non-negative integer, not -1$"):
        RunConfig("m", "p", -1)


def _s(edge, o_valid, o_ready, i_ready, offered=False):
    return Sample(edge, offered, o_ready, o_valid, i_ready, (1, 0) if o_valid else None)


def test_pipelined_rule_catches_i_ready_violations():
    r = Pipelined(5, 1)
    r.start(10)
    assert r.check(_s(10, False, True, True), 0) == []
    assert r.check(_s(11, True, False, False), 3) == []
    assert r.check(_s(12, False, True, False), 3) == ["edge 12: i_ready low while o_ready high (stalls the stream)"]
    assert r.check(_s(13, True, False, True), 3) == ["edge 13: i_ready high while o_valid & !o_ready"]


def test_folded_rule_catches_i_ready_violations():
    r = Folded(8, 8)
    r.start(1)
    assert r.check(_s(1, False, True, True), 0) == []
    assert r.check(_s(2, False, True, False), 1) == []
    assert r.check(_s(3, True, True, True), 1) == []            # its output transfers now
    assert r.check(_s(4, True, False, True), 1) == \
        ["edge 4: i_ready 1 with 1 target(s) in flight, o_valid 1, o_ready 0"]
    assert r.check(_s(5, False, True, False), 0) != []


def test_modulo_rule_follows_the_phase_through_stalls():
    r = Modulo(10, 3)
    r.start(20)
    # phase 0 at relative edge 1 (absolute 20); en high: 0, 1, 2, 0 ...
    assert [r.check(_s(e, False, True, e in (20, 23)), 0) for e in (20, 21, 22, 23)] == [[], [], [], []]
    assert r.check(_s(24, True, False, False), 1) == []         # stall at phase 1: frozen
    assert r.check(_s(25, True, True, False), 1) == []          # phase 1, en: advances to 2
    assert r.check(_s(26, False, True, True), 0) == \
        ["edge 26: i_ready 1, expected 0 (modulo schedule: phase 2 of II 3, o_valid 0, o_ready 1)"]


def test_buffered_rule_counts_the_buffer_words():
    r = Buffered(10, 1)
    r.start(1)
    assert r.check(_s(1, False, True, True), 10) == []
    assert r.check(_s(2, True, False, False), 11) == []
    assert r.check(_s(3, True, False, True), 11) == \
        ["edge 3: i_ready 1 with 11 target(s) in flight, expected 0 (an output buffer of 11 words)"]
    assert r.check(_s(4, False, True, False), 4) != []


def test_buffered_latency_allows_waiting_only_behind_stalls():
    """An output of a buffered core is out ``latency`` edges after its input, or at the first
    edge without a stall once the one before it is out; one more edge is an error."""
    from types import SimpleNamespace

    from ikseries.sim.cocotb_leg.scoreboard import Checker, Scoreboard

    def problems(outs, stalls):
        lat = Checker("latency")
        Scoreboard(["y"], 5, 1, buffered=True)._buffered_latency(
            SimpleNamespace(in_edges=[1, 2, 3], out_edges=outs, stall_edges=stalls), lat)

    problems([6, 7, 8], [])
    problems([6, 9, 10], [7, 8])              # the second waits behind two stalls, the third behind it
    with pytest.raises(AssertionError, match="target 1"):
        problems([6, 9, 10], [7])             # an edge without a stall and without a transfer
    with pytest.raises(AssertionError, match="target 0"):
        problems([5, 7, 8], [])               # sooner than the latency


def test_modulo_pwm_timing_waits_for_the_scheduled_edges():
    r = timing_rule("modulo", 12, 4)
    sched = {"A": 100, "B": 104, "C": 200, "D": 204, "F": 405}
    assert r.pwm_period_problem(200) is None and r.pwm_period_problem(30) is not None
    t = r.pwm_timing(sched, 820)
    assert t.ready_pulses and t.i_ready_combinational and set(t.inputs) == set(sched) | {"G"}
    assert all(t.inputs[nm] < sched[nm] - 12 + 1 for nm in sched)
    assert t.o_valid[sched["A"] - 2] == 1 and t.o_valid[-1] == 1       # G waits until the reset
    p = timing_rule("pipelined", 12, 1).pwm_timing(sched, 820)
    assert p.inputs == {nm: e - 12 for nm, e in sched.items()} and np.all(p.i_ready == 1)
    with pytest.raises(ValueError, match=r"^stream rule must be one of pipelined, folded, modulo, buffered, not 'x'$"):
        timing_rule("x", 1, 1)


def test_runner_refuses_unknown_tests_and_a_mismatched_manifest(tiny, tmp_path):
    plan_file = tmp_path / "plan.json"
    plan_file.write_text(tiny.dumps())
    with pytest.raises(ValueError, match=r"^testcase must name tests from test_back_to_back, test_backpressure, "
                                         r"test_pwm, not 'test_pmw'$"):
        run(plan_file, 64, "icarus", tmp_path / "b", testcase="test_back_to_back,test_pmw")
    man = tmp_path / "manifest.json"
    man.write_text(json.dumps(bench_manifest(tiny, LegCore(tiny, 64), "tiny_core")))
    with pytest.raises(ValueError, match=r"has a PWM period of \[64\] cycles, not 128$"):
        run(plan_file, 128, "icarus", tmp_path / "b", manifest=man)
    with pytest.raises(ValueError, match=r"^name must be the manifest's module 'tiny_core', not 'other'$"):
        run(plan_file, 64, "icarus", tmp_path / "b", manifest=man, name="other")
