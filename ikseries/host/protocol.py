"""Host-side frame codec of the controller's link: CRC, request encoder, frame parser, decoder.

Everything comes from the protocol table (:mod:`ikseries.hdl.protocol`): the CRC is computed in
pure Python from :data:`~ikseries.hdl.protocol.CRC`'s parameters, field layouts and value ranges
from :data:`~ikseries.hdl.protocol.COMMANDS`. :class:`FrameParser` follows the same frame rules as
the hardware receiver (:class:`ikseries.hdl.link.FrameReceiver`), so a parser over the request
lengths (:func:`request_parser`) is a model of it.
"""
from __future__ import annotations

from dataclasses import dataclass, field as dataclass_field
from functools import lru_cache
from typing import Iterable, Mapping

from ..hdl import protocol as P

__all__ = ["CRCTable", "crc", "frame", "field_bounds", "encode", "encode_answer", "decode_request", "decode_answer",
           "Message", "FrameParser", "request_parser", "Decoder"]


class CRCTable:
    """A byte-at-a-time CRC of ``params`` (a :class:`ikseries.hdl.protocol.CRCParameters`)."""

    def __init__(self, params: P.CRCParameters):
        if params.width < 8:
            raise ValueError(f"CRC width must be at least 8 bits for the byte table, not {params.width!r}")
        self.params = params
        w = params.width
        self._mask = (1 << w) - 1
        poly = _reflect(params.polynomial, w) if params.reflect_input else params.polynomial
        table = []
        for b in range(256):
            if params.reflect_input:     # LSB-first register
                r = b
                for _ in range(8):
                    r = (r >> 1) ^ poly if r & 1 else r >> 1
            else:
                r = b << (w - 8)
                for _ in range(8):
                    r = ((r << 1) ^ poly) if r & (1 << (w - 1)) else r << 1
            table.append(r & self._mask)
        self._table = tuple(table)

    def compute(self, data: Iterable[int]) -> int:
        p, w, t, mask = self.params, self.params.width, self._table, self._mask
        if p.reflect_input:
            r = _reflect(p.initial, w)
            for b in data:
                r = (r >> 8) ^ t[(r ^ b) & 0xFF]
            out = r if p.reflect_output else _reflect(r, w)
        else:
            r = p.initial
            for b in data:
                r = ((r << 8) & mask) ^ t[((r >> (w - 8)) ^ b) & 0xFF]
            out = _reflect(r, w) if p.reflect_output else r
        return out ^ p.xor_output


def _reflect(v: int, width: int) -> int:
    return int(format(v, f"0{width}b")[::-1], 2)


@lru_cache(maxsize=None)
def _table(params: P.CRCParameters) -> CRCTable:
    return CRCTable(params)


def crc(data: Iterable[int], params: P.CRCParameters = P.CRC) -> int:
    """The CRC of ``data`` (bytes)."""
    return _table(params).compute(data)


def frame(code: int, payload: bytes) -> bytes:
    """``SYNC LEN CMD PAYLOAD CRC`` for ``code`` and ``payload``."""
    if not isinstance(code, int) or not 0 <= code <= 0xFF:
        raise ValueError(f"command code must be a byte in [0, 255], not {code!r}")
    if len(payload) > P.MAX_PAYLOAD:
        raise ValueError(f"payload must be at most {P.MAX_PAYLOAD} bytes, not {len(payload)}")
    body = bytes((len(payload), code)) + bytes(payload)
    return bytes((P.SYNC,)) + body + crc(body).to_bytes(P.CRC.width // 8, P.CRC_BYTE_ORDER)


# ---- field values ---------------------------------------------------------------------------

def field_bounds(f: P.Field, shape: P.Shape | None) -> tuple[int, int, str]:
    """The integer range of ``f`` (for a robot of ``shape``; None: the kind's range) and how to
    say it when a value is outside."""
    nbytes, signed = P.KINDS[f.kind]
    lo, hi = (-(1 << (8 * nbytes - 1)), (1 << (8 * nbytes - 1)) - 1) if signed else (0, (1 << (8 * nbytes)) - 1)
    rule = f.values if shape is not None else None
    if rule == "channel":
        lo, hi = 0, shape.channels - 1
    elif rule == "leg":
        lo, hi = 0, shape.legs - 1
    elif rule == "channel_mask":
        return 0, (1 << shape.channels) - 1, f"a mask of channels 0..{shape.channels - 1} (at most {hex((1 << shape.channels) - 1)})"
    elif rule == "leg_mask":
        return 1, (1 << shape.legs) - 1, f"a non-empty mask of legs 0..{shape.legs - 1} (1 .. {hex((1 << shape.legs) - 1)})"
    elif rule == "failsafe_action":
        lo, hi = 0, len(P.FAILSAFE_ACTIONS) - 1
    return lo, hi, f"in [{lo}, {hi}]"


def _int(f: P.Field, v, shape, where: str) -> int:
    if f.values == "failsafe_action" and isinstance(v, str):
        names = [n for n, _ in P.FAILSAFE_ACTIONS]
        if v not in names:
            raise ValueError(f"{where} must be one of {', '.join(names)} (or 0..{len(names) - 1}), not {v!r}")
        v = names.index(v)
    lo, hi, said = field_bounds(f, shape)
    if not isinstance(v, int) or isinstance(v, bool) or not lo <= v <= hi:
        raise ValueError(f"{where} must be {said}, not {hex(v) if 'mask' in said and isinstance(v, int) else repr(v)}")
    return v


def _ints(f: P.Field, v, n: int, shape, where: str) -> tuple[int, ...]:
    if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) != n:
        raise ValueError(f"{where} must be {n} integers, not {v!r}")
    return tuple(_int(f, x, shape, f"{where}[{i}]") for i, x in enumerate(v))


