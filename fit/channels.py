"""The per-channel table applied around a shared plan: the mirror of left legs and each
channel's calibration constants.

A robot core (:class:`ikseries.hdl.shared.RobotCore`) evaluates one plan for every leg. The
table says, per leg, whether its target is mirrored before the plan (``mirror_input`` negated),
and per channel (leg ``l``, servo ``j``: channel ``l * servos + j``) what the servo's width
becomes after it::

    width = min(max(offset + sign * plan_width, lo), hi)

``sign`` -1 mirrors the pulse (``offset`` = 2 centre + trim), +1 passes it (``offset`` = trim).
A table whose channels scale the plan's pulse (a leg's servo with a gain of its own:
``gain_bits`` > 0) has a fixed-point gain per channel, ``gain / 2**gain_bits``, and an offset at
the same scale that carries the rounding half::

    width = min(max((offset + sign * gain * plan_width) >> gain_bits, lo), hi)

The constants change no fit and no coefficient: a trim or a limit changes this table only.

This module is the semantics (:meth:`ChannelTable.mirror_inputs`, :meth:`ChannelTable.apply`:
the golden model runs them), the interval analysis the hardware widths come from
(:meth:`ChannelTable.sum_range`) and the checks; the RTL is ``RobotCore``'s. No Amaranth here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TableChannel", "ChannelTable"]


@dataclass(frozen=True)
class TableChannel:
    """One channel's constants (ticks): ``width = min(max((offset + sign * gain * w) >>
    gain_bits, lo), hi)`` (``gain`` 1 in a table without gains, ``gain_bits`` 0)."""
    sign: int
    offset: int
    lo: int
    hi: int
    gain: int = 1

    def record(self, gains: bool = False) -> dict:
        d = {"sign": self.sign, "offset": self.offset, "lo": self.lo, "hi": self.hi}
        if gains:     # left out without gains: the records (and manifests) they predate
            d["gain"] = self.gain
        return d


@dataclass(frozen=True)
class ChannelTable:
    """The table of a robot of ``legs`` legs of ``servos`` (leg-major channels)."""
    legs: int
    servos: tuple[str, ...]
    mirror_input: str | None           # the input negated for a mirrored leg (None: no leg is)
    mirrored: tuple[bool, ...]         # per leg
    channels: tuple[TableChannel, ...]
    gain_bits: int = 0                 # fraction bits of the channels' gains (0: no gains)

    def __post_init__(self):
        n = self.legs * len(self.servos)
        if len(self.channels) != n or len(self.mirrored) != self.legs:
            raise ValueError(f"a channel table of {self.legs} legs x {len(self.servos)} servos needs {n} channels "
                             f"and {self.legs} mirror flags, not {len(self.channels)} and {len(self.mirrored)}")
        for k, c in enumerate(self.channels):
            if c.sign not in (1, -1) or not c.lo <= c.hi:
                raise ValueError(f"channel {k} must have sign +1 or -1 and lo <= hi, not {c!r}")
            if c.gain < 1 or (self.gain_bits == 0 and c.gain != 1):
                raise ValueError(f"channel {k} must have a gain >= 1 (1 with gain_bits 0), not {c.gain!r}")
        if self.gain_bits < 0:
            raise ValueError(f"gain_bits must be >= 0, not {self.gain_bits!r}")
        if any(self.mirrored) != (self.mirror_input is not None):
            raise ValueError("mirror_input must be named exactly when some leg is mirrored")

    def channel(self, leg: int, servo: str) -> TableChannel:
        return self.channels[leg * len(self.servos) + self.servos.index(servo)]

    # -- checks against a plan --------------------------------------------------------------
    def check(self, plan) -> None:
        """Fail (one line) unless the table fits ``plan``: its servos, every channel's limits
        within its servo's unsigned output width (so the width keeps the plan's output shape),
        and a mirrored input whose in-range integers are their own negation."""
        names = tuple(o.name for o in plan.outputs)
        if names != self.servos:
            raise ValueError(f"channel table servos must be the plan's ({', '.join(names)}), "
                             f"not ({', '.join(self.servos)})")
        for k, c in enumerate(self.channels):
            node = plan.nodes[plan.outputs[k % len(names)].node]
            top = (1 << node.width) - 1
            if node.lo < 0 or not 0 <= c.lo <= c.hi <= top:
                raise ValueError(f"channel {k} (leg {k // len(names)} {names[k % len(names)]}) limits [{c.lo}, {c.hi}] "
                                 f"ticks must fit the plan's {node.width}-bit unsigned output [0, {top}]")
        if self.mirror_input is not None:
            inp = next((i for i in plan.inputs if i.name == self.mirror_input), None)
            if inp is None or inp.lo != -inp.hi:
                rng = "no such input" if inp is None else f"[{inp.lo}, {inp.hi}]"
                raise ValueError(f"plan input {self.mirror_input} must have a range symmetric about 0 to be "
                                 f"mirrored, not {rng}")

    def is_identity(self, plan) -> bool:
        """True when the table changes nothing for ``plan``: no mirrored leg, every channel
        sign +1, offset 0 and limits containing its servo's output range (the core then has
        no table stage)."""
        if self.mirror_input is not None:
            return False
        n = len(self.servos)
        for k, c in enumerate(self.channels):
            node = plan.nodes[plan.outputs[k % n].node]
            if self.gain_bits or c.sign != 1 or c.offset != 0 or c.lo > node.lo or c.hi < node.hi:
                return False
        return True

    def sum_range(self, plan, j: int) -> tuple[int, int]:
        """The range of ``offset + sign * gain * width`` of servo ``j`` over every leg and
        every width its output node can take (interval analysis: the adder's width)."""
        node = plan.nodes[plan.outputs[j].node]
        ends = [c.offset + c.sign * c.gain * w for c in self.channels[j::len(self.servos)] for w in (node.lo, node.hi)]
        return min(ends), max(ends)

    def gain_range(self, j: int) -> int:
        """The largest gain of servo ``j``'s channels (the multiplier's constant operand)."""
        return max(c.gain for c in self.channels[j::len(self.servos)])

    # -- semantics ---------------------------------------------------------------------------
    def mirror_inputs(self, plan, legs, ints: dict) -> dict:
        """Port integers as the plan sees them: a mirrored leg's ``mirror_input`` negated,
        saturated to its port (only the most negative port value, out of range, needs it)."""
        if self.mirror_input is None:
            return dict(ints)
        inp = next(i for i in plan.inputs if i.name == self.mirror_input)
        flip = np.asarray(self.mirrored, dtype=bool)[np.asarray(legs, dtype=np.int64)]
        v = np.asarray(ints[inp.name], dtype=np.int64)
        return {**ints, inp.name: np.where(flip, np.minimum(-v, inp.port_range[1]), v)}

    def apply(self, legs, widths: dict) -> dict:
        """Channel widths of the plan's ``widths`` ({servo: int array}) for targets of ``legs``."""
        legs = np.asarray(legs, dtype=np.int64)
        out = {}
        for j, s in enumerate(self.servos):
            ch = self.channels[j::len(self.servos)]
            sign, off, lo, hi, gain = (np.array([getattr(c, f) for c in ch], dtype=np.int64)[legs]
                                       for f in ("sign", "offset", "lo", "hi", "gain"))
            v = off + sign * gain * np.asarray(widths[s], dtype=np.int64)
            out[s] = np.clip(v >> self.gain_bits, lo, hi)     # >>: the floor, as the hardware's shift
        return out

    # -- records ------------------------------------------------------------------------------
    def record(self) -> dict:
        d = {"legs": self.legs, "servos": list(self.servos), "mirror_input": self.mirror_input,
             "mirrored": list(self.mirrored), "channels": [c.record(self.gain_bits > 0) for c in self.channels]}
        if self.gain_bits:
            d["gain_bits"] = self.gain_bits
        return d

    @classmethod
    def from_record(cls, d: dict) -> "ChannelTable":
        return cls(d["legs"], tuple(d["servos"]), d["mirror_input"], tuple(d["mirrored"]),
                   tuple(TableChannel(**c) for c in d["channels"]), d.get("gain_bits", 0))
