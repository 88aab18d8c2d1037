"""The host link's wire protocol: frame format, CRC, commands and their fields, as data.

The one home of every protocol fact. Pure Python with no Amaranth import: the hardware
(:mod:`ikseries.hdl.link`), the host library (:mod:`ikseries.host.protocol`) and the spec
(``docs/protocol.md``, whose tables :func:`markdown_tables` renders) all read it.

A frame is ``SYNC LEN CMD PAYLOAD[LEN] CRC_LO CRC_HI``: LEN counts the payload bytes only; the
CRC (:data:`CRC`) covers LEN, CMD and the payload and is sent low byte first, so the CRC over
LEN .. CRC_HI is 0. It is a reflected CRC (least significant bit first, as the UART sends a
byte's bits): both ends may compute it a bit at a time as the bits cross the line. Fields are little-endian two's complement (signed) or unsigned integers.
Requests go host -> controller; every good request is answered by a frame whose CMD is the
request's :func:`answer_code` (its answer fields, or none: an acknowledgement) or by a
:data:`NACK` frame. Answer layouts do not depend on the robot; request layouts depend on its
:class:`Shape` (coordinates per leg, numbers of legs and channels).
"""
from __future__ import annotations

from dataclasses import dataclass

from .servo_fields import FailsafeAction

__all__ = ["PROTOCOL_VERSION", "SYNC", "MAX_PAYLOAD", "ANSWER_BIT", "NACK", "CRC", "CRC_BYTE_ORDER",
           "COUNTER_BITS", "BYTE_BITS", "RX_TIMEOUT_BYTES", "ERROR_COUNTERS", "RECEIVER_COUNTERS", "NACK_REASONS",
           "FAILSAFE_ACTIONS", "KINDS", "Field", "Command", "Shape", "COMMANDS", "NACK_FIELDS", "command", "answer_code",
           "request_lengths", "answer_lengths", "max_request_payload", "markdown_tables"]

#: 2: the CRC is reflected (CRC-16/MCRF4XX, sent low byte first; 1 had CRC-16/CCITT-FALSE, high
#: byte first)
PROTOCOL_VERSION = 2
#: first byte of every frame; never a valid LEN (> MAX_PAYLOAD) nor a command or answer code,
#: so a receiver that rejects a LEN or CMD byte equal to SYNC takes it as the next frame's start
SYNC = 0xA5
#: largest payload of any frame, either direction
MAX_PAYLOAD = 64
#: an answer's CMD is the request's code with this bit set
ANSWER_BIT = 0x80
#: CMD of the negative answer (fields :data:`NACK_FIELDS`)
NACK = 0xFF
#: width of every error counter, in the hardware and in the status answer; they saturate
COUNTER_BITS = 16
#: bit times of one byte on the line (8N1: start bit, 8 data bits, stop bit)
BYTE_BITS = 10
#: a pause of more than this many byte times between two bytes of a frame abandons the frame (it is
#: not counted) and the receiver hunts for SYNC again; a host that waits for each answer (at least
#: 5 bytes) or for its own timeout before the next request therefore never has that request swallowed
#: by earlier garbage that looked like a header
RX_TIMEOUT_BYTES = 4


@dataclass(frozen=True)
class CRCParameters:
    """A CRC in the Rocksoft/Williams model (the parameters of ``amaranth.lib.crc.Algorithm``)."""
    name: str
    width: int
    polynomial: int
    initial: int
    reflect_input: bool
    reflect_output: bool
    xor_output: int
    check: int      #: the CRC of the ASCII bytes "123456789"


#: least significant bit first, as the UART's bits: the hardware steps it a bit per bit on the line
CRC = CRCParameters("CRC-16/MCRF4XX", width=16, polynomial=0x1021, initial=0xFFFF,
                    reflect_input=True, reflect_output=True, xor_output=0x0000, check=0x6F91)
CRC_BYTE_ORDER = "little"

