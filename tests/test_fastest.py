"""hardware.architecture = "fastest": the fastest configuration whose Yosys counts fit
hardware.fit_device. The choice is tested with an injected fake synthesis; one test runs Yosys."""
import argparse
import dataclasses
import tomllib

import pytest

from ikseries.architecture import ArchitectureError, build_target, candidates, choose_architecture
from ikseries.cli import _hardware_overrides
from ikseries.report import _throughput_lines
from ikseries.robot import parse_robot, preset_text, robot_from_record, robot_record


@pytest.fixture
def fastest(small_robot):
    return dataclasses.replace(small_robot, hardware=dataclasses.replace(small_robot.hardware, architecture="fastest",
                                                                        fit_device="ecp5-25f", dsp="ecp5"))


class FakeSynth:
    """Counts from ``counts(candidate)``; remembers what it synthesised and for which target."""

    def __init__(self, counts):
        self.counts = counts
        self.calls = []

    def __call__(self, cand, core, target):
        self.calls.append(((cand.name, cand.multipliers or cand.interval), target))
        return {"LUT": 1000, "FF": 1000, "carry": 100, "DSP": 4, "BRAM": 0, **self.counts(cand)}


def _rates(robot, plan):
    """(architecture, multipliers or initiation interval) -> refresh Hz, from the built cores."""
    out = {}
    for c in candidates(robot):
        core = c.build(plan, build_target(robot))
        out[(c.name, c.multipliers or c.interval)] = robot.hardware.clock_hz / core.initiation_interval
    return out


def test_fastest_fitting_configuration_is_chosen(fastest, small_plan):
    rates = _rates(fastest, small_plan)
    # the pipelined core overflows the DSPs; the fastest folded one overflows the LUTs
    order = sorted(rates, key=lambda c: (-rates[c], c[1] or 0))
    assert order[0] == ("pipelined", None)
    too_big = order[1]
    synth = FakeSynth(lambda c: {"DSP": 40} if c.name == "pipelined" else
                      {"LUT": 30000} if (c.name, c.multipliers or c.interval) == too_big else {})
    msgs = []
    c = choose_architecture(fastest, small_plan, synth=synth, progress=msgs.append)
    assert [call for call, _ in synth.calls] == order[:3] and {t for _, t in synth.calls} == {"ecp5"}
    cand = c.candidate
    assert (cand.name, cand.multipliers or cand.interval, cand.dsp) == (*order[2], "ecp5")
    assert c.refresh_hz == rates[order[2]] == fastest.hardware.clock_hz / c.core.initiation_interval
    rej = [t.rejected for t in c.tried]
    assert rej[0] == ("does not fit LFE5U-25F by Yosys cell counts (before place-and-route): DSP 40 > 28")
    assert rej[1].endswith("LUT 30,000 > 24,288") and rej[2] is None
    assert [t.counts["DSP"] for t in c.tried] == [40, 4, 4]
    assert c.reason.startswith("fastest: the fastest configuration whose Yosys cell counts fit LFE5U-25F "
                               "(hardware.fit_device = ecp5-25f; LUT 1,000/24,288, FF 1,000/24,288, DSP 4/28, "
                               "BRAM 0/56; an estimate before place-and-route")
    assert "faster ones rejected: pipelined (one target per cycle): does not fit" in c.reason
    assert "slower ones, not tried: " in c.reason
    rec = c.record()
    assert rec["fit_device"] == {"name": "ecp5-25f", "part": "LFE5U-25F",
                                 "capacity": {"LUT": 24288, "FF": 24288, "DSP": 28, "BRAM": 56}}
    assert [t["rejected"] is None for t in rec["tried"]] == [False, False, True]
    assert rec["tried"][0]["counts"]["DSP"] == 40 and rec["tried"][0]["initiation_interval"] == 1
    assert any("rejected" in m for m in msgs)
    # the report lists every candidate tried with its counts and why it was rejected
    lines = "\n".join(_throughput_lines({"initiation_interval": c.core.initiation_interval,
                                         "throughput_targets_per_s": c.refresh_hz, "simulation": {},
                                         "architecture": rec}))
    assert "| pipelined (one target per cycle) | 1 | 48,000,000 | 1,000 | 1,000 | 40 | 0 | does not fit" in lines
    assert "**chosen**" in lines


