"""`ikseries build --board` end to end (with --long: a fit, a bitstream and a Verilator model):
the hexapod on a ULX3S-25F, its manifest and report, `ikseries program` on the build directory,
and the host library driving the build's controller behind `serve`'s pty."""
import json

import pytest

from ikseries.cli import main

pytestmark = pytest.mark.long


@pytest.fixture(scope="module")
def board_build(tmp_path_factory):
    out = tmp_path_factory.mktemp("board") / "build"
    assert main(["build", "--preset", "hexapod", "--board", "ulx3s-25f", "--no-synth", "--cocotb", "none",
                 "-q", "-o", str(out)]) == 0
    return out


def test_manifest_report_and_bitstream(board_build):
    man, rep = (json.loads((board_build / f).read_text()) for f in ("manifest.json", "report.json"))
    b = man["board"]
    assert b["board"] == "ulx3s-25f" and b["controller_module"] == "hexapod_core_controller"
    assert [c["channel"] for c in b["channels"]] == list(range(18))
    assert [(c["leg"], c["servo"]) for c in b["channels"][:4]] == [(0, "s1"), (0, "s2"), (0, "s3"), (1, "s1")]
    assert len({c["pin"] for c in b["channels"]}) == 18
    assert b["clock"]["achieved_hz"] == rep["clock_hz"] == 24e6
    assert rep["board"]["meets_clock"] and rep["board"]["fmax_mhz"] * 1e6 >= b["clock"]["achieved_hz"]
    assert (board_build / "bitstream" / "hexapod_core.bit").stat().st_size > 100_000
    assert (board_build / "hexapod_core_controller.v").read_text().count("module hexapod_core_controller(") == 1
    md = (board_build / "report.md").read_text()
    assert "## Board" in md and "| gpio_0:0+ |" in md and f"Fmax of the whole top {rep['board']['fmax_mhz']:g} MHz" in md
    p = rep["board"]["servo_pulses"]
    assert p["lead_cycles"] + p["max_width_cycles"] == man["pwm"][0]["period_cycles"]
    assert f"rises at once, {p['lead_cycles']:,} cycles" in md


def test_program_takes_the_build_directory(board_build, capsys, monkeypatch):
    monkeypatch.delenv("OPENFPGALOADER", raising=False)
    assert main(["program", str(board_build)]) == 1          # no board attached here
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("no board answered" in err or "openFPGALoader cannot start" in err)


def test_host_drives_the_build_behind_serve(board_build, tmp_path):
    from ikseries.host.controller import Controller
    from ikseries.hostcmd import build_info, port_targets
    from ikseries.robot import load_preset
    from ikseries.sim.serve import build_server
    man = json.loads((board_build / "manifest.json").read_text())
    b = man["board"]
    server = build_server((board_build / f"{b['controller_module']}.v").read_text(), b["controller_module"], 18,
                          b["uart_divisor"], man["pwm"][0]["period_cycles"], tmp_path / "serve")
    info = build_info(board_build)
    with server.start() as s:
        host = Controller(s.pty, 1e6, timeout=60)
        assert bytes(host.manifest) == info.digest and host.name == "hexapod"
        host.enable(range(18))
        host.move(2, port_targets(info, ["70", "0", "0"]))
        clock = b["clock"]["achieved_hz"]
        widths = s.wait_widths(lambda w: w[6] not in (0, None), timeout=300)
        want = [p * 0.5 for p in load_preset("hexapod").pulses_pu(70.0, 0.0, 0.0)]
        got = [w * 1e6 / clock for w in widths[6:9]]
        assert all(abs(g - w) <= 0.25 for g, w in zip(got, want)), (got, want)    # ±0.5 pu of 0.5 µs


def test_hexapod_on_the_icebreaker_meets_its_clock(tmp_path):
    """The issue's command: the hexapod's whole top on the iCE40UP5K at its 24 MHz clock."""
    out = tmp_path / "build"
    assert main(["build", "--preset", "hexapod", "--board", "icebreaker", "--no-synth", "--cocotb", "none",
                 "-q", "-o", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    b = rep["board"]
    assert b["board"] == "icebreaker" and b["meets_clock"] and b["fmax_mhz"] >= 24.0
    assert b["utilisation"]["LC"]["used"] <= b["utilisation"]["LC"]["available"]
    assert (out / "bitstream" / "hexapod_core.bin").stat().st_size > 100_000
    assert [c["pin"] for c in b["channels"][:2]] == ["pmod_0:1", "pmod_0:2"]
