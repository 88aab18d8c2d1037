"""The command line: presets, eval, build, and one-line errors."""
import json
import re
import shutil

import pytest

from ikseries.cli import main
from ikseries.robot import preset_text


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_presets(capsys):
    code, out, _ = run(capsys, "presets")
    assert code == 0 and out.startswith("cylinder-leg\t")


@pytest.fixture(scope="module")
def small_toml(tmp_path_factory):
    p = tmp_path_factory.mktemp("robot") / "small-leg.toml"
    p.write_text(preset_text("cylinder-leg").replace('name = "cylinder-leg"', 'name = "small-leg"')
                 .replace("tolerance_pu = 0.5 ", "tolerance_pu = 4.0 ")
                 # the pipelined leg (auto would pick a folded one: cocotb on folded builds is
                 # tested in test_hexapod_build.py)
                 .replace("pwm_period_us = 20000.0", 'pwm_period_us = 20000.0\narchitecture = "pipelined"'))
    return p


@pytest.fixture(scope="module")
def built(small_toml, tmp_path_factory):
    out = tmp_path_factory.mktemp("build") / "small"
    assert main(["build", str(small_toml), "--no-synth", "--vcd", "--cocotb", "icarus", "-q",
                 "-o", str(out)]) == 0
    return out


def test_build_writes_every_artifact(built):
    names = sorted(p.name for p in built.iterdir())
    assert names == [".ikseries-build.json", "cocotb_icarus.log", "error_map.png", "manifest.json", "plan.json",
                     "report.json", "report.md", "sim.vcd", "small_leg_core.sdc", "small_leg_core.v"]
    assert json.loads((built / ".ikseries-build.json").read_text())["files"] == names[1:]
    assert (built / "error_map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    vcd = (built / "sim.vcd").read_text()
    assert "$enddefinitions" in vcd and "pwm_s1" in vcd
    assert "create_clock -name clk -period 20.8333 [get_ports {clk}]" in (built / "small_leg_core.sdc").read_text()
    rep = json.loads((built / "report.json").read_text())
    man = json.loads((built / "manifest.json").read_text())
    assert rep["simulation"]["mismatches"] == 0
    assert rep["simulation"]["latency_cycles_measured"] == rep["latency_cycles"] == man["latency_cycles"]
    assert rep["cocotb"]["icarus"]["passed"]
    assert rep["cocotb"]["icarus"]["latency_cycles_measured"] == rep["latency_cycles"]
    assert rep["cocotb"]["icarus"]["tests"] == ["test_back_to_back", "test_backpressure"]
    assert rep["accuracy_points"] >= 1_000_000
    assert all(s["error_pu"]["total"] <= 4.0 for s in rep["servos"])
    # every port the manifest names exists in the Verilog with that width
    v = (built / "small_leg_core.v").read_text()
    top = re.search(r"^module small_leg_core\(.*?^endmodule", v, re.M | re.S).group(0)
    ports = {name: int(w) + 1 if w else 1 for w, name in
             re.findall(r"^\s*(?:input|output)\s+(?:\[(\d+):0\]\s+)?(\w+);", top, re.M)}
    for f in man["inputs"]["fields"] + man["outputs"]["fields"]:
        assert ports[f["port"]] == f["width"], f
    for p in man["pwm"]:
        assert ports[p["port"]] == 1
    assert {"clk", "rst"} <= set(ports)
    md = (built / "report.md").read_text()
    assert "| s1 |" in md and "Latency" in md


def test_build_is_byte_identical(built, small_toml, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(built, out)     # an earlier build with --vcd and cocotb on icarus
    assert main(["build", str(small_toml), "--no-synth", "--cocotb", "none", "-q", "-o", str(out)]) == 0
    for f in ("small_leg_core.v", "plan.json", "manifest.json"):
        assert (out / f).read_bytes() == (built / f).read_bytes(), f
    # recorded by the earlier build, not written by this one: the stale copies are gone
    assert not (out / "sim.vcd").exists() and not (out / "cocotb_icarus.log").exists()


def test_eval_with_plan(capsys, built, small_toml):
    code, out, _ = run(capsys, "eval", "--robot", str(small_toml), "--plan", str(built / "plan.json"),
                       "10", "45", "5")
    assert code == 0
    rows = [l.split() for l in out.splitlines() if l.startswith("s")][1:]
    assert [r[0] for r in rows] == ["s1", "s2", "s3"]
    assert all(abs(float(r[4])) <= 4.0 for r in rows)


@pytest.mark.parametrize("argv, message", [
    (["eval", "50", "0", "0"], "ikseries: error: r must be within [0, 40] mm, not 50\n"),
    (["eval", "10", "0", "-1"], "ikseries: error: z must be within [0, 40] mm, not -1\n"),
    (["eval", "--preset", "planar-arm", "1", "2", "3"],
     "ikseries: error: eval needs 2 values (x, y) for planar-arm, not 3\n"),
    (["eval", "--preset", "nope", "1", "1", "1"],
     "ikseries: error: preset must be one of ['cylinder-leg', 'freenove-hexapod', 'hexapod', 'hexapod-leg', 'mearm', 'phantomx', 'phoenix', 'planar-arm', 'quadruped-fore', 'quadruped-hind', 'spotmicro'], not 'nope'\n"),
    (["build", "--preset", "cylinder-leg", "also.toml"],
     "ikseries: error: give either a robot description file or --preset, not both\n"),
    (["build", "--cocotb", "modelsim"],
     "ikseries: error: --cocotb must be auto, none or a list from icarus,verilator, not 'modelsim'\n"),
    (["build", "--table-entries", "8"],
     "ikseries: error: --table-entries must be an integer from 16 to 4096, not '8'\n"),
    (["build", "--table-entries", "many"],
     "ikseries: error: --table-entries must be an integer from 16 to 4096, not 'many'\n"),
])
def test_bad_arguments_give_one_line_errors(capsys, argv, message):
    code, out, err = run(capsys, *argv)
    assert code == 2 and err == message


def test_bad_robot_file_writes_nothing(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(preset_text("cylinder-leg").replace("tibia = 90.0", "tibia = -90.0"))
    out = tmp_path / "out"
    code, _, err = run(capsys, "build", str(bad), "-o", str(out))
    assert code == 2 and err == "ikseries: error: geometry.tibia must be > 0, not -90.0\n"
    assert not out.exists()


def test_unreachable_workspace_is_one_line(capsys, tmp_path):
    far = tmp_path / "far.toml"
    far.write_text(preset_text("cylinder-leg").replace("[workspace.r]\nmin = 0.0\nmax = 40.0",
                                                       "[workspace.r]\nmin = 0.0\nmax = 90.0"))
    code, _, err = run(capsys, "build", str(far), "-o", str(tmp_path / "out"))
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("ikseries: error: workspace: target (r=") and "is unreachable" in err


def test_unwritable_output_fails_before_fitting(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run(capsys, "build", "-q", "-o", str(blocker / "out"))
    assert code == 1 and err == (f"ikseries: error: cannot create or write the output directory "
                                 f"'{blocker / 'out'}' ('{blocker}' is not a writable directory)\n")
    code, _, err = run(capsys, "build", "-q", "-o", str(blocker))
    assert code == 1 and err == f"ikseries: error: output directory '{blocker}' exists and is not a directory\n"


def test_unmeetable_tolerance_writes_nothing(capsys, tmp_path):
    tight = tmp_path / "tight.toml"
    tight.write_text(preset_text("cylinder-leg").replace("tolerance_pu = 0.5 ", "tolerance_pu = 0.01 "))
    out = tmp_path / "out"
    code, _, err = run(capsys, "build", str(tight), "-q", "-o", str(out))
    assert code == 2 and err.startswith("ikseries: error: fit.tolerance_pu must be > 0.0277778 pu with 24 PWM "
                                        "ticks per pulse unit") and err.count("\n") == 1
    assert not out.exists() and sorted(tmp_path.iterdir()) == [tight]


def test_robot_file_not_utf8_is_one_line(capsys, tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(preset_text("cylinder-leg").replace("Futaba-style", "Futaba-st\u00fcle").encode("latin-1"))
    code, _, err = run(capsys, "build", str(bad), "-q", "-o", str(tmp_path / "out"))
    assert code == 2 and err.startswith(f"ikseries: error: robot description '{bad}' must be UTF-8 text (TOML), "
                                        "not bytes like b'\\xfcle ' at byte 250\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("content, message", [
    (None, "--plan must be a plan file, not '{path}' (a directory or other non-file)"),
    ("[1, 2]", "{path}: not a valid ikseries plan: a plan is a JSON object, not a list"),
    ('{"format": "ikseries.plan", "version": 1, "inputs": 3}', "{path}: not a valid ikseries plan: "),
    ("{", "{path}: not a valid ikseries plan: Expecting property name"),
])
def test_bad_plan_file_is_one_line(capsys, tmp_path, content, message):
    path = tmp_path / "plan.json"
    if content is None:
        path.mkdir()
    else:
        path.write_text(content)
    code, _, err = run(capsys, "eval", "--plan", str(path), "-q", "10", "45", "5")
    assert code == 2 and err.startswith("ikseries: error: " + message.format(path=path)) and err.count("\n") == 1


def test_fit_divided_differences_writes_its_report(capsys, tmp_path):
    code, out, _ = run(capsys, "fit", "--preset", "planar-arm", "--method", "divided-differences",
                       "-o", str(tmp_path / "dd"), "-q")
    assert code == 0 and "divided differences on 3 paths" in out
    assert sorted(p.name for p in (tmp_path / "dd").iterdir()) == ["divided.json", "divided.md"]
    assert "phi180-vertical" in (tmp_path / "dd" / "divided.md").read_text()


def test_fit_method_on_the_wrong_robot_is_a_one_line_error(capsys, tmp_path):
    code, _, err = run(capsys, "fit", "--method", "divided-differences", "-o", str(tmp_path / "x"), "-q")
    assert code == 2 and not (tmp_path / "x").exists()
    assert err == ("ikseries: error: --method divided-differences needs a planar-arm robot, not "
                   "'cylinder-leg' (geometry CylinderLeg)\n")


def test_fit_ikseries_reports_sampled_and_certified(capsys, tmp_path):
    code, out, _ = run(capsys, "fit", "--preset", "quadruped-hind", "-o", str(tmp_path / "f"), "-q")
    assert code == 0 and out.startswith("quadruped-hind: ikseries fit, max error")
    rec = json.loads((tmp_path / "f" / "fit.json").read_text())
    assert [s["servo"] for s in rec["servos"]] == ["s1", "s2", "s3"]
    for s in rec["servos"]:
        assert s["sampled_max_pu"] <= s["certified_total_pu"] <= 0.5
    assert (tmp_path / "f" / "plan.json").is_file()


def test_eval_plan_ignores_hardware_fields_but_not_fit_fields(capsys, built, small_toml, tmp_path):
    """A plan is reused when only the architecture differs; another tolerance is refused."""
    folded = tmp_path / "folded.toml"
    folded.write_text(small_toml.read_text().replace('architecture = "pipelined"', 'architecture = "folded"'))
    code, out, _ = run(capsys, "eval", "--robot", str(folded), "--plan", str(built / "plan.json"),
                       "10", "45", "5", "-q")
    assert code == 0 and "s3" in out
    tight = tmp_path / "tight.toml"
    tight.write_text(small_toml.read_text().replace("tolerance_pu = 4.0 ", "tolerance_pu = 2.0 "))
    code, _, err = run(capsys, "eval", "--robot", str(tight), "--plan", str(built / "plan.json"),
                       "10", "45", "5", "-q")
    assert code == 2 and err == (f"ikseries: error: {built / 'plan.json'} was fitted for a different "
                                 "robot description than 'small-leg'\n")