def _pack(fields: tuple[P.Field, ...], values: Mapping, shape: P.Shape | None, name: str) -> tuple[bytes, dict]:
    """The payload of ``values`` (checked) and the values normalised (tuples, codes)."""
    names = [f.name for f in fields]
    extra = sorted(set(values) - set(names))
    missing = [n for n in names if n not in values]
    if extra or missing:
        raise ValueError(f"{name} takes fields ({', '.join(names) or 'none'}), not "
                         f"{'unknown ' + repr(extra[0]) if extra else 'without ' + repr(missing[0])}")
    out, norm = bytearray(), {}
    for f in fields:
        v, where = values[f.name], f.name
        if f.kind == "text":
            raw = v.encode() if isinstance(v, str) else None
            if raw is None or len(raw) > f.count:
                raise ValueError(f"{where} must be a string of at most {f.count} UTF-8 bytes, not {v!r}")
            out += raw
            norm[f.name] = v
            continue
        if f.kind == "bytes":
            if not isinstance(v, (bytes, bytearray)) or len(v) != f.count:
                raise ValueError(f"{where} must be {f.count} bytes, not {v!r}")
            out += v
            norm[f.name] = bytes(v)
            continue
        nbytes, signed = P.KINDS[f.kind]
        n = f.elements(shape)
        if f.per is not None:
            k = bin(norm[f.per]).count("1")
            if isinstance(v, (str, bytes)) or not hasattr(v, "__len__") or len(v) != k:
                raise ValueError(f"{where} must be {k} groups of {n} integers (one per leg in {f.per}), not {v!r}")
            val = tuple(_ints(f, g, n, shape, f"{where}[{j}]") for j, g in enumerate(v))
            flat = [x for g in val for x in g]
        elif f.count == 1:
            val = _int(f, v, shape, where)
            flat = [val]
        else:
            val = _ints(f, v, n, shape, where)
            flat = list(val)
        for x in flat:
            out += x.to_bytes(nbytes, "little", signed=signed)
        norm[f.name] = val
    return bytes(out), norm


def _unpack(fields: tuple[P.Field, ...], payload: bytes, shape: P.Shape | None) -> dict:
    values, pos = {}, 0
    for f in fields:
        if f.kind == "text":
            values[f.name] = payload[pos:].decode(errors="replace")
            pos = len(payload)
            continue
        if f.kind == "bytes":
            values[f.name] = bytes(payload[pos:pos + f.count])
            pos += f.count
            continue
        nbytes, signed = P.KINDS[f.kind]
        n = f.elements(shape)
        groups = bin(values[f.per]).count("1") if f.per is not None else 1
        flat = []
        for _ in range(groups * n):
            flat.append(int.from_bytes(payload[pos:pos + nbytes], "little", signed=signed))
            pos += nbytes
        if f.per is not None:
            values[f.name] = tuple(tuple(flat[j * n:(j + 1) * n]) for j in range(groups))
        else:
            values[f.name] = flat[0] if f.count == 1 else tuple(flat)
    if pos != len(payload):
        raise ValueError(f"payload must be {pos} bytes for these fields, not {len(payload)}")
    return values


@dataclass(frozen=True)
class Message:
    """A decoded frame: the command's name, its field values, and whether it is a NACK (then
    ``command`` is the refused request and ``fields`` is ``{"reason": <reason name>}``)."""
    command: str
    fields: dict = dataclass_field(default_factory=dict)
    nack: bool = False


def encode(command: str | int, shape: P.Shape, **fields) -> bytes:
    """The request frame of ``command`` with ``fields`` for a robot of ``shape``."""
    cmd = P.command(command)
    payload, _ = _pack(cmd.request, fields, shape, cmd.name)
    return frame(cmd.code, payload)


def encode_answer(command: str | int, **fields) -> bytes:
    """The answer frame of ``command`` (``"nack"``: fields ``request`` and ``reason``, names or codes)."""
    if command == "nack":
        req = fields.get("request")
        reason = fields.get("reason")
        names = [n for n, _ in P.NACK_REASONS]
        code = P.command(req).code if req is not None else None
        if isinstance(reason, str):
            if reason not in names:
                raise ValueError(f"reason must be one of {', '.join(names)}, not {reason!r}")
            reason = names.index(reason) + 1
        payload, _ = _pack(P.NACK_FIELDS, {"request": code, "reason": reason}, None, "nack")
        return frame(P.NACK, payload)
    cmd = P.command(command)
    payload, _ = _pack(cmd.answer, fields, None, f"{cmd.name} answer")
    return frame(P.answer_code(cmd), payload)


