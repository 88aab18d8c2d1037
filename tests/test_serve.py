"""``ikseries serve`` and :mod:`ikseries.sim.serve` on a small design with the board top's contract:
the project's UART echoes every byte back plus one, and a 4-channel servo PWM bank takes each
byte, round robin, as a pulse width of 4 * byte cycles. One Verilator build for the module."""
from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial
from amaranth.back import verilog
from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ikseries.cli import main
from ikseries.hdl.pwmbank import ServoPWMBank
from ikseries.hdl.top import design_channels
from ikseries.hdl.uart import UARTRx, UARTTx
from ikseries.sim.runner import verilator_tools
from ikseries.servecmd import format_report, speed_line
from ikseries.sim.serve import build_server, check_design_ports

pytestmark = pytest.mark.skipif(not verilator_tools()[0], reason=verilator_tools()[1] or "verilator")

DIVISOR, PERIOD, CHANNELS, SCALE = 8, 1000, 4, 4
TOP = "echo_pwm"


class EchoPWM(wiring.Component):
    """Echoes each byte plus one; byte ``b`` sets the next channel's width to ``SCALE * b``
    cycles (at least ``PERIOD``: the line is held high)."""

    def __init__(self):
        super().__init__({"rx": In(1), "tx": Out(1, init=1), "pwm": Out(CHANNELS)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.urx = urx = UARTRx(DIVISOR)
        m.submodules.utx = utx = UARTTx(DIVISOR)
        m.submodules.bank = bank = ServoPWMBank(PERIOD, 10, CHANNELS, 1)
        take = urx.o.valid & utx.i.ready
        chan = Signal(range(CHANNELS))
        m.d.comb += [urx.rx.eq(self.rx), self.tx.eq(utx.tx), self.pwm.eq(bank.pwm),
                     utx.i.payload.eq(urx.o.payload + 1), utx.i.valid.eq(urx.o.valid), urx.o.ready.eq(utx.i.ready),
                     bank.i.valid.eq(take), bank.i.payload.group.eq(chan),
                     bank.i.payload.widths[0].eq(urx.o.payload * SCALE)]
        with m.If(take):
            m.d.sync += chan.eq(chan + 1)
        return m


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    design = EchoPWM()
    assert design_channels(design) == CHANNELS        # what BoardTop would accept
    text = verilog.convert(design, name=TOP, emit_src=False)
    wd = tmp_path_factory.mktemp("serve")
    (wd.parent / f"{TOP}.v").write_text(text)
    return build_server(text, TOP, CHANNELS, DIVISOR, PERIOD, wd, cxx_opt="-O1"), text, wd


def _snapshot(d: Path) -> dict:
    return {p: p.stat().st_mtime_ns for p in d.rglob("*")}


def _processes_running(binary: Path) -> list[int]:
    found = []
    for p in Path("/proc").iterdir():
        try:
            if p.name.isdigit() and Path(os.readlink(p / "exe")) == binary:
                found.append(int(p.name))
        except OSError:
            pass
    return found


def test_build_writes_only_its_own_files(built):
    server, _, wd = built
    assert sorted(p.name for p in wd.iterdir()) == [f"{TOP}.v", "obj", "serve.cpp"]
    assert server.binary == wd / "obj" / f"V{TOP}" and server.build_s > 0


def test_bytes_echo_through_the_pty(built):
    server, _, _ = built
    sent = bytes(range(0, 256, 3))
    with server.start() as s:
        with serial.Serial(s.pty, baudrate=115200, timeout=5) as port:
            port.write(sent)
            got = port.read(len(sent))
        st = s.status()
    assert got == bytes((b + 1) % 256 for b in sent)
    assert st["rx_bytes"] == st["tx_bytes"] == len(sent) and st["framing_errors"] == 0
    assert s.slowdown(2 * st["cycles_per_second"], st) == 2


def test_report_and_speed_lines():
    assert format_report({"cycle": 1_500_000, "widths": [72_000, 0, None]}, 48e6) == \
        "t=0.0312 s  pulse us: 1500.00 - high"
    assert speed_line({"cycles_per_second": 4_000_000}, 48e6, 960_000) == (
        "simulating 4.00 M cycles/s, 12.0 times slower than the 48 MHz board: one 20 ms PWM period "
        "takes 240 ms; give host timeouts 12.0 times their margin")


def test_reported_widths_are_what_the_design_was_told(built):
    server, _, _ = built
    first, second = [10, 200, 0, 100], [30, 255, 60, 249]
    with server.start() as s:
        fd = os.open(s.pty, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, bytes(first))
            assert s.wait_widths(lambda w: w == [SCALE * b for b in first], 10)
            st = s.status()
            os.write(fd, bytes(second))
            # 255 * SCALE is longer than the period: the line is held high
            assert s.wait_widths(lambda w: w == [120, None, 240, 996], 10)
        finally:
            os.close(fd)
        history = [r["widths"] for r in s.history]
    assert st["periods"] == [PERIOD, PERIOD, 0, PERIOD] and st["widths"] == [40, 800, 0, 400]
    # reset widths, no pulse: the first report (three periods in) comes at the first look at the
    # pty, before any byte read there reaches the design
    assert history[0] == [0, 0, 0, 0]
    allowed = [{0, SCALE * a, SCALE * b} for a, b in zip(first, second)]
    allowed[1].add(None)
    assert all(w in ok for ws in history for w, ok in zip(ws, allowed)), history


@pytest.mark.parametrize("how", ["stop", "sigint"])
def test_stops_cleanly(built, how):
    server, _, wd = built
    before = _snapshot(wd)
    s = server.start()
    st = s.status()
    if how == "sigint":
        os.kill(s.pid, signal.SIGINT)
        deadline = time.monotonic() + 10
        while s.running and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not s.running     # stopped by the signal, not by stop()'s SIGTERM below
    final = s.stop()
    assert final["event"] == "stopped" and final["cycle"] >= st["cycle"] > 0
    assert s.returncode == 0 and _processes_running(server.binary) == []
    assert _snapshot(wd) == before


def _alive(pid: int) -> bool:
    try:
        return "\nState:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False


def test_server_ends_with_its_parent(built):
    """A Python parent killed without a chance to stop the server: its stdin closes, it stops."""
    server, _, _ = built
    code = ("import sys, time\nfrom pathlib import Path\nfrom ikseries.sim.serve import Server\n"
            f"s = Server(Path({str(server.binary)!r}), {TOP!r}, {CHANNELS}, {DIVISOR}, {PERIOD}, 0.0).start()\n"
            "print(s.pid, flush=True)\ntime.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        pid = int(parent.stdout.readline())
        assert _alive(pid)
    finally:
        parent.kill()
        parent.wait()
        parent.stdout.close()
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not _alive(pid)


def test_design_and_parameter_errors(built, tmp_path):
    _, text, _ = built
    with pytest.raises(ValueError, match=r"^the Verilog has no module robot$"):
        check_design_ports(text, "robot", CHANNELS)
    with pytest.raises(ValueError, match=r"^module echo_pwm's port pwm must be an output of 18 bit\(s\), "
                                         r"not an output of 4$"):
        check_design_ports(text, TOP, 18)
    no_tx = text.replace("  output tx;\n", "")
    with pytest.raises(ValueError, match=r"^module echo_pwm must have a port tx \(output\), not none$"):
        check_design_ports(no_tx, TOP, CHANNELS)
    with pytest.raises(ValueError, match=r"^top must be a plain Verilog identifier, not '1x'$"):
        check_design_ports(text, "1x", CHANNELS)
    with pytest.raises(ValueError, match=r"^divisor must be an integer >= 4, not 3$"):
        build_server(text, TOP, CHANNELS, 3, PERIOD, tmp_path)
    with pytest.raises(ValueError, match=r"^channels must be at most 64, not 65$"):
        build_server(text, TOP, 65, DIVISOR, PERIOD, tmp_path)
    assert list(tmp_path.iterdir()) == []


def _serve_args(verilog_path, **over):
    opts = {"--verilog": str(verilog_path), "--top": TOP, "--channels": str(CHANNELS), "--divisor": str(DIVISOR),
            "--period": str(PERIOD), "--clock-hz": "1e6"} | over
    return ["serve", *[x for kv in opts.items() for x in kv]]


@pytest.mark.parametrize("over, message", [
    ({"--verilog": "nowhere/top.v"}, "--verilog file 'nowhere/top.v' does not exist"),
    ({"--divisor": "3"}, "--divisor must be an integer >= 4 (clock cycles per bit), not '3'"),
    ({"--divisor": "fast"}, "--divisor must be an integer >= 4 (clock cycles per bit), not 'fast'"),
    ({"--channels": "18"}, "--verilog file '{v}': module echo_pwm's port pwm must be an output of 18 bit(s), "
                           "not an output of 4"),
    ({"--top": "robot"}, "--verilog file '{v}': the Verilog has no module robot"),
    ({"--clock-hz": "0"}, "--clock-hz must be a positive number of Hz, not '0'"),
])
def test_cli_errors_are_one_line(built, capsys, over, message):
    _, _, wd = built
    v = wd.parent / f"{TOP}.v"
    assert main(_serve_args(v, **over)) == 2
    assert capsys.readouterr().err == f"ikseries: error: {message.format(v=v)}\n"


class _Lines:
    """Lines of a pipe read as they come (a buffered reader would hide lines from select)."""

    def __init__(self, pipe):
        self.fd, self.buf = pipe.fileno(), b""

    def wait_for(self, want: str, deadline: float) -> str:
        """The first complete line containing ``want``."""
        while True:
            *lines, self.buf = self.buf.split(b"\n")
            for k, line in enumerate(lines):
                if want in line.decode():
                    self.buf = b"\n".join(lines[k + 1:] + [self.buf])
                    return line.decode()
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                raise AssertionError(f"no line with {want!r} from ikseries serve")
            chunk = os.read(self.fd, 65536)
            if not chunk:
                raise AssertionError(f"no line with {want!r} from ikseries serve before it ended")
            self.buf += chunk


def _cli(args, **kw):
    return subprocess.Popen([sys.executable, "-m", "ikseries.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def test_cli_serves_until_interrupted(built):
    """The command prints the pty, the widths in µs (1 MHz: one cycle is 1 µs) and the speed; an
    interrupt stops it and its simulator."""
    server, _, wd = built
    proc = _cli([*_serve_args(wd.parent / f"{TOP}.v"), "--workdir", str(wd)])
    try:
        deadline = time.monotonic() + 60     # the build is up to date: only make runs
        out = _Lines(proc.stdout)
        pty = out.wait_for("pty: ", deadline).split()[1]
        fd = os.open(pty, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, bytes([100, 50, 0, 255]))
            got = b""
            while len(got) < 4 and select.select([fd], [], [], 10)[0]:
                got += os.read(fd, 4)
        finally:
            os.close(fd)
        assert got == bytes([101, 51, 1, 0])
        assert out.wait_for("pulse us: 400.00 200.00 - high", deadline)
        time.sleep(2.5)                      # the first speed line
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 128 + signal.SIGINT, err
    assert "simulating " in err and " M cycles/s, " in err and "4 bytes in, 4 out, 0 framing errors" in err
    assert err.endswith("ikseries: interrupted\n") and _processes_running(server.binary) == []


def test_cli_interrupted_build_leaves_nothing(built, tmp_path):
    """Interrupted while Verilator compiles: no temporary directory, no compiler left."""
    _, _, wd = built
    proc = _cli(_serve_args(wd.parent / f"{TOP}.v", **{"--divisor": "10"}), env=dict(os.environ, TMPDIR=str(tmp_path)))
    try:
        assert "building the Verilator model" in proc.stderr.readline()
        time.sleep(3)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 128 + signal.SIGINT and err.endswith("ikseries: interrupted\n"), err
    assert list(tmp_path.iterdir()) == []
    left = [p for p in Path("/proc").iterdir() if p.name.isdigit() and _cwd_under(p, tmp_path)]
    assert left == []


def _cwd_under(proc_dir: Path, root: Path) -> bool:
    try:
        return str(Path(os.readlink(proc_dir / "cwd"))).startswith(str(root))
    except OSError:
        return False


def test_cli_failed_build_is_status_1(built, tmp_path, capsys, monkeypatch):
    """Verilog with the right ports that Verilator refuses: status 1, its temporary build removed."""
    _, text, _ = built
    bad = tmp_path / "bad.v"
    bad.write_text(text.replace("  output tx;\n", "  output tx;\n  this is not verilog;\n", 1))
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr("tempfile.tempdir", None)     # read TMPDIR again
    assert main([*_serve_args(bad), "-q"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("ikseries: error: Verilator build of echo_pwm failed (status ") and "%Error: echo_pwm.v:" in err
    assert list(tmp.iterdir()) == []
