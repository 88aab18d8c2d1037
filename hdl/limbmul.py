"""Multi-cycle signed multiplier built from one DSP-sized product (limb by limb)."""
from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..constraints.devices import Primitive, dsp_size, family_primitives, multiplier_families
from ..constraints.facts import dsp_limbs

__all__ = ["LimbMultiplier", "check_dsp", "check_dsp_registers", "limb_split"]


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


def check_dsp_registers(dsp_registers, dsp) -> Primitive | None:
    """The DSP primitive of family ``dsp_registers`` (None for None); refuses a family without
    one, or a ``dsp`` size that is not the family's."""
    families = multiplier_families()
    if dsp_registers is None:
        return None
    if not isinstance(dsp_registers, str) or dsp_registers not in families or dsp != dsp_size(dsp_registers):
        raise ValueError("dsp_registers must be None, or "
                         + " or ".join(f"{f!r} with dsp={dsp_size(f)}" for f in families)
                         + f", not {dsp_registers!r}" + (f" with dsp={dsp}" if dsp_registers in families else ""))
    return family_primitives(dsp_registers, "multiplier")[0]


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
    limbs = tuple(dsp_limbs(w, d) for w, d in zip((a_width, b_width), dsp))
    return bits, limbs, tuple(l * n + 1 for l, n in zip(bits, limbs))


class LimbMultiplier(wiring.Component):
    """Exact signed product ``a * b`` computed with one ``dsp``-sized multiplier.

    The operands are latched, cut into signed limbs (see :func:`limb_split`) and the
    ``limbs_a * limbs_b`` partial products go through one registered multiplier (inputs
    and output registered, so it maps onto one DSP block of the family whose
    :attr:`~ikseries.constraints.facts.Family.dsp` is ``dsp``), one per cycle, and are
    accumulated, shifted into place, modulo ``2**product_width`` (one operand in one limb:
    the other's limbs from the top down, Horner's rule, a constant shift; the adder never
    spans the bits a later product cannot change). The accumulated sum is
    the exact product whenever that fits ``product_width`` signed bits.

    Parameters
    ----------
    a_width, b_width : int
        Signed widths of the operands.
    dsp : (int, int) or None
        Signed operand widths of the DSP product; None: one full-width product.
    product_width : int, optional
        Signed width of the result (default ``a_width + b_width``).
    dsp_registers : None or str
        None (default): the limb product's operand and product registers are fabric flip-flops
        (Yosys maps the product to a DSP block without absorbing them: they reset
        synchronously, its registers do not). A family with a DSP primitive
        (:data:`ikseries.constraints.devices.PRIMITIVES`; ``dsp`` must be its size): the limb
        product is an instantiated primitive whose own input and output registers are those
        registers (always enabled: its operand registers then also load while no limb pair is
        due, a product no later stage reads), same timing and outputs.

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
                 product_width: int | None = None, dsp_registers: str | None = None):
        self._bits, self._limbs, self._regw = limb_split(a_width, b_width, dsp)
        self._primitive = check_dsp_registers(dsp_registers, dsp)
        if product_width is None:
            product_width = a_width + b_width
        _check_width("product_width", product_width)
        self._a_width, self._b_width, self._pw, self._dsp = a_width, b_width, product_width, dsp
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"a": signed(a_width), "b": signed(b_width)}))),
            "o": Out(stream.Signature(signed(product_width), always_ready=True)),
        })

    @property
    def dsp_registers(self) -> str | None:
        """The family whose DSP primitive holds the limb product and its registers, or None."""
        return None if self._primitive is None else self._primitive.family

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

    def _pairs(self) -> list[tuple[int, int]]:
        """The (a limb, b limb) of each step. With one operand in one limb, from the top limb
        down: the accumulator is then Horner's rule, ``acc << bits + p``, a constant shift
        (no shift multiplexer before its adder); otherwise a-limb major, from the bottom."""
        (na, nb), nl = self._limbs, self.n_limbs
        if nb == 1:
            return [(na - 1 - s, 0) for s in range(nl)]
        if na == 1:
            return [(0, nb - 1 - s) for s in range(nl)]
        return [(s // nb, s % nb) for s in range(nl)]

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
        p = Signal(signed(len(da) + len(db)))
        if self._primitive is None:
            with m.If(v1):
                with m.Switch(s1):
                    for s, (i, j) in enumerate(self._pairs()):
                        with m.Case(s):
                            m.d.sync += [da.eq(limb(a, na, la, i)), db.eq(limb(b, nb, lb, j))]
            # stage 3: the DSP's output register
            m.d.sync += p.eq(da * db)
        else:   # stages 2 and 3 inside the primitive: the limb pair selected before its registers
            pa, pb = Signal.like(da, name="limb_a"), Signal.like(db, name="limb_b")
            with m.Switch(s1):
                for s, (i, j) in enumerate(self._pairs()):
                    with m.Case(s):
                        m.d.comb += [pa.eq(limb(a, na, la, i)), pb.eq(limb(b, nb, lb, j))]
            m.submodules.dsp = self._primitive.instance(m, pa, pb, p, Const(1, 1))
        s3 = Signal(range(nl))
        v3 = Signal()
        m.d.sync += [s3.eq(s2), v3.eq(v2)]
        acc = self._accumulate(m, p, s3, v3)
        done = Signal()
        m.d.sync += done.eq(v3 & (s3 == nl - 1))
        m.d.comb += [self.o.valid.eq(done), self.o.payload.eq(acc)]
        return m

    def _accumulate(self, m, p, s3, v3):
        """Stage 4: the partial product ``p`` of step ``s3`` accumulated (when ``v3``), modulo
        ``2**product_width``; the accumulator register."""
        (la, lb), (na, nb), nl = self._bits, self._limbs, self.n_limbs
        acc = Signal(signed(self._pw))
        if nl == 1:
            with m.If(v3):
                m.d.sync += acc.eq(p)
            return acc
        if na == 1 or nb == 1:
            # Horner, top limb first: (acc << l) + p, whose l low bits are p's: the adder is
            # l bits narrower than the product and has no multiplexer in front
            l = la if nb == 1 else lb
            lo, hi, step = 0, len(acc), Cat(p[:l], acc + (p >> l))
        else:
            # each product shifted to its place; every one after the first is shifted by at
            # least k bits, so acc's k low bits are final and the adder k bits narrower
            k = min(la, lb)
            shifted = Signal(signed(self._pw))
            with m.Switch(s3):
                for s, (i, j) in enumerate(self._pairs()):
                    with m.Case(s):
                        m.d.comb += shifted.eq(p << (la * i + lb * j))
            lo, hi, step = k, len(acc), acc[k:] + shifted[k:]
        with m.If(v3 & (s3 == 0)):
            m.d.sync += acc.eq(p)
        with m.Elif(v3):
            m.d.sync += acc[lo:hi].eq(step)
        return acc
