"""Request fields out of payload bytes and answer payloads into bytes, from the protocol table.

Both directions follow :data:`~ikseries.hdl.protocol.COMMANDS`: a payload is its fields in
order, each little-endian, so a field is a bit slice of the payload read as one integer and an
answer payload is the :func:`~amaranth.hdl.Cat` of its fields (Cat is least significant first).
"""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Value

from . import protocol as P

__all__ = ["scalar_offsets", "head_bytes", "pack_answer", "answer_bytes", "has_targets"]


def has_targets(cmd: P.Command) -> bool:
    """Whether the request carries leg targets (``count="coords"`` fields)."""
    return any(f.count == "coords" for f in cmd.request)


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


def head_bytes(shape: P.Shape) -> int:
    """The most payload bytes a request holds besides leg targets (the dispatcher's argument
    register): every byte of a request without targets, the leading scalars of one with them."""
    return max(max(P.request_lengths(c, shape)) if not has_targets(c)
               else sum(n for _, n, _ in scalar_offsets(c).values()) for c in P.COMMANDS)


def field_value(args: Value, cmd: P.Command, name: str) -> Value:
    """Field ``name`` of request ``cmd`` in the argument register ``args`` (its payload bytes)."""
    off, nbytes, signed = scalar_offsets(cmd)[name]
    v = args[8 * off:8 * (off + nbytes)]
    return v.as_signed() if signed else v


def _field_bits(f: P.Field, value) -> Value:
    if f.kind in ("bytes", "text"):
        raw = value.encode() if isinstance(value, str) else bytes(value)
        limit = f.count
        if len(raw) > limit or (f.kind == "bytes" and len(raw) != limit):
            raise ValueError(f"{f.name} must be {'at most ' if f.kind == 'text' else ''}{limit} bytes, not {len(raw)}")
        return Const(int.from_bytes(raw, "little"), 8 * len(raw)) if raw else Const(0, 0)
    bits = 8 * P.KINDS[f.kind][0]
    if isinstance(value, int):
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if P.KINDS[f.kind][1] else (0, (1 << bits) - 1)
        if not lo <= value <= hi:
            raise ValueError(f"{f.name} must be in [{lo}, {hi}] to fit a {f.kind}, not {value}")
        return Const(value, bits)
    v = Value.cast(value)
    if len(v) > bits:      # a wider value would be cut: a wiring mistake, not a run-time condition
        raise ValueError(f"{f.name} must fit {bits} bits, not a {len(v)}-bit value")
    return Cat(v, Const(0, bits - len(v)))


def pack_answer(fields: tuple[P.Field, ...], values: dict) -> Value:
    """The payload of an answer with these field values (Amaranth values or Python constants),
    byte ``i`` at bits ``8 i .. 8 i + 7``."""
    missing = [f.name for f in fields if f.name not in values]
    if missing or set(values) - {f.name for f in fields}:
        raise ValueError(f"answer fields must be {[f.name for f in fields]}, not {sorted(values)}")
    return Cat(*(_field_bits(f, values[f.name]) for f in fields))


def answer_bytes(fields: tuple[P.Field, ...]) -> int:
    """Payload bytes of an answer without a text field."""
    return sum(f.group_bytes(None) for f in fields)
