"""``ikseries serve``: a board-level design's exported Verilog simulated behind a pseudo-terminal,
for the host library and CLI to drive before anything is flashed (:mod:`ikseries.sim.serve`).

It prints the pty path on stdout, then every change of the pulse widths the simulated pins show
(µs at ``clock_hz``, at simulated time), and on stderr how fast the simulation runs against the
board, until interrupted.
"""
from __future__ import annotations

import contextlib
import dataclasses
import tempfile
import time
from pathlib import Path

from .hdl.uart import MIN_DIVISOR
from .sim.serve import MAX_CHANNELS, build_server, check_design_ports
from .sim.verilator_build import check_identifier

__all__ = ["ServeError", "ServeFailed", "ServeOptions", "parse_options", "format_report", "speed_line", "serve"]

#: seconds between two speed lines on stderr, and before the first (the rate settles quickly)
STATUS_EVERY_S = 10.0
FIRST_STATUS_S = 2.0


class ServeError(RuntimeError):
    """A bad option or a design the server cannot drive."""


class ServeFailed(RuntimeError):
    """No Verilator, a failed build, a server that could not start or ended."""


@dataclasses.dataclass(frozen=True)
class ServeOptions:
    verilog: Path
    verilog_text: str
    top: str
    channels: int
    divisor: int
    period: int
    clock_hz: float
    workdir: Path | None


def _int(text: str, option: str, least: int, most: int | None, unit: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = least - 1
    if v < least or (most is not None and v > most):
        bound = f"in [{least}, {most}]" if most is not None else f">= {least}"
        raise ServeError(f"{option} must be an integer {bound}{unit}, not {text!r}")
    return v


def _clock(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = 0.0
    if not 0 < v < float("inf"):
        raise ServeError(f"--clock-hz must be a positive number of Hz, not {text!r}")
    return v


def _read_verilog(text: str) -> str:
    path = Path(text)
    if not path.is_file():
        raise ServeError(f"--verilog file {text!r} does not exist")
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ServeError(f"--verilog file {text!r} is not a readable text file ({e})") from None


def parse_options(verilog: str, top: str, channels: str, divisor: str, period: str, clock_hz: str,
                  workdir: str | None) -> ServeOptions:
    """The command's options checked one by one, each refusal one line naming the option and value."""
    try:
        check_identifier(top, "--top")
    except ValueError as e:
        raise ServeError(str(e)) from None
    text = _read_verilog(verilog)
    opts = ServeOptions(Path(verilog), text, top, _int(channels, "--channels", 1, MAX_CHANNELS, ""),
                        _int(divisor, "--divisor", MIN_DIVISOR, None, " (clock cycles per bit)"),
                        _int(period, "--period", 2, None, " (clock cycles)"), _clock(clock_hz),
                        None if workdir is None else Path(workdir))
    try:
        check_design_ports(text, top, opts.channels)
    except ValueError as e:
        raise ServeError(f"--verilog file {verilog!r}: {e}") from None
    return opts


def format_report(event: dict, clock_hz: float) -> str:
    """One line of pulse widths: simulated time, then µs per channel in channel order
    ('-' no pulse, 'high' a line held high)."""
    cells = ["high" if w is None else "-" if w == 0 else f"{w * 1e6 / clock_hz:.2f}" for w in event["widths"]]
    return f"t={event['cycle'] / clock_hz:.4f} s  pulse us: " + " ".join(cells)


def speed_line(status: dict, clock_hz: float, period: int) -> str:
    """How fast the simulation runs against the board, and what that means for host timeouts."""
    rate = status["cycles_per_second"]
    if not rate:
        return "no cycles simulated yet"
    slow = clock_hz / rate
    pace = f"{slow:.1f} times slower than" if slow >= 1 else f"{1 / slow:.1f} times faster than"
    return (f"simulating {rate / 1e6:.2f} M cycles/s, {pace} the {clock_hz / 1e6:g} MHz board: one "
            f"{period / clock_hz * 1e3:g} ms PWM period takes {period / rate * 1e3:.3g} ms"
            + (f"; give host timeouts {slow:.1f} times their margin" if slow > 1 else ""))


@contextlib.contextmanager
def _build_dir(workdir: Path | None):
    """The given work directory (kept, so a rerun rebuilds only what changed) or a temporary one."""
    if workdir is not None:
        yield workdir
        return
    with tempfile.TemporaryDirectory(prefix="ikseries-serve-") as d:
        yield Path(d)


def serve(opts: ServeOptions, out, progress) -> None:
    """Build and run the server until interrupted (KeyboardInterrupt, after a clean stop)."""
    with _build_dir(opts.workdir) as wd:
        progress(f"building the Verilator model of {opts.top} in {wd}")
        try:
            server = build_server(opts.verilog_text, opts.top, opts.channels, opts.divisor, opts.period, wd)
            progress(f"built in {server.build_s:g} s")
            session = server.start()
        except RuntimeError as e:     # no Verilator, a failed build, a server that could not start
            raise ServeFailed(str(e)) from None
        try:
            _run(session, opts, out, progress)
        finally:
            final = session.stop()
            if final is not None:
                progress(f"stopped after {final['cycle']:,} cycles ({final['cycle'] / opts.clock_hz:.3f} s of "
                         f"the board's time) in {final['seconds']:.1f} s; {final['rx_bytes']} bytes in, "
                         f"{final['tx_bytes']} out, {final['framing_errors']} framing errors")


def _run(session, opts: ServeOptions, out, progress) -> None:
    out(f"pty: {session.pty}")
    out(f"pulse widths of channels 0..{opts.channels - 1} at {opts.clock_hz:g} Hz ('-' no pulse, 'high' held high):")
    seen = 0
    next_status = time.monotonic() + FIRST_STATUS_S
    while True:
        try:
            reports = session.new_reports(seen, max(0.05, next_status - time.monotonic()))
            for r in reports:
                out(format_report(r, opts.clock_hz))
            seen += len(reports)
            if time.monotonic() >= next_status:
                progress(speed_line(session.status(), opts.clock_hz, opts.period))
                next_status = time.monotonic() + STATUS_EVERY_S
        except (RuntimeError, TimeoutError) as e:     # the server ended or hangs
            raise ServeFailed(str(e)) from None
