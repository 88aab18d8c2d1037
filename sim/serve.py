"""Try before you flash: a board-level design's exported Verilog in Verilator behind a pseudo-terminal.

The design is any component with the board top's contract (:class:`ikseries.hdl.top.BoardTop`):
``rx: In(1)``, ``tx: Out(1, init=1)`` (8N1 UART at ``divisor`` clock cycles per bit),
``pwm: Out(n)`` and the one clock domain ``sync`` (exported as ``clk`` and ``rst``). The server
(a C++ ``main``, ``templates/serve.cpp``, compiled with the model) opens the pseudo-terminal itself
(``posix_openpt``) and keeps its slave side open, in raw mode, so that a host can open, close
and reopen the slave path like a USB serial port without a hangup. It then runs the clock as fast
as it can:

- bytes the host writes to the pty are shifted into ``rx``, each bit exactly ``divisor`` cycles,
  bytes back to back;
- ``tx`` is sampled in the middle of every bit and each byte written back to the pty;
- on every ``pwm`` channel the high time of every pulse (rising to falling edge, in cycles) is
  measured; a change is reported once, one PWM ``period`` after it is first seen (so the
  channels changed in one period come together), and the first report comes after three
  periods. A line with no edge for two periods reports 0 (low: no pulse) or None (held high).

The server speaks JSON lines on its stdout (``event``: ``ready`` with the pty path, ``widths``,
``status`` with the rising-to-rising ``periods``, the speed and byte counters, and ``stopped``,
the final status); it reads lines on its stdin (``status``) and stops on ``stop``, on the end of
its stdin (the Python side closed it or died: no orphaned simulator) and on SIGTERM or SIGINT.

The simulated robot is slower than the real one: ``slowdown(clock_hz)`` of a :class:`Session`
is the real clock over the measured cycles per second (``ikseries serve`` prints it). Host
timeouts against a served design must be that many times longer than on the board. Seen on this
project's machine (2 cores) with the tests' echo + ``ServoPWMBank`` design widened to 18 channels
of 20 bits, divisor 48, period 960,000, ``-O2``: 5.6 M cycles per CPU second, 8.6 times slower
than a 48 MHz board (a 20 ms PWM period in 0.17 s); 2.8 to 3.6 M cycles/s of wall time while
other jobs shared the cores. The real ``RobotController`` (two cylinder legs, 6 channels, the
4 pu test plan, 1 Mbaud, 20 ms) ran 1.7 M cycles/s of wall time under the same load: 28 times
slower than the board, a PWM period in 0.57 s; ``ikseries.host.controller.Controller`` on the pty
(timeout 0.5 s times the slowdown) read its identity and status and set a 1500 µs pulse.

Example::

    server = build_server(verilog_text, "robot_controller", 18, 48, 960_000, workdir)
    with server.start() as s:
        port = serial.Serial(s.pty, baudrate=1_000_000, timeout=1.0)
        ...
        s.wait_widths(lambda w: w[0] == 72_000, timeout=10)
"""
from __future__ import annotations

import dataclasses
import json
import re
import signal
import string
import subprocess
import threading
import time
from pathlib import Path

from ..hdl.uart import MIN_DIVISOR
from .verilator_build import check_identifier, verilate

__all__ = ["MAX_CHANNELS", "POLL_CYCLES", "Server", "Session", "build_server", "check_design_ports"]

#: the pwm port is read as one 64-bit word per cycle
MAX_CHANNELS = 64
#: cycles run between two looks at the pty and stdin: short against a byte (10 * divisor
#: cycles) would only add system calls, the host's bytes wait in the pty meanwhile
POLL_CYCLES = 4096
#: the C++ main, a ``string.Template`` with ``top`` and ``channels``
TEMPLATE = Path(__file__).parent / "templates" / "serve.cpp"


def _positive(name: str, v, least: int) -> None:
    if not isinstance(v, int) or isinstance(v, bool) or v < least:
        raise ValueError(f"{name} must be an integer >= {least}, not {v!r}")


def check_design_ports(verilog: str, top: str, channels: int) -> None:
    """Refuse ``verilog`` unless its module ``top`` has the ports ``clk``, ``rst``, ``rx``
    (inputs), ``tx`` (output) and ``pwm``, an output ``channels`` bits wide."""
    check_identifier(top)
    m = re.search(rf"^\s*module\s+{top}\s*\((.*?)\)\s*;(.*?)^\s*endmodule", verilog, re.M | re.S)
    if m is None:
        raise ValueError(f"the Verilog has no module {top}")
    decls = {name: (d, int(hi) + 1 if hi else 1) for d, hi, name in
             re.findall(r"^\s*(input|output)\s+(?:\[(\d+):0\]\s*)?(\w+)\s*;", m.group(2), re.M)}
    want = {"clk": ("input", 1), "rst": ("input", 1), "rx": ("input", 1), "tx": ("output", 1),
            "pwm": ("output", channels)}
    for name, (d, width) in want.items():
        got = decls.get(name)
        if got is None:
            raise ValueError(f"module {top} must have a port {name} ({d}), not none")
        if got != (d, width):
            raise ValueError(f"module {top}'s port {name} must be an {d} of {width} bit(s), "
                             f"not an {got[0]} of {got[1]}")


@dataclasses.dataclass(frozen=True)
class Server:
    """A built server: the Verilator model of one design with the pty main."""
    binary: Path
    top: str
    channels: int
    divisor: int
    period: int
    build_s: float

    def start(self, *, poll_cycles: int = POLL_CYCLES, timeout: float = 10.0) -> "Session":
        """Run the server; returns once it has opened its pty (or raises ``RuntimeError``)."""
        _positive("poll_cycles", poll_cycles, 1)
        return Session(self, poll_cycles, timeout)


