"""``ikseries move``, ``status``, ``enable``, ``relax``: a robot controller driven from the
command line through the host library (:class:`ikseries.host.controller.Controller`), on a
board's serial port or on the pseudo-terminal of ``ikseries serve``.

Targets are given in the robot's own units (the inputs of the build's manifest, e.g. mm and
degrees) and sent as the plan's port integers (``value * 2**frac_bits``, rounded); a value
outside an input's range is refused here, before anything is sent, although the controller
would clamp it (and count it). The build directory also proves that the controller on the port
is the one built there: its identity carries the first 8 bytes of the SHA-256 of the build's
manifest.json.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

__all__ = ["HostCommandError", "BuildInfo", "build_info", "port_targets", "open_controller", "status_lines"]


class HostCommandError(ValueError):
    """A bad argument, or a controller that is not the build's (one line)."""


class BuildInfo:
    """What the host commands read of a build directory made with ``--board``."""

    def __init__(self, directory: Path, manifest_text: str):
        self.directory = directory
        self.manifest = json.loads(manifest_text)
        self.digest = hashlib.sha256(manifest_text.encode()).digest()[:8]
        self.inputs = [f for f in self.manifest["inputs"]["fields"] if f["name"] != "leg"]
        self.channels = self.manifest["board"]["channels"]


def build_info(directory) -> BuildInfo:
    path = Path(directory) / "manifest.json"
    try:
        text = path.read_text()
        info = BuildInfo(Path(directory), text)
    except (OSError, ValueError, KeyError, TypeError):
        raise HostCommandError(f"--build must be a build directory made with `ikseries build --board`, not "
                               f"{str(directory)!r} (no manifest.json naming a board there)") from None
    return info


def port_targets(info: BuildInfo, values: list[str]) -> tuple[int, ...]:
    """The port integers of a target given in the inputs' units, each checked against its range."""
    if len(values) != len(info.inputs):
        names = ", ".join(f"{f['name']} [{f['unit']}]" for f in info.inputs)
        raise HostCommandError(f"a target must give {len(info.inputs)} values ({names}), not {len(values)}")
    out = []
    for text, f in zip(values, info.inputs):
        try:
            v = float(text)
        except ValueError:
            v = float("nan")
        lo, hi = (x / 2 ** f["frac_bits"] for x in f["range"])
        if not lo <= v <= hi:
            raise HostCommandError(f"{f['name']} must be a number in [{lo:g}, {hi:g}] {f['unit']}, not {text!r}")
        out.append(round(v * 2 ** f["frac_bits"]))
    return tuple(out)


def open_controller(port: str, baud: float, timeout: float, info: BuildInfo | None):
    """The :class:`Controller` on ``port``; with ``info``, refused unless it is that build's."""
    from .host.controller import Controller
    ctl = Controller(port, baud, timeout)
    if info is not None and bytes(ctl.manifest) != info.digest:
        raise HostCommandError(f"the controller on {port} ({ctl.name!r}, manifest {bytes(ctl.manifest).hex()}) is not "
                               f"the one built in {info.directory} (manifest {info.digest.hex()})")
    return ctl


def status_lines(ctl, info: BuildInfo | None) -> list[str]:
    """The controller's identity, counters and every channel's pulses, one line each."""
    st = ctl.status()
    lines = [f"{ctl.name}: {ctl.shape.legs} legs, {ctl.shape.channels} channels, clock {ctl.clock_hz / 1e6:g} MHz, "
             f"PWM period {ctl.period * 1e3 / ctl.clock_hz:g} ms, up {st['uptime'] * ctl.period / ctl.clock_hz:.2f} s",
             "errors: " + ", ".join(f"{k} {st[k]}" for k in ("crc", "framing", "overrun", "bad_length",
                                                          "unknown_command", "dropped", "clamped"))]
    for ch in range(ctl.shape.channels):
        c = ctl.channel_status(ch)
        where = ""
        if info is not None:
            rec = info.channels[ch]
            where = f" (leg {rec['leg']} {rec['servo']}, pin {rec['pin']})"
        lines.append(f"channel {ch}{where}: {'on' if c['enabled'] else 'relaxed'}, commanded {c['commanded_us']:.2f} µs, "
                     f"current {c['current_us']:.2f} µs{', moving' if c['moving'] else ''}")
    return lines
