"""The fuzz traffic: a seeded mix of good requests, corrupted ones and garbage, cut into
segments that each end with the one good frame the protocol's receiver finds in it.

The good requests are those whose effect on the pins the model knows exactly and that fit the
short test period (moves inside the test's target box, pulses in its width range, reads). Any
piece whose bytes would complete a frame of another kind (a corrupted LEN that is still the
right one, garbage that happens to frame) is drawn again, so what the receiver finds is only
ever a frame of that set; which good-looking frames are swallowed by an earlier truncated
one is the receiver model's verdict (:func:`ikseries.host.protocol.request_parser`).
"""
from __future__ import annotations

import copy
import random
from dataclasses import dataclass

from ikseries.hdl import protocol as P
from ikseries.host.protocol import decode_request, encode, request_parser
from ikseries.linkcheck import corrupt, random_request

__all__ = ["Traffic", "fuzz_traffic", "GOOD"]

#: the commands of the good requests in the fuzz
GOOD = ("move_leg", "move_legs", "set_pulse", "status", "channel_status", "identity")
#: bytes a host sends to leave the receiver hunting whatever its state (docs/protocol.md)
RESYNC = 68


@dataclass
class Traffic:
    """The segments to send, the receiver model's counters over all of them, and how many good
    frames directly follow a bad piece (the resynchronisations the stream exercises)."""
    segments: list[bytes]
    counters: dict
    resyncs: int
    nbytes: int


def _good(rng: random.Random, shape: P.Shape, box, pulses) -> bytes:
    cmd = rng.choice(GOOD)
    def target():
        return [rng.randint(lo, hi) for lo, hi in box]
    if cmd == "move_leg":
        return encode(cmd, shape, leg=rng.randrange(shape.legs), target=target())
    if cmd == "move_legs":
        mask = rng.randrange(1, 1 << shape.legs)
        return encode(cmd, shape, legs=mask, targets=[target() for _ in range(bin(mask).count("1"))])
    if cmd == "set_pulse":
        ch = rng.randrange(shape.channels)
        return encode(cmd, shape, channel=ch, pulse=rng.randint(*pulses[ch]))
    if cmd == "channel_status":
        return encode(cmd, shape, channel=rng.randrange(shape.channels))
    return encode(cmd, shape)


def _bad(rng: random.Random, shape: P.Shape) -> tuple[bytes, str]:
    if rng.random() < 0.7:
        return corrupt(rng, random_request(rng, shape), shape), "corrupt"
    return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 12))), "garbage"


def fuzz_traffic(rng: random.Random, shape: P.Shape, nbytes: int, box, pulses) -> Traffic:
    """About ``nbytes`` of traffic (half the pieces good) and the resynchronising tail: 68 zero
    bytes and a ``status`` request, whose answer holds the counters of everything before it.
    ``box``: (lo, hi) per target coordinate; ``pulses``: (lo, hi) per channel."""
    parser = request_parser(shape)
    segments, current, resyncs, after_bad, sent = [], bytearray(), 0, False, 0
    while sent < nbytes:
        kind = "good" if rng.random() < 0.5 else None
        piece, kind = (_good(rng, shape, box, pulses), "good") if kind else _bad(rng, shape)
        trial = copy.deepcopy(parser)
        frames = trial.feed(piece)
        if any(P.command(c).name not in GOOD for c, _ in frames) or len(frames) > 1 or \
                (frames and kind != "good"):
            continue
        parser, sent = trial, sent + len(piece)
        current += piece
        if frames:
            resyncs += after_bad
            segments.append(bytes(current))
            current = bytearray()
        after_bad = kind != "good" or (not frames and after_bad)
    resync = bytes(RESYNC) + encode("status", shape)
    frames = parser.feed(resync)      # ``current`` is in the parser already, piece by piece
    assert [decode_request(c, p, shape).command for c, p in frames] == ["status"], \
        f"the resynchronising tail gave {frames}"
    segments.append(bytes(current) + resync)
    counters = {k: v for k, v in parser.counters.items() if k != "garbage"}
    return Traffic(segments, counters, resyncs, sum(map(len, segments)))
