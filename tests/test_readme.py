"""The README stays true: its setup commands, and every TOML block of "Describing your own
robot" is a valid robot description (whole, as changes to a named file, or an excerpt of one)."""
from __future__ import annotations

import copy
import dataclasses
import re
import tomllib
from pathlib import Path

import pytest

from ikseries.robot import RobotError, load_preset, parse_robot
from test_chain import HEXAPOD_CHAIN, _robot_data

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
#: a block's first line when it holds only what differs from FILE, or an excerpt of FILE
HEADER = re.compile(r"# (changes to|from) (\S+)\n")


def toml_blocks(text: str) -> list[str]:
    return re.findall(r"```toml\n(.*?)```", text, re.S)


def merge(base: dict, changes: dict) -> dict:
    """``base`` with ``changes`` applied: tables merge key by key, other values replace, and a
    ``geometry`` of another ``type`` replaces the whole geometry table."""
    out = copy.deepcopy(base)
    for key, value in changes.items():
        new_type = key == "geometry" and "type" in value and value["type"] != out.get(key, {}).get("type")
        if isinstance(value, dict) and isinstance(out.get(key), dict) and not new_type:
            out[key] = merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def block_robot(block: str):
    """The robot a README block describes; an excerpt must be one of its file, a change must
    change it."""
    data = tomllib.loads(block)
    m = HEADER.match(block)
    if m is None:
        return parse_robot(data, "README block")
    path = ROOT / m.group(2)
    base = tomllib.loads(path.read_text())
    merged = merge(base, data)
    if m.group(1) == "from":
        assert merged == base, f"README block is not an excerpt of {m.group(2)}"
    else:
        assert merged != base, f"README block changes nothing in {m.group(2)}"
    return parse_robot(merged, f"README block on {m.group(2)}", path.parent)


def _section(title: str) -> str:
    return README.split(f"## {title}\n", 1)[1].split("\n## ", 1)[0]


BLOCKS = toml_blocks(_section("Describing your own robot"))


def test_the_walkthrough_has_its_steps():
    # the whole default robot, joint conventions, a chain, a URDF, a body, per-servo calibration
    assert len(BLOCKS) == 6 and len(toml_blocks(README)) == len(BLOCKS)


@pytest.mark.parametrize("k", range(len(BLOCKS)))
def test_readme_toml_block_is_a_valid_robot(k):
    block_robot(BLOCKS[k])


def test_readme_example_robot_is_the_default_preset():
    robot = block_robot(BLOCKS[0])
    preset = load_preset("cylinder-leg")
    assert dataclasses.replace(robot, name=preset.name, description=preset.description) == preset


def test_readme_blocks_describe_what_their_steps_say():
    conventions, chain, urdf, body, calibration = (block_robot(b) for b in BLOCKS[1:])
    assert conventions.geometry.angle_directions == (1, 1, -1)
    # "the hexapod leg again": the chain whose IK tests/test_chain.py checks against the closed form
    assert chain.geometry == parse_robot(_robot_data("hexapod-leg", HEXAPOD_CHAIN)).geometry
    assert [j.name for j in urdf.geometry.joints] == ["base_yaw", "shoulder", "elbow"]
    mounts = [dataclasses.replace(leg, servos=()) for leg in load_preset("phoenix").body.legs]
    assert list(body.body.legs) == mounts          # the Phoenix's mounts (its preset adds per-leg clamps)
    assert sorted(calibration.calibration.servos) == ["s1", "s2", "s3"]


def test_a_bad_readme_block_is_refused():
    bad = BLOCKS[2].replace("range = [0, 90]", "range = [90, 0]")
    with pytest.raises(RobotError, match=r"^geometry.joints\[2\].range must be \[min, max\] deg with min < max"):
        block_robot(bad)
    with pytest.raises(AssertionError, match="not an excerpt of examples/desk-arm/desk-arm.toml"):
        block_robot(BLOCKS[3].replace('"pen_tip"', '"pen_holder"'))


def test_readme_keeps_the_setup_and_test_commands():
    assert '```sh\napt-get install -y iverilog && pip install -e ".[dev]" && ikseries build\n```' in README
    assert "```sh\npython -m pytest -n 2 -q\n```" in README