def decode_request(code: int, payload: bytes, shape: P.Shape) -> Message:
    """The request ``code`` with ``payload`` (a length :func:`request_parser` accepted)."""
    cmd = P.command(code)
    return Message(cmd.name, _unpack(cmd.request, payload, shape))


def decode_answer(code: int, payload: bytes) -> Message:
    """The answer ``code`` with ``payload`` (a length :class:`Decoder` accepted)."""
    if code == P.NACK:
        v = _unpack(P.NACK_FIELDS, payload, None)
        try:
            req = P.command(v["request"]).name
        except ValueError:     # a code this host does not know: keep the number
            req = v["request"]
        reasons = [n for n, _ in P.NACK_REASONS]
        reason = reasons[v["reason"] - 1] if 1 <= v["reason"] <= len(reasons) else v["reason"]
        return Message(req, {"reason": reason}, nack=True)
    cmd = P.command(code & ~P.ANSWER_BIT)
    return Message(cmd.name, _unpack(cmd.answer, payload, None))


# ---- framing --------------------------------------------------------------------------------

class FrameParser:
    """Frames out of a byte stream, by the rules of ``docs/protocol.md`` ("Receiving").

    ``lengths`` maps each accepted CMD to its payload lengths. :meth:`feed` returns the good
    ``(code, payload)`` frames; ``counters`` counts ``garbage`` (bytes skipped while hunting for
    SYNC), ``bad_length``, ``unknown_command`` and ``crc`` exactly as the hardware does.
    :meth:`pause` is the receive timeout: call it when the line was quiet for more than
    :data:`~ikseries.hdl.protocol.RX_TIMEOUT_BYTES` byte times.
    """

    def __init__(self, lengths: Mapping[int, frozenset[int]]):
        self.lengths = dict(lengths)
        self.max_length = max(max(v) for v in self.lengths.values())
        self.counters = {"garbage": 0, "bad_length": 0, "unknown_command": 0, "crc": 0}
        self._state, self._buf, self._need = "hunt", bytearray(), 0

    def _reject(self, counter: str, b: int) -> None:
        self.counters[counter] += 1
        self._state = "len" if b == P.SYNC else "hunt"

    def pause(self) -> None:
        """A pause longer than the receive timeout: a frame in progress is abandoned, uncounted."""
        self._state = "hunt"

    def feed(self, data: Iterable[int]) -> list[tuple[int, bytes]]:
        out, crc_bytes = [], P.CRC.width // 8
        for b in data:
            st = self._state
            if st == "hunt":
                if b == P.SYNC:
                    self._state = "len"
                else:
                    self.counters["garbage"] += 1
            elif st == "len":
                if b > self.max_length:
                    self._reject("bad_length", b)
                else:
                    self._buf = bytearray((b,))
                    self._state = "cmd"
            elif st == "cmd":
                if b not in self.lengths:
                    self._reject("unknown_command", b)
                elif self._buf[0] not in self.lengths[b]:
                    self._reject("bad_length", b)
                else:
                    self._buf.append(b)
                    self._need = self._buf[0] + crc_bytes
                    self._state = "body"
            else:
                self._buf.append(b)
                self._need -= 1
                if self._need == 0:
                    self._state = "hunt"
                    body, sent = self._buf[:-crc_bytes], self._buf[-crc_bytes:]
                    if crc(body) == int.from_bytes(sent, P.CRC_BYTE_ORDER):
                        out.append((self._buf[1], bytes(self._buf[2:-crc_bytes])))
                    else:
                        self.counters["crc"] += 1
        return out


def request_parser(shape: P.Shape) -> FrameParser:
    """A parser of requests for a robot of ``shape``: the model of the hardware receiver."""
    return FrameParser({c.code: P.request_lengths(c, shape) for c in P.COMMANDS})


class Decoder:
    """Answers out of the controller's byte stream: :meth:`feed` bytes, get :class:`Message`\\ s.

    Garbage and bad frames are skipped and counted in ``counters`` (see :class:`FrameParser`).
    """

    def __init__(self):
        lengths = {P.answer_code(c): P.answer_lengths(c) for c in P.COMMANDS}
        lengths[P.NACK] = frozenset({sum(f.group_bytes(None) for f in P.NACK_FIELDS)})
        self._parser = FrameParser(lengths)

    @property
    def counters(self) -> dict:
        return self._parser.counters

    def pause(self) -> None:
        """The line was quiet for longer than the receive timeout (see :meth:`FrameParser.pause`)."""
        self._parser.pause()

    def feed(self, data: Iterable[int]) -> list[Message]:
        return [decode_answer(code, payload) for code, payload in self._parser.feed(data)]