def build_server(verilog_text: str, top_name: str, channels: int, divisor: int, period: int, workdir, *,
                 cxx_opt: str = "-O2", jobs: int = 2) -> Server:
    """Verilate ``verilog_text`` (module ``top_name``, ``channels`` servo channels) with the pty
    main into ``workdir`` (``<top>.v``, ``serve.cpp``, ``obj/``)."""
    _positive("channels", channels, 1)
    if channels > MAX_CHANNELS:
        raise ValueError(f"channels must be at most {MAX_CHANNELS}, not {channels}")
    _positive("divisor", divisor, MIN_DIVISOR)
    _positive("period", period, 2)
    check_design_ports(verilog_text, top_name, channels)
    cpp = string.Template(TEMPLATE.read_text()).substitute(top=top_name, channels=channels)
    binary, build_s = verilate(verilog_text, top_name, cpp, "serve.cpp", workdir, cxx_opt=cxx_opt, jobs=jobs)
    return Server(binary, top_name, channels, divisor, period, build_s)


class Session:
    """A running server: its pty path, the pulse widths it reports, a clean stop.

    A thread reads the server's events; ``widths`` is the latest report, ``history`` every
    ``widths`` event so far. Use it as a context manager, or call :meth:`stop`.
    """

    def __init__(self, server: Server, poll_cycles: int, timeout: float):
        self.server = server
        self.history: list[dict] = []
        self.final: dict | None = None
        self._status: list[dict] = []
        self._ready: dict | None = None
        self._eof = False
        self._cond = threading.Condition()
        self._proc = subprocess.Popen(
            [str(server.binary), str(server.divisor), str(server.period), str(poll_cycles)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
            start_new_session=True)     # the caller's terminal interrupt reaches us, who stop it in order
        self._reader = threading.Thread(target=self._read, name=f"serve-{server.top}", daemon=True)
        self._reader.start()
        try:
            ready = self._wait(lambda: self._ready, timeout, "open its pseudo-terminal")
        except BaseException:
            self.stop()
            raise
        self.pty: str = ready["pty"]

    def _read(self) -> None:
        try:
            for line in self._proc.stdout:
                self._take(json.loads(line))
        finally:     # also if a line is no event: the waits then end instead of timing out
            with self._cond:
                self._eof = True
                self._cond.notify_all()

    def _take(self, ev: dict) -> None:
        with self._cond:
            kind = ev["event"]
            if kind == "ready":
                self._ready = ev
            elif kind == "widths":
                self.history.append(ev)
            elif kind == "status":
                self._status.append(ev)
            else:
                self.final = ev
            self._cond.notify_all()

    def _wait(self, pred, timeout: float, what: str):
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                got = pred()
                if got:
                    return got
                left = deadline - time.monotonic()
                if self._eof:
                    err = self._proc.stderr.read().strip() if self._proc.poll() is not None else ""
                    raise RuntimeError(f"the {self.server.top} server ended before it could {what}"
                                       + (f": {err}" if err else ""))
                if left <= 0:
                    raise TimeoutError(f"the {self.server.top} server did not {what} within {timeout:g} s")
                self._cond.wait(left)

    @property
    def widths(self) -> list[int | None] | None:
        """The latest reported pulse widths in cycles, one per channel (None before the first)."""
        with self._cond:
            return self.history[-1]["widths"] if self.history else None

    def wait_widths(self, pred, timeout: float) -> list[int | None]:
        """The first reported widths (this report or a later one) for which ``pred(widths)`` holds."""
        with self._cond:      # the latest report counts: the widths may already be there
            nxt = [max(0, len(self.history) - 1)]

        def match():
            while nxt[0] < len(self.history):
                w = self.history[nxt[0]]["widths"]
                nxt[0] += 1
                if pred(w):
                    return w
            return None
        return self._wait(match, timeout, "report the pulse widths asked for")

    def new_reports(self, since: int, timeout: float) -> list[dict]:
        """The ``widths`` events after the first ``since`` ones, as soon as there is one, or []
        after ``timeout`` seconds; ``RuntimeError`` if the server has ended."""
        try:
            return self._wait(lambda: self.history[since:], timeout, "report")
        except TimeoutError:
            return []

    def status(self, timeout: float = 10.0) -> dict:
        """A fresh status event: cycle, seconds, widths, periods, cycles_per_second, counters."""
        with self._cond:
            n = len(self._status)
        self._proc.stdin.write("status\n")
        self._proc.stdin.flush()
        return self._wait(lambda: self._status[n] if len(self._status) > n else None, timeout, "report its status")

    def slowdown(self, clock_hz: float, status: dict | None = None) -> float:
        """How many times slower than a ``clock_hz`` board the simulation runs (from ``status``,
        default a fresh one)."""
        rate = (status or self.status())["cycles_per_second"]
        return clock_hz / rate if rate else float("inf")

    def stop(self, timeout: float = 10.0) -> dict | None:
        """Stop the server (SIGTERM, then SIGKILL after ``timeout``); returns its final status."""
        if self._proc.poll() is None:
            self._proc.send_signal(signal.SIGTERM)
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._reader.join(timeout)
        for f in (self._proc.stdin, self._proc.stdout, self._proc.stderr):
            try:
                f.close()
            except OSError:     # stdin's buffer could not be flushed to a dead server
                pass
        return self.final

    @property
    def pid(self) -> int:
        return self._proc.pid

    @property
    def running(self) -> bool:
        return self._proc.poll() is None

    @property
    def returncode(self) -> int | None:
        """The server's exit status once it has ended (0: a clean stop)."""
        return self._proc.poll()

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
