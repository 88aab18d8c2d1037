"""The host commands' argument checks (before anything is sent) and the board options of
`ikseries build`, `serve` and `program` refused in one line before any fit."""
import hashlib
import json

import pytest

from ikseries.cli import main
from ikseries.hostcmd import HostCommandError, build_info, port_targets

MANIFEST = {"inputs": {"fields": [
    {"name": "leg", "range": [0, 5]},
    {"name": "x", "unit": "mm", "frac_bits": 2, "range": [216, 376]},
    {"name": "z", "unit": "mm", "frac_bits": 0, "range": [-20, 30]}]},
    "board": {"board": "icebreaker", "controller_module": "r_controller", "channels": []}}


@pytest.fixture
def build_dir(tmp_path):
    text = json.dumps(MANIFEST)
    (tmp_path / "manifest.json").write_text(text)
    return tmp_path, hashlib.sha256(text.encode()).digest()[:8]


def test_targets_in_the_robots_units_become_port_integers(build_dir):
    info = build_info(build_dir[0])
    assert info.digest == build_dir[1] and [f["name"] for f in info.inputs] == ["x", "z"]
    assert port_targets(info, ["54", "-20"]) == (216, -20)
    assert port_targets(info, ["70.3", "29.6"]) == (281, 30)      # round(70.3 * 4), round(29.6)
    with pytest.raises(HostCommandError, match=r"^x must be a number in \[54, 94\] mm, not '94.5'$"):
        port_targets(info, ["94.5", "0"])
    with pytest.raises(HostCommandError, match=r"^z must be a number in \[-20, 30\] mm, not 'q'$"):
        port_targets(info, ["60", "q"])
    with pytest.raises(HostCommandError, match=r"^a target must give 2 values \(x \[mm\], z \[mm\]\), not 3$"):
        port_targets(info, ["60", "0", "1"])


def test_a_directory_without_a_board_manifest_is_refused(tmp_path, capsys):
    with pytest.raises(HostCommandError, match=r"^--build must be a build directory made with `ikseries build "
                                               r"--board`, not '.*' \(no manifest.json naming a board there\)$"):
        build_info(tmp_path)
    (tmp_path / "manifest.json").write_text(json.dumps({"inputs": {"fields": []}}))
    assert main(["serve", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip().endswith("(no manifest.json naming a board there)")
    assert main(["program", str(tmp_path)]) == 2
    assert "must be a bitstream or a build directory made with --board" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["--servo-pins", "pmod_0:1"], "--servo-pins needs --board (a board to put the controller on), not 'pmod_0:1' alone"),
    (["--board", "nope"], "board must be one of icebreaker, ulx3s-25f, ulx3s-85f or a board file (.toml), not 'nope'"),
    (["--board", "icebreaker", "--baud", "fast"], "--baud must be a positive integer (bits per second), not 'fast'"),
    (["--board", "icebreaker", "--servo-pins", "pmod_0:1,pmod_0:1"], "servo_pins must name 18 pins (one per pwm channel), not 2"),
])
def test_build_board_options_are_refused_before_the_fit(argv, message, capsys, tmp_path):
    assert main(["build", "--preset", "hexapod", "-q", "-o", str(tmp_path / "b"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"ikseries: error: {message}" and not (tmp_path / "b").exists()


def test_serve_needs_a_build_or_every_option(capsys):
    assert main(["serve", "--top", "t"]) == 2
    assert capsys.readouterr().err.strip() == ("ikseries: error: serve needs a build directory made with --board, "
                                               "or --verilog, --channels, --divisor, --period, --clock-hz")


def test_move_needs_the_build_for_its_units(capsys):
    assert main(["move", "--port", "/dev/null", "0", "1", "2"]) == 2
    assert capsys.readouterr().err.strip().startswith("ikseries: error: move needs --build DIR")