#: error counters of the status answer, in its order, with their meaning
ERROR_COUNTERS = (
    ("crc", "frames dropped because their CRC was wrong"),
    ("framing", "bytes dropped by the UART because their stop bit was low"),
    ("overrun", "bytes lost because the previous byte had not been taken"),
    ("bad_length", "frames dropped at a LEN above the largest request or a LEN their command does not take"),
    ("unknown_command", "frames dropped at a CMD that is no request code"),
    ("dropped", "good frames dropped because the previous one had not been taken"),
    ("clamped", "leg targets clamped to the workspace"),
)
#: the counters the frame receiver itself keeps (the rest belong to the controller)
RECEIVER_COUNTERS = tuple(name for name, _ in ERROR_COUNTERS if name != "clamped")
#: reason byte of a NACK, code = index + 1
NACK_REASONS = (
    ("bad_value", "a field is out of range for this robot (channel, leg, mask, limits)"),
    ("busy", "the controller cannot take the request now"),
    ("unsupported", "this controller does not implement the command"),
)
_FAILSAFE_MEANINGS = {
    FailsafeAction.HOLD: "keep the last pulse",
    FailsafeAction.RELAX: "stop the pulses (the servo goes limp)",
    FailsafeAction.HOME: "move to the home pulse",
}
#: per-channel action when the failsafe timeout expires, code = index; the codes' home is
#: :class:`~ikseries.hdl.servo_fields.FailsafeAction`, this table only names and explains them
FAILSAFE_ACTIONS = tuple((a.name.lower(), _FAILSAFE_MEANINGS[a]) for a in sorted(FailsafeAction))
if [a.value for a in sorted(FailsafeAction)] != list(range(len(FAILSAFE_ACTIONS))):
    raise ImportError("FailsafeAction codes must be 0 .. n-1: the protocol sends them as indices")

#: integer kinds: (bytes, signed)
KINDS = {"u8": (1, False), "u16": (2, False), "u24": (3, False), "u32": (4, False),
         "s16": (2, True), "s24": (3, True)}
#: the shape-dependent value ranges a field may name
VALUE_RULES = ("channel", "leg", "channel_mask", "leg_mask", "failsafe_action")


@dataclass(frozen=True)
class Field:
    """One payload field.

    ``kind`` is an integer kind of :data:`KINDS`, ``"bytes"`` (``count`` raw bytes) or ``"text"``
    (UTF-8, 0 .. ``count`` bytes, the payload's last field). ``count`` is the number of integers
    (1: a scalar) or ``"coords"`` (the robot's coordinates per leg); ``per`` names an earlier
    leg-mask field, giving one group of ``count`` integers per leg in the mask (lowest leg
    first). ``values`` is a shape-dependent range of :data:`VALUE_RULES`, tighter than the kind's.
    """
    name: str
    kind: str
    doc: str
    count: int | str = 1
    per: str | None = None
    values: str | None = None

    def __post_init__(self):
        if self.kind not in KINDS and self.kind not in ("bytes", "text"):
            raise ValueError(f"field kind must be one of {', '.join(KINDS)}, bytes, text, not {self.kind!r}")
        if self.values is not None and self.values not in VALUE_RULES:
            raise ValueError(f"field values must be one of {', '.join(VALUE_RULES)}, not {self.values!r}")

    def elements(self, shape: "Shape | None") -> int:
        """Integers (or bytes) in one group of this field."""
        if self.count == "coords":
            if shape is None:
                raise ValueError(f"field {self.name} depends on the robot's shape")
            return shape.coords
        return self.count

    def group_bytes(self, shape: "Shape | None") -> int:
        """Bytes of one group (the whole field unless ``per`` repeats it; the most for text)."""
        per_element = 1 if self.kind in ("bytes", "text") else KINDS[self.kind][0]
        return per_element * self.elements(shape)


@dataclass(frozen=True)
class Command:
    """A request and its answer (no answer fields: an acknowledgement)."""
    name: str
    code: int
    doc: str
    request: tuple[Field, ...] = ()
    answer: tuple[Field, ...] = ()


@dataclass(frozen=True)
class Shape:
    """What the request layouts depend on: legs (a leg mask is one byte), coordinates per leg
    (each an s16: the plan's input port integers must fit) and servo channels (a channel mask is
    a u32)."""
    legs: int
    coords: int
    channels: int

    def __post_init__(self):
        for name, v, top in (("legs", self.legs, 8), ("coords", self.coords, 255), ("channels", self.channels, 32)):
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= top:
                raise ValueError(f"{name} must be an integer in [1, {top}], not {v!r}")
        need = max_request_payload(self)
        if need > MAX_PAYLOAD:
            raise ValueError(f"a {self.legs}-leg robot with {self.coords} coordinates per leg needs "
                             f"{need}-byte payloads; the protocol's limit is {MAX_PAYLOAD}")


def _channel(doc="servo channel"):
    return Field("channel", "u8", doc, values="channel")


