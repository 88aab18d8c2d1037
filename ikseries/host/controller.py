"""The robot controller from a host: requests over a serial port (or any byte stream), answers
checked, pulses in µs converted to clock ticks with the controller's own clock."""
from __future__ import annotations

import time
from typing import Mapping

from ..hdl import protocol as P
from .protocol import Decoder, Message, encode

__all__ = ["Controller", "ControllerError", "NackError", "AnswerTimeout", "READ_TIMEOUT_S"]

#: longest wait of one read of a serial port
READ_TIMEOUT_S = 0.02


class ControllerError(RuntimeError):
    """A request the controller did not carry out; the message is one line."""


class NackError(ControllerError):
    """The controller refused a request (``reason``: a NACK reason name)."""

    def __init__(self, command: str, reason):
        self.command, self.reason = command, reason
        meaning = dict(P.NACK_REASONS).get(reason, "unknown reason")
        super().__init__(f"the controller refused {command}: {reason} ({meaning})")


class AnswerTimeout(ControllerError):
    """No answer within the timeout."""


def _open(port_or_stream, baud, timeout):
    if isinstance(port_or_stream, str):
        import serial       # only a real port needs pyserial
        # a short read timeout: read(n) returns what has arrived (an answer is shorter than n)
        # and the exchange keeps its own deadline
        return serial.Serial(port_or_stream, baud, timeout=min(timeout, READ_TIMEOUT_S))
    if not (callable(getattr(port_or_stream, "read", None)) and callable(getattr(port_or_stream, "write", None))):
        raise TypeError(f"port_or_stream must be a port name or an object with read and write, not {port_or_stream!r}")
    return port_or_stream


