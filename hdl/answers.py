"""Request fields out of payload bytes and answer payloads into bytes, from the protocol table.

Both directions follow :data:`~ikseries.hdl.protocol.COMMANDS`: a payload is its fields in
order, each little-endian. The dispatcher's microprogram reads a request field byte by byte at
its offset and builds an answer byte by byte, so what it needs here is where each field's bytes
are.
"""
from __future__ import annotations

from . import protocol as P

__all__ = ["scalar_offsets", "answer_bytes", "answer_constant"]


def scalar_offsets(cmd: P.Command) -> dict[str, tuple[int, int, bool]]:
    """``{field: (byte offset, bytes, signed)}`` of the request's leading scalar fields (those
    before any leg target, whose offsets do not depend on the robot's shape)."""
    out, pos = {}, 0
    for f in cmd.request:
        if f.count != 1 or f.kind not in P.KINDS:
            break
        nbytes, signed = P.KINDS[f.kind]
        out[f.name] = (pos, nbytes, signed)
        pos += nbytes
    return out


def answer_bytes(fields: tuple[P.Field, ...]) -> int:
    """Payload bytes of an answer without a text field."""
    return sum(f.group_bytes(None) for f in fields)


def _field_bytes(f: P.Field, value) -> bytes:
    if f.kind in ("bytes", "text"):
        raw = value.encode() if isinstance(value, str) else bytes(value)
        if len(raw) > f.count or (f.kind == "bytes" and len(raw) != f.count):
            raise ValueError(f"{f.name} must be {'at most ' if f.kind == 'text' else ''}{f.count} bytes, "
                             f"not {len(raw)}")
        return raw
    nbytes, signed = P.KINDS[f.kind]
    bits = 8 * nbytes
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    if not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{f.name} must be an integer in [{lo}, {hi}] to fit a {f.kind}, not {value!r}")
    return value.to_bytes(nbytes, "little", signed=signed)


def answer_constant(fields: tuple[P.Field, ...], values: dict) -> bytes:
    """The payload of an answer whose field values are all Python constants (the identity)."""
    missing = [f.name for f in fields if f.name not in values]
    if missing or set(values) - {f.name for f in fields}:
        raise ValueError(f"answer fields must be {[f.name for f in fields]}, not {sorted(values)}")
    return b"".join(_field_bytes(f, values[f.name]) for f in fields)