def test_no_configuration_fits_names_the_smallest_and_the_overflow(fastest, small_plan):
    synth = FakeSynth(lambda c: {"DSP": 130 if c.name == "pipelined" else 30 + (c.multipliers or 0)})
    with pytest.raises(ArchitectureError) as e:
        choose_architecture(fastest, small_plan, synth=synth)
    assert len(synth.calls) == len(candidates(fastest)) == 8   # pipelined, 4 modulo, 3 folded
    rate = _rates(fastest, small_plan)[("folded", 1)]
    assert str(e.value) == (
        "hardware.fit_device = ecp5-25f: no configuration fits LFE5U-25F by Yosys cell counts (before "
        f"place-and-route); the smallest synthesised, folded, 1 multiplier (ecp5 18x18 DSP) ({rate:,.0f} Hz), "
        "needs DSP 31 > 28")


def test_slower_than_min_refresh_is_not_synthesised(fastest, small_plan):
    rates = _rates(fastest, small_plan)
    slow = max(v for k, v in rates.items() if k[0] == "folded") * 1.01
    synth = FakeSynth(lambda c: {"DSP": 130})
    slow_robot = dataclasses.replace(fastest, hardware=dataclasses.replace(fastest.hardware, min_refresh_hz=slow))
    with pytest.raises(ArchitectureError) as e:
        choose_architecture(slow_robot, small_plan, synth=synth)
    assert [call for call, _ in synth.calls] == [k for k in sorted(rates, key=lambda k: -rates[k])
                                                 if rates[k] >= slow]
    assert [call for call, _ in synth.calls][:2] == [("pipelined", None), ("modulo", 2)]
    assert str(e.value).endswith("needs DSP 130 > 28; slower ones are below hardware.min_refresh_hz "
                                 f"{slow:g}")
    # even the pipelined core is too slow: the rate error, nothing synthesised
    synth.calls.clear()
    slow_robot = dataclasses.replace(fastest, hardware=dataclasses.replace(fastest.hardware, min_refresh_hz=1e9))
    with pytest.raises(ArchitectureError, match="^hardware.min_refresh_hz must be at most 4.8e\\+07 Hz, the best "
                                                "rate of any architecture .*pipelined"):
        choose_architecture(slow_robot, small_plan, synth=synth)
    assert synth.calls == []


def test_several_legs_try_shared_configurations_only(fastest, small_plan):
    six = dataclasses.replace(fastest, legs=6, hardware=dataclasses.replace(fastest.hardware, fit_device="ice40-up5k",
                                                                                dsp="ice40"))
    synth = FakeSynth(lambda c: {})
    c = choose_architecture(six, small_plan, synth=synth)
    assert synth.calls[0][1] == "ice40" and len(synth.calls) == 1
    assert c.candidate.name == "shared" and c.core.legs == 6
    assert c.refresh_hz == c.core.refresh_hz


def test_fit_device_options_and_record(small_robot):
    d = tomllib.loads(preset_text("cylinder-leg"))
    d["hardware"].update(architecture="fastest", fit_device="ecp5-25f")
    r = parse_robot(d)
    hw = r.hardware
    assert (hw.architecture, hw.fit_device, hw.dsp) == ("fastest", "ecp5-25f", "ecp5")   # DSP size of the device
    assert robot_from_record(robot_record(r)) == r
    d["hardware"]["dsp"] = "none"
    assert parse_robot(d).hardware.dsp == "none"
    ns = dict(architecture=None, multipliers=None, dsp=None, fit_device=None)
    cli = _hardware_overrides(small_robot, argparse.Namespace(**{**ns, "architecture": "fastest",
                                                                 "fit_device": "xc7a35t"}))
    assert (cli.hardware.architecture, cli.hardware.fit_device, cli.hardware.dsp) == ("fastest", "xc7a35t", "xc7")
    back = _hardware_overrides(r, argparse.Namespace(**{**ns, "architecture": "auto"}))
    assert (back.hardware.architecture, back.hardware.fit_device) == ("auto", None)


def test_fastest_runs_yosys(small_robot, small_plan):
    """End to end on the small plan for the iCE40UP5K: the pipelined core needs more DSPs than
    the 8 it has; a slower (modulo-scheduled or folded) one fits."""
    robot = dataclasses.replace(small_robot, hardware=dataclasses.replace(small_robot.hardware, architecture="fastest",
                                                                          fit_device="ice40-up5k", dsp="ice40"))
    c = choose_architecture(robot, small_plan)
    first = c.tried[0]
    assert first.candidate.name == "pipelined" and first.counts["DSP"] > 8
    assert f"DSP {first.counts['DSP']} > 8" in first.rejected
    assert c.candidate.name in ("modulo", "folded") and c.tried[-1].rejected is None
    assert all("does not fit" in t.rejected for t in c.tried[:-1])
    assert 0 < c.tried[-1].counts["DSP"] <= 8 and 0 < c.tried[-1].counts["LUT"] <= 5280