class Controller:
    """A robot controller on a serial link (``docs/protocol.md``).

    Parameters
    ----------
    port_or_stream : str or object
        A serial port name (opened with ``serial.Serial(port, baud, timeout=...)``) or any
        object with ``read(n) -> bytes`` (at most n bytes, fewer at its own timeout) and
        ``write(bytes)``, such as a simulated link.
    baud : float
        Line rate of a port (default 1 Mbaud).
    timeout : float
        Seconds to wait for an answer.

    On opening, the identity is read: ``shape``, ``clock_hz``, ``name``, ``period``.
    Pulse arguments are µs, sent as ``round(µs * clock_hz / 1e6)`` ticks; speed in µs per
    PWM period, acceleration in µs per period per period; times in PWM periods. Every
    method waits for the answer: a NACK raises :class:`NackError`, no answer
    :class:`AnswerTimeout`, a bad argument ``ValueError``, each with a one-line message.
    """

    def __init__(self, port_or_stream, baud: float = 1e6, timeout: float = 0.5):
        if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, not {timeout!r}")
        self._io, self._timeout = _open(port_or_stream, baud, timeout), timeout
        self._decoder = Decoder()
        # requests before the identity is known need no shape: a placeholder of one leg
        self.shape = P.Shape(1, 1, 1)
        ident = self.identity()
        if ident["version"] != P.PROTOCOL_VERSION:
            raise ControllerError(f"the controller speaks protocol version {ident['version']}, "
                                  f"this host {P.PROTOCOL_VERSION}")
        self.shape = P.Shape(ident["legs"], ident["coords"], ident["channels"])
        self.clock_hz, self.period, self.name = ident["clock_hz"], ident["pwm_period"], ident["name"]
        self.manifest = ident["manifest"]

    # -- the exchange
    def _exchange(self, command: str, **fields) -> dict:
        self._io.write(encode(command, self.shape, **fields))
        deadline = time.monotonic() + self._timeout
        while time.monotonic() < deadline:
            data = self._io.read(64)
            for msg in self._decoder.feed(data or b""):
                return self._accept(command, msg)
        raise AnswerTimeout(f"no answer to {command} within {self._timeout:g} s")

    @staticmethod
    def _accept(command: str, msg: Message) -> dict:
        if msg.nack:
            raise NackError(msg.command, msg.fields["reason"])
        if msg.command != command:
            raise ControllerError(f"the controller answered {msg.command} to {command}")
        return msg.fields

    def ticks(self, us, what: str = "pulse") -> int:
        """Clock ticks of ``us`` microseconds."""
        if isinstance(us, bool) or not isinstance(us, (int, float)) or us != us:
            raise ValueError(f"{what} must be a number of µs, not {us!r}")
        return round(us * self.clock_hz / 1e6)

    def _ticks_field(self, us, what, signed=False):
        t = self.ticks(us, what)
        lo, hi = (-(1 << 23), (1 << 23) - 1) if signed else (0, (1 << 24) - 1)
        if not lo <= t <= hi:
            raise ValueError(f"{what} must be in [{lo * 1e6 / self.clock_hz:g}, {hi * 1e6 / self.clock_hz:g}] µs "
                             f"at {self.clock_hz:g} Hz, not {us!r}")
        return t

    # -- requests
    def identity(self) -> dict:
        return self._exchange("identity")

    def status(self) -> dict:
        return self._exchange("status")

    def channel_status(self, channel: int) -> dict:
        """The channel's commanded and current pulses (in µs) and its flags."""
        f = self._exchange("channel_status", channel=channel)
        return {**f, "commanded_us": f["commanded"] * 1e6 / self.clock_hz,
                "current_us": f["current"] * 1e6 / self.clock_hz}

    def move(self, leg: int, target) -> None:
        """Move one leg's tip to ``target`` (the plan's input port integers, in plan order)."""
        self._exchange("move_leg", leg=leg, target=tuple(target))

    def move_legs(self, targets: Mapping[int, tuple]) -> None:
        """Move every leg of ``{leg: target}`` together (applied at one PWM period start)."""
        if not isinstance(targets, Mapping) or not targets:
            raise ValueError(f"targets must be a non-empty mapping of leg to target, not {targets!r}")
        for leg in targets:
            if not isinstance(leg, int) or isinstance(leg, bool) or not 0 <= leg < self.shape.legs:
                raise ValueError(f"leg must be in [0, {self.shape.legs - 1}], not {leg!r}")
        legs = sorted(targets)
        self._exchange("move_legs", legs=sum(1 << l for l in legs), targets=tuple(tuple(targets[l]) for l in legs))

    def set_pulse(self, channel: int, us) -> None:
        self._exchange("set_pulse", channel=channel, pulse=self._ticks_field(us, "pulse"))

    def trim(self, channel: int, us) -> None:
        self._exchange("set_trim", channel=channel, trim=self._ticks_field(us, "trim", signed=True))

    def limits(self, channel: int, min_us, max_us) -> None:
        self._exchange("set_limits", channel=channel, min=self._ticks_field(min_us, "min"),
                       max=self._ticks_field(max_us, "max"))

    def speed(self, channel: int, us_per_period) -> None:
        """Speed limit in µs per PWM period (0: unlimited)."""
        self._exchange("set_speed", channel=channel, speed=self._ticks_field(us_per_period, "speed"))

    def accel(self, channel: int, us_per_period2) -> None:
        """Acceleration limit in µs per period per period (0: unlimited)."""
        self._exchange("set_accel", channel=channel, accel=self._ticks_field(us_per_period2, "accel"))

    def home(self, channel: int, us) -> None:
        self._exchange("set_home", channel=channel, pulse=self._ticks_field(us, "home pulse"))

    def enable(self, channels) -> None:
        """Start the pulses on ``channels`` (an iterable of channel numbers)."""
        self._exchange("enable", channels=self._mask(channels))

    def relax(self, channels) -> None:
        self._exchange("relax", channels=self._mask(channels))

    def failsafe(self, periods: int, action: Mapping[int, str] | None = None) -> None:
        """The failsafe timeout in PWM periods (0: never) and, per channel, its action
        (``hold``, ``relax`` or ``home``)."""
        for channel, act in (action or {}).items():
            self._exchange("set_failsafe_action", channel=channel, action=act)
        self._exchange("set_failsafe", periods=periods)

    def move_time(self, periods: int) -> None:
        """Duration of the following moves in PWM periods (0: as fast as the limits allow)."""
        self._exchange("set_move_time", periods=periods)

    def _mask(self, channels) -> int:
        if isinstance(channels, (str, bytes)) or not hasattr(channels, "__iter__"):
            raise ValueError(f"channels must be an iterable of channel numbers, not {channels!r}")
        mask = 0
        for c in channels:
            if not isinstance(c, int) or isinstance(c, bool) or not 0 <= c < self.shape.channels:
                raise ValueError(f"channel must be in [0, {self.shape.channels - 1}], not {c!r}")
            mask |= 1 << c
        return mask
