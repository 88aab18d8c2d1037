"""`ikseries build` end to end on the six-legged robot (shared core) and on a folded single leg."""
import json
import re

import pytest

from ikseries.cli import main
from ikseries.hdl.shared import RobotCore
from ikseries.robot import load_preset, preset_text


def _ports(verilog, module):
    top = re.search(rf"^module {module}\(.*?^endmodule", verilog, re.M | re.S).group(0)
    return {name: int(w) + 1 if w else 1 for w, name in
            re.findall(r"^\s*(?:input|output)\s+(?:\[(\d+):0\]\s+)?(\w+);", top, re.M)}


@pytest.fixture(scope="module")
def hexapod(tmp_path_factory):
    out = tmp_path_factory.mktemp("hexapod") / "build"
    # cocotb on Icarus runs the bench on the exported robot top (random legs, II > 1)
    assert main(["build", "--preset", "hexapod", "--no-synth", "--cocotb", "icarus", "-q", "-o", str(out)]) == 0
    return out


def test_hexapod_build_report_and_ports(hexapod):
    rep = json.loads((hexapod / "report.json").read_text())
    man = json.loads((hexapod / "manifest.json").read_text())
    robot = load_preset("hexapod")
    assert sorted(p.name for p in hexapod.iterdir()) == [
        ".ikseries-build.json", "cocotb_icarus.log", "error_map.png", "hexapod_core.sdc", "hexapod_core.v", "manifest.json", "plan.json",
        "report.json", "report.md"]
    a = rep["architecture"]
    assert (a["architecture"], a["multipliers"], a["dsp"], a["legs"]) == ("shared", 1, "ice40", 6)
    # the rate comes from the core's initiation interval, which the simulation measured
    ii = rep["initiation_interval"]
    assert rep["simulation"]["initiation_interval_measured"] == ii == man["initiation_interval"]
    assert rep["simulation"]["latency_cycles_measured"] == rep["latency_cycles"] == man["latency_cycles"]
    assert rep["refresh_hz"] == man["refresh_hz"] == robot.hardware.clock_hz / (6 * ii) >= 1000
    assert rep["simulation"]["mismatches"] == rep["simulation"]["leg_mismatches"] == 0
    assert rep["simulation"]["legs_addressed"] == [0, 1, 2, 3, 4, 5]
    c = rep["cocotb"]["icarus"]
    assert rep["cocotb_note"] is None and c["passed"]
    assert c["tests"] == ["test_back_to_back", "test_backpressure"]
    assert c["latency_cycles_measured"] == rep["latency_cycles"] and c["initiation_interval"] == ii
    assert c["random_targets"] == min(1000, 60_000 // ii)
    log = (hexapod / "cocotb_icarus.log").read_text()
    assert f"one every {ii} cycle(s), legs [0, 1, 2, 3, 4, 5]: bit-exact" in log
    assert all(s["error_pu"]["total"] <= 0.5 for s in rep["servos"])
    ports = _ports((hexapod / "hexapod_core.v").read_text(), "hexapod_core")
    pwm = sorted(p for p in ports if p.startswith("pwm_"))
    assert len(pwm) == 18 and "pwm_l0_s1" in pwm and "pwm_l5_s3" in pwm
    assert sorted(p["port"] for p in man["pwm"]) == pwm
    for f in man["inputs"]["fields"] + man["outputs"]["fields"]:
        assert ports[f["port"]] == f["width"], f
    assert ports["i_leg"] == ports["o_leg"] == 3
    md = (hexapod / "report.md").read_text()
    assert f"cocotb on icarus (exported Verilog): test_back_to_back, test_backpressure passed ({c['random_targets']} " \
           f"random targets plus the corners), latency {ii} cycles, a target every {ii} cycles" in md
    assert "cocotb skipped" not in md and "Refresh rate" in md and "folded evaluator shared by 6 legs" in md
    assert "create_clock -name clk -period 41.6667 [get_ports {clk}]" in (hexapod / "hexapod_core.sdc").read_text()


def test_hexapod_core_rate_matches_a_rebuilt_core(hexapod):
    """The report's figures are those of the component built from plan.json (not a formula)."""
    from ikseries.fit.plan import Plan
    rep = json.loads((hexapod / "report.json").read_text())
    plan = Plan.from_json(json.loads((hexapod / "plan.json").read_text()))
    robot = load_preset("hexapod")
    core = RobotCore(plan, 6, robot.hardware.pwm_period_ticks, robot.hardware.clock_hz, multipliers=1, dsp=(16, 16))
    assert (core.latency, core.initiation_interval, core.refresh_hz) == (
        rep["latency_cycles"], rep["initiation_interval"], rep["refresh_hz"])


def test_single_leg_folded_build_from_the_command_line(tmp_path, capsys, monkeypatch, small_fitted):
    """A folded leg from the command line, from the run's fit of the small leg (the same fit
    record: only the name differs); cocotb of folded Verilog is in test_cocotb.py, the build's
    cocotb step on a folded (shared) core in the hexapod build."""
    import ikseries.steps
    monkeypatch.setattr(ikseries.steps, "fit_robot", lambda robot, progress, **options: small_fitted)
    toml = tmp_path / "small-leg.toml"
    toml.write_text(preset_text("cylinder-leg").replace('name = "cylinder-leg"', 'name = "small-leg"')
                    .replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 "))
    out = tmp_path / "out"
    assert main(["build", str(toml), "--architecture", "folded", "--multipliers", "2", "--dsp", "none",
                 "--no-synth", "--cocotb", "none", "-q", "-o", str(out)]) == 0
    assert "2 multipliers (full-width)" in capsys.readouterr().out
    rep = json.loads((out / "report.json").read_text())
    a = rep["architecture"]
    assert (a["architecture"], a["multipliers"], a["dsp"], a["legs"]) == ("folded", 2, "none", 1)
    assert a["reason"].startswith("hardware.architecture = folded")
    ii = rep["initiation_interval"]
    assert ii > 1 and rep["simulation"]["initiation_interval_measured"] == ii
    assert rep["refresh_hz"] == 48e6 / ii and rep["cocotb"] == {} and rep["cocotb_note"] is None
    assert rep["simulation"]["latency_cycles_measured"] == rep["latency_cycles"]
    ports = _ports((out / "small_leg_core.v").read_text(), "small_leg_core")
    assert {"pwm_s1", "pwm_s2", "pwm_s3", "i_r", "o_s1"} <= set(ports) and "i_leg" not in ports


def test_modulo_build_with_dsp_sized_products_on_ecp5_primitives(tmp_path, capsys):
    """The ECP5 configuration end to end: products fitted to 18x18 operands (fit.products = dsp),
    a modulo core whose products run on instantiated MULT18X18D blocks; the Amaranth simulation
    runs the fabric twin, cocotb the exported Verilog with the primitive's model (shipped with
    the build)."""
    toml = tmp_path / "small-leg.toml"
    toml.write_text(preset_text("cylinder-leg").replace('name = "cylinder-leg"', 'name = "small-leg"')
                    .replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 "))
    out = tmp_path / "out"
    assert main(["build", str(toml), "--architecture", "modulo", "--interval", "4", "--dsp", "ecp5",
                 "--dsp-primitives", "--products", "dsp", "--no-synth", "--cocotb", "icarus", "-q",
                 "-o", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    man = json.loads((out / "manifest.json").read_text())
    plan = json.loads((out / "plan.json").read_text())
    assert plan["meta"]["method"]["operand_bits"] == [18, 18]
    assert man["primitives"]["cells"] == ["MULT18X18D"]
    assert rep["simulation"]["mismatches"] == 0 and rep["cocotb"]["icarus"]["passed"]
    assert rep["cocotb"]["icarus"]["latency_cycles_measured"] == rep["latency_cycles"]
    verilog = (out / "small_leg_core.v").read_text()
    assert "MULT18X18D" in verilog and (out / "sim_models" / "MULT18X18D.v").is_file()
