"""The robots in examples/ build end to end from a fresh clone: `ikseries build` on the desk arm,
a chain read only from its URDF file (examples/desk-arm/), certified within the tolerance and
bit-exact in the Amaranth simulation and in cocotb on Icarus."""
import json
from pathlib import Path

import pytest

from ikseries.cli import main
from ikseries.robot import load_robot

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
DESK_ARM = EXAMPLES / "desk-arm" / "desk-arm.toml"


def test_desk_arm_is_a_urdf_chain_with_its_bench_calibration():
    robot = load_robot(DESK_ARM)
    assert robot.geometry.inputs == ("x", "y", "z")
    # base_yaw 40 mm above base_link, the shoulder 30 mm above that; the pen tip on two fixed joints
    assert [j.xyz for j in robot.geometry.joints] == [(0, 0, 40), (0, 0, 30), (80, 0, 0)]
    assert robot.geometry.tip == (120, 0, 0)
    assert robot.calibration.servos["s2"].us_per_degree == 10.4


@pytest.mark.long
def test_desk_arm_builds_certified_and_bit_exact(tmp_path):
    out = tmp_path / "desk-arm"
    assert main(["build", str(DESK_ARM), "--cocotb", "icarus", "-q", "-o", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    man = json.loads((out / "manifest.json").read_text())
    assert (out / "report.md").is_file() and (out / "desk_arm_core.v").is_file()
    assert rep["tolerance_pu"] == 0.5
    for s in rep["servos"]:
        assert s["certificate"]["converged"] and s["certificate"]["total_pu"] <= 0.5, s["name"]
        assert s["error_pu"]["total"] <= s["certificate"]["total_pu"], s["name"]
    assert rep["simulation"]["simulator"] == "amaranth" and rep["simulation"]["mismatches"] == 0
    assert rep["simulation"]["targets"] >= 1000
    c = rep["cocotb"]["icarus"]
    assert rep["cocotb_note"] is None and c["passed"] and c["tests"] == ["test_back_to_back", "test_backpressure"]
    assert c["latency_cycles_measured"] == rep["latency_cycles"] == man["latency_cycles"]
    assert "bit-exact" in (out / "cocotb_icarus.log").read_text()
    assert [p["port"] for p in man["pwm"]] == ["pwm_s1", "pwm_s2", "pwm_s3"]
    assert [s["trim_us"] for s in rep["calibration"]] == [0.0, 8.0, 0.0]