COMMANDS = (
    Command("identity", 0x01, "who the controller is", answer=(
        Field("version", "u8", "protocol version"),
        Field("clock_hz", "u32", "clock frequency (Hz): ticks per second"),
        Field("pwm_period", "u24", "PWM period in ticks"),
        Field("legs", "u8", "legs"),
        Field("coords", "u8", "coordinates per leg target"),
        Field("channels", "u8", "servo channels"),
        Field("manifest", "bytes", "first 8 bytes of the SHA-256 of the build's manifest.json", count=8),
        Field("name", "text", "robot name (UTF-8)", count=32))),
    Command("status", 0x02, "counters and flags of the whole controller", answer=(
        Field("uptime", "u32", "PWM periods since reset"),
        *(Field(name, "u16", doc) for name, doc in ERROR_COUNTERS),
        Field("moving", "u32", "channel mask: not yet at the commanded pulse"),
        Field("enabled", "u32", "channel mask: sending pulses"))),
    Command("channel_status", 0x03, "one channel's pulses", request=(_channel(),), answer=(
        Field("channel", "u8", "servo channel"),
        Field("commanded", "u24", "commanded pulse (ticks)"),
        Field("current", "u24", "pulse sent this period (ticks)"),
        Field("moving", "u8", "1 while not at the commanded pulse"),
        Field("enabled", "u8", "1 while sending pulses"))),
    Command("move_leg", 0x10, "move one leg's tip to a target (through the IK)", request=(
        Field("leg", "u8", "leg index", values="leg"),
        Field("target", "s16", "tip target: the plan's input port integers", count="coords"))),
    Command("move_legs", 0x11, "move several legs together, applied at one PWM period start", request=(
        Field("legs", "u8", "leg mask (bit l: leg l), not empty", values="leg_mask"),
        Field("targets", "s16", "a tip target per leg in the mask, lowest leg first", count="coords",
              per="legs"))),
    Command("set_pulse", 0x12, "set a channel's pulse directly (bypassing the IK)", request=(
        _channel(), Field("pulse", "u24", "pulse width (ticks)"))),
    Command("set_move_time", 0x13, "duration of the moves that follow: their channels arrive together", request=(
        Field("periods", "u16", "PWM periods (0: as fast as the limits allow)"),)),
    Command("set_trim", 0x20, "offset added to a channel's pulse", request=(
        _channel(), Field("trim", "s24", "ticks"))),
    Command("set_limits", 0x21, "a channel's pulse range (commands are clamped to it)", request=(
        _channel(), Field("min", "u24", "ticks"), Field("max", "u24", "ticks"))),
    Command("set_speed", 0x22, "a channel's speed limit", request=(
        _channel(), Field("speed", "u24", "ticks per PWM period (0: unlimited)"))),
    Command("set_accel", 0x23, "a channel's acceleration limit", request=(
        _channel(), Field("accel", "u24", "ticks per period per period (0: unlimited)"))),
    Command("set_home", 0x24, "a channel's home pulse (failsafe action home)", request=(
        _channel(), Field("pulse", "u24", "ticks"))),
    Command("enable", 0x28, "start sending pulses on channels", request=(
        Field("channels", "u32", "channel mask", values="channel_mask"),)),
    Command("relax", 0x29, "stop sending pulses on channels (the servos go limp)", request=(
        Field("channels", "u32", "channel mask", values="channel_mask"),)),
    Command("set_failsafe", 0x2A, "failsafe timeout: act when no good request arrived for this long", request=(
        Field("periods", "u16", "PWM periods (0: never)"),)),
    Command("set_failsafe_action", 0x2B, "what a channel does when the failsafe expires", request=(
        _channel(), Field("action", "u8", "failsafe action code", values="failsafe_action"))),
)
NACK_FIELDS = (Field("request", "u8", "code of the refused request"),
               Field("reason", "u8", "NACK reason code"))

_BY_NAME = {c.name: c for c in COMMANDS}
_BY_CODE = {c.code: c for c in COMMANDS}


def command(key: str | int) -> Command:
    """The command named ``key`` or of code ``key``."""
    found = (_BY_NAME if isinstance(key, str) else _BY_CODE).get(key)
    if found is None:
        raise ValueError(f"command must be one of {', '.join(_BY_NAME)} (or their codes), not {key!r}")
    return found


def answer_code(cmd: Command) -> int:
    return ANSWER_BIT | cmd.code


def _lengths(fields: tuple[Field, ...], shape: Shape | None) -> frozenset[int]:
    fixed = sum(f.group_bytes(shape) for f in fields if f.per is None and f.kind != "text")
    groups = [f.group_bytes(shape) for f in fields if f.per is not None]
    text = [f.count for f in fields if f.kind == "text"]
    if groups:    # one group per leg of a non-empty leg mask
        return frozenset(fixed + k * sum(groups) for k in range(1, shape.legs + 1))
    if text:
        return frozenset(range(fixed, fixed + text[0] + 1))
    return frozenset({fixed})


