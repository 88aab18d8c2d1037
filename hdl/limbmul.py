"""Multi-cycle signed multiplier built from one DSP-sized product (limb by limb)."""
from __future__ import annotations

import math

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

__all__ = ["LimbMultiplier", "check_dsp", "limb_split"]


def _check_width(name, w):
    if not isinstance(w, int) or isinstance(w, bool) or w < 2:
        raise ValueError(f"{name} must be an integer >= 2 (signed bits), not {w!r}")


def check_dsp(dsp):
    """Refuse a ``dsp`` that is not None or a pair of signed operand widths."""
    ok = dsp is None or (isinstance(dsp, tuple) and len(dsp) == 2 and all(
        isinstance(d, int) and not isinstance(d, bool) and d >= 2 for d in dsp))
    if not ok:
        raise ValueError(f"dsp must be None or a pair of signed operand widths >= 2 such as (16, 16), "
                         f"not {dsp!r}")


def limb_split(a_width: int, b_width: int, dsp: tuple[int, int] | None):
    """How signed operands of ``a_width`` x ``b_width`` bits are cut for a ``dsp`` product.

    Every limb is a *signed* DSP operand: the low limbs carry ``dsp - 1`` bits each,
    zero-extended (never negative), the top limb carries the rest, sign-extended. So
    ``n`` limbs of ``l`` bits hold ``l * n + 1`` signed bits. Returns
    ``((limb_bits_a, limb_bits_b), (limbs_a, limbs_b), (reg_width_a, reg_width_b))``;
    ``dsp=None`` gives one full-width limb per operand.
    """
    _check_width("a_width", a_width)
    _check_width("b_width", b_width)
    check_dsp(dsp)
    if dsp is None:
        return (a_width - 1, b_width - 1), (1, 1), (a_width, b_width)
    bits = (dsp[0] - 1, dsp[1] - 1)
    limbs = tuple(max(1, math.ceil((w - 1) / l)) for w, l in zip((a_width, b_width), bits))
    return bits, limbs, tuple(l * n + 1 for l, n in zip(bits, limbs))


class LimbMultiplier(wiring.Component):
    """Exact signed product ``a * b`` computed with one ``dsp``-sized multiplier.

    The operands are latched, cut into signed limbs (see :func:`limb_split`) and the
    ``limbs_a * limbs_b`` partial products go through one registered multiplier (inputs
    and output registered, so it maps onto one DSP block of the family whose
    :attr:`~ikseries.constraints.facts.Family.dsp` is ``dsp``), one per cycle, and are
    accumulated, shifted into place, modulo ``2**product_width``. The accumulated sum is
    the exact product whenever that fits ``product_width`` signed bits.

    Parameters
    ----------
    a_width, b_width : int
        Signed widths of the operands.
    dsp : (int, int) or None
        Signed operand widths of the DSP product; None: one full-width product.
    product_width : int, optional
        Signed width of the result (default ``a_width + b_width``).

    Attributes
    ----------
    i : In(stream.Signature(StructLayout({"a": signed(a_width), "b": signed(b_width)})))
        Operands. ``i.ready`` is high when the unit can take a new pair.
    o : Out(stream.Signature(signed(product_width), always_ready=True))
        The product; ``o.valid`` is high for one cycle, and ``o.payload`` holds the
        product until the fourth cycle after the next transfer on ``i``.

    Latency
    -------
    ``latency`` = ``n_limbs + 3`` cycles from a transfer on ``i`` to ``o.valid``.

    Throughput
    ----------
    One operand pair every ``initiation_interval`` = ``n_limbs`` cycles (one per cycle
    when ``dsp`` is None or the operands fit one DSP).
    """

    def __init__(self, a_width: int, b_width: int, dsp: tuple[int, int] | None = None,
                 product_width: int | None = None):
        self._bits, self._limbs, self._regw = limb_split(a_width, b_width, dsp)
        if product_width is None:
            product_width = a_width + b_width
        _check_width("product_width", product_width)
        self._a_width, self._b_width, self._pw, self._dsp = a_width, b_width, product_width, dsp
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"a": signed(a_width), "b": signed(b_width)}))),
            "o": Out(stream.Signature(signed(product_width), always_ready=True)),
        })

    @property
    def limbs(self) -> tuple[int, int]:
        return self._limbs

    @property
    def n_limbs(self) -> int:
        return self._limbs[0] * self._limbs[1]

    @property
    def latency(self) -> int:
        return self.n_limbs + 3

    @property
    def initiation_interval(self) -> int:
        return self.n_limbs

    def elaborate(self, platform):
        m = Module()
        (la, lb), (na, nb), (wa, wb) = self._bits, self._limbs, self._regw
        nl = na * nb
        a = Signal(signed(wa))
        b = Signal(signed(wb))
        s1 = Signal(range(nl))
        v1 = Signal()
        last1 = s1 == nl - 1
        m.d.comb += self.i.ready.eq(~v1 | last1)
        with m.If(self.i.valid & self.i.ready):
            m.d.sync += [a.eq(self.i.payload.a), b.eq(self.i.payload.b), s1.eq(0), v1.eq(1)]
        with m.Elif(v1):
            m.d.sync += [s1.eq(s1 + 1), v1.eq(~last1)]

        # stage 2: the DSP's input registers hold one limb pair
        da = Signal(signed(wa if na == 1 else la + 1))
        db = Signal(signed(wb if nb == 1 else lb + 1))
        s2 = Signal(range(nl))
        v2 = Signal()

        def limb(x, n, l, k):
            return x if n == 1 else x[l * k:l * (k + 1)] if k < n - 1 else x[l * k:].as_signed()

        m.d.sync += [s2.eq(s1), v2.eq(v1)]
        with m.If(v1):
            with m.Switch(s1):
                for s in range(nl):
                    with m.Case(s):
                        m.d.sync += [da.eq(limb(a, na, la, s // nb)), db.eq(limb(b, nb, lb, s % nb))]
        # stage 3: the DSP's output register
        p = Signal(signed(len(da) + len(db)))
        s3 = Signal(range(nl))
        v3 = Signal()
        m.d.sync += [p.eq(da * db), s3.eq(s2), v3.eq(v2)]
        # stage 4: accumulate, each partial product shifted to its place
        acc = Signal(signed(self._pw))
        shifted = Signal(signed(self._pw))
        with m.Switch(s3):
            for s in range(nl):
                with m.Case(s):
                    m.d.comb += shifted.eq(p << (la * (s // nb) + lb * (s % nb)))
        with m.If(v3):
            m.d.sync += acc.eq(Mux(s3 == 0, 0, acc) + shifted)
        done = Signal()
        m.d.sync += done.eq(v3 & (s3 == nl - 1))
        m.d.comb += [self.o.valid.eq(done), self.o.payload.eq(acc)]
        return m