def request_lengths(cmd: Command, shape: Shape) -> frozenset[int]:
    """The payload lengths a request of ``cmd`` may have for a robot of ``shape``."""
    return _lengths(cmd.request, shape)


def answer_lengths(cmd: Command) -> frozenset[int]:
    """The payload lengths of ``cmd``'s answer (0: an acknowledgement)."""
    return _lengths(cmd.answer, None)


def max_request_payload(shape: Shape) -> int:
    return max(max(_lengths(c.request, shape)) for c in COMMANDS)


def _size_formula(fields: tuple[Field, ...]) -> str:
    fixed = sum(f.group_bytes(None) for f in fields if f.count != "coords" and f.kind != "text")
    terms = [str(fixed)] if fixed or not fields else []
    for f in fields:
        if f.count == "coords":
            per_coord = KINDS[f.kind][0]
            terms.append(f"{per_coord}·C·k" if f.per else f"{per_coord}·C")
        elif f.kind == "text":
            terms.append(f"0..{f.count}")
    return " + ".join(terms)


def _field_text(f: Field) -> str:
    count = "" if f.count == 1 else "[C]" if f.count == "coords" else f"[{f.count}]"
    per = f" per leg of `{f.per}`" if f.per else ""
    return f"`{f.name}` {f.kind}{count}{per}"


def _rows(head, rows) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head),
            *("| " + " | ".join(str(c) for c in row) + " |" for row in rows), ""]


def markdown_tables() -> str:
    """The generated part of ``docs/protocol.md``: constants, commands, fields and codes."""
    out = ["### Constants", ""]
    out += _rows(("name", "value"), [
        ("protocol version", PROTOCOL_VERSION), ("SYNC", f"0x{SYNC:02X}"), ("largest payload", f"{MAX_PAYLOAD} bytes"),
        ("answer code", f"request code \\| 0x{ANSWER_BIT:02X}"), ("NACK code", f"0x{NACK:02X}"),
        ("CRC", f"{CRC.name}: width {CRC.width}, polynomial 0x{CRC.polynomial:04X}, initial 0x{CRC.initial:04X}, "
                f"reflect input {CRC.reflect_input}, reflect output {CRC.reflect_output}, "
                f"xor output 0x{CRC.xor_output:04X}, check 0x{CRC.check:04X}"),
        ("CRC byte order", f"{CRC_BYTE_ORDER}-endian ({'low' if CRC_BYTE_ORDER == 'little' else 'high'} byte first)"),
        ("error counters", f"{COUNTER_BITS}-bit, saturating"),
        ("receive timeout", f"a pause of more than {RX_TIMEOUT_BYTES} byte times "
                            f"({RX_TIMEOUT_BYTES * BYTE_BITS} bit times) inside a frame abandons it")])
    out += ["### Commands", "", "C: coordinates per leg; k: legs in the mask (1 .. legs). Sizes in bytes.", ""]
    out += _rows(("code", "command", "request payload", "request size", "answer code", "answer payload",
                  "answer size", "what it does"),
                 [(f"0x{c.code:02X}", f"`{c.name}`", ", ".join(_field_text(f) for f in c.request) or "–",
                   _size_formula(c.request), f"0x{answer_code(c):02X}",
                   ", ".join(_field_text(f) for f in c.answer) or "– (ack)", _size_formula(c.answer), c.doc)
                  for c in COMMANDS])
    out += ["### Fields", ""]
    out += _rows(("command", "direction", "field", "type", "meaning"),
                 [(f"`{c.name}`", d, f"`{f.name}`", _field_text(f).split(" ", 1)[1], f.doc)
                  for c in COMMANDS for d, fields in (("request", c.request), ("answer", c.answer))
                  for f in fields] + [("NACK", "answer", f"`{f.name}`", f.kind, f.doc) for f in NACK_FIELDS])
    out += ["### Codes", ""]
    out += _rows(("table", "code", "name", "meaning"),
                 [("NACK reason", i + 1, f"`{n}`", d) for i, (n, d) in enumerate(NACK_REASONS)]
                 + [("failsafe action", i, f"`{n}`", d) for i, (n, d) in enumerate(FAILSAFE_ACTIONS)]
                 + [("error counter", i, f"`{n}`", d) for i, (n, d) in enumerate(ERROR_COUNTERS)])
    return "\n".join(out)
