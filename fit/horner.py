"""Lower a multivariable polynomial to plan operations: nested Horner, or a Horner/Estrin mix
that trades a few multiplications for pipeline depth."""
from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

from .plan import PlanBuilder, extend_stages

__all__ = ["horner", "estrin", "power", "poly_degrees", "choose_split", "lower_poly", "parity_split"]


def horner(b: PlanBuilder, poly: dict, var_nodes: list[int], frac: int, coefficient=None) -> int:
    """Nested Horner scheme for ``sum c_e * prod(v_k ** e_k)``.

    Coefficients become ``coefficient(c_e, frac)`` nodes (default ``b.const``: ``c_e`` rounded
    to ``frac`` fractional bits; a piecewise plan passes per-cell tables to ``b.lut``), and every product
    ``r * v`` is truncated (floor) back to ``frac`` bits, so the accumulator
    keeps a fixed binary point. The first variable is the outermost loop.
    Multiplications: about one per term. Pipeline depth: two stages per power
    of the outermost variable (multiply, then add).
    """
    coefficient = coefficient or b.const
    if not var_nodes:
        (c,) = poly.values()    # exponents are distinct: one term is left
        return coefficient(c, frac)
    groups: dict[int, dict] = {}
    for e, c in poly.items():
        groups.setdefault(e[0], {})[e[1:]] = c
    r = None
    for i in range(max(groups), -1, -1):
        if r is not None:
            r = b.mul(r, var_nodes[0], frac)
        if i in groups:
            sub = horner(b, groups[i], var_nodes[1:], frac, coefficient)
            r = sub if r is None else b.add(r, sub)
    return r


def power(b: PlanBuilder, x: int, k: int, guard: int = 0) -> int:
    """``x ** k`` (k >= 1), every product truncated to ``frac(x) + guard`` bits (a normalised
    variable, |x| <= 1, keeps its powers <= 1). Built from the largest power of two <= k times
    the rest, so ``ceil(log2 k)`` multiplier stages; powers are shared through the builder's
    structural sharing (with ``guard=0``, ``x**2`` is the node ``b.mul(x, x, frac(x))`` that a
    parity split builds too)."""
    if k < 1:
        raise ValueError(f"power exponent must be >= 1, not {k}")
    if k == 1:
        return x
    f = b.frac(x) + guard
    h = 1 << (k.bit_length() - 1)
    if h == k:
        half = power(b, x, k // 2, guard)
        return b.mul(half, half, f)
    return b.mul(power(b, x, h, guard), power(b, x, k - h, guard), f)


def _splits(split, n: int) -> tuple:
    if split is None or isinstance(split, int):
        return (split,) * n
    split = tuple(split)
    if len(split) != n:
        raise ValueError(f"split must give one block size per variable ({n}), not {len(split)}")
    return split


def estrin(b: PlanBuilder, poly: dict, var_nodes: list[int], frac: int, coefficient=None,
           split: int | Sequence[int | None] | None = None, parity: int | None = None,
           guard: int = 0) -> int:
    """Horner/Estrin mix for ``sum c_e * prod(v_k ** e_k)`` (same operands and formats as
    :func:`horner`: coefficients ``coefficient(c_e, frac)``, products truncated to ``frac`` bits).

    Per variable x (the first outermost), with ``m`` its block size in ``split`` (an int for
    every variable, or one entry per variable; ``None`` or ``m > degree`` = Horner),
    ``p = sum_j q_j(x) * (x**m)**j``: the blocks ``q_j`` (degree < m in x) by Horner, in
    parallel, their coefficients (polynomials in the inner variables) lowered recursively
    the same way, then combined by Estrin as a tree: ``(q_0 + q_1 y) + (q_2 + q_3 y) y**2 + ...``
    with ``y = x**m`` and the powers from :func:`power` (truncated to ``frac(x) + guard`` bits).
    ``split=1`` is full Estrin. Depth per variable: ``2 (m - 1)`` for the blocks plus two per
    Estrin level instead of ``2 * degree``; extra multipliers: the powers of x.
    With ``split=None`` the nodes are exactly :func:`horner`'s.

    ``parity=k``: variable k has only even or only odd powers in part of the terms; evaluate
    ``E(..., v**2, ...) + v * O(..., v**2, ...)`` (:func:`parity_split`, ``v**2`` truncated to
    ``frac(v)`` bits, as the fitter's parity split), ``split`` applying to E and O.
    """
    coefficient = coefficient or b.const
    splits = _splits(split, len(var_nodes))
    if parity is None:
        return _estrin(b, poly, list(var_nodes), frac, coefficient, splits, guard)
    v = var_nodes[parity]
    vs = list(var_nodes[:parity]) + [power(b, v, 2)] + list(var_nodes[parity + 1:])
    even, odd = parity_split(poly, parity)
    acc = _estrin(b, even, vs, frac, coefficient, splits, guard) if even else None
    if odd:
        o = b.mul(v, _estrin(b, odd, vs, frac, coefficient, splits, guard), frac)
        acc = o if acc is None else b.add(acc, o)
    return acc


def _estrin(b, poly, vs, frac, coefficient, splits, guard) -> int:
    if not vs:
        (c,) = poly.values()
        return coefficient(c, frac)
    groups: dict[int, dict] = {}
    for e, c in poly.items():
        groups.setdefault(e[0], {})[e[1:]] = c
    n, x = max(groups), vs[0]
    m = splits[0] if splits[0] is not None and splits[0] <= n else n + 1
    if m < 1:
        raise ValueError(f"block size must be >= 1, not {m}")
    blocks = []
    for j in range(n // m, -1, -1):   # highest block first, each a Horner as in horner()
        r = None
        for i in range(min(n, j * m + m - 1), j * m - 1, -1):
            if r is not None:
                r = b.mul(r, x, frac)
            if i in groups:
                sub = _estrin(b, groups[i], vs[1:], frac, coefficient, splits[1:], guard)
                r = sub if r is None else b.add(r, sub)
        blocks.append(r)
    blocks.reverse()
    k = m
    while len(blocks) > 1:   # Estrin: pair the blocks with y = x**k, then y**2 ...
        y = power(b, x, k, guard)
        pairs = []
        for lo, hi in itertools.zip_longest(blocks[::2], blocks[1::2]):
            t = None if hi is None else b.mul(hi, y, frac)
            pairs.append(lo if t is None else t if lo is None else b.add(lo, t))
        blocks, k = pairs, 2 * k
    return blocks[0]


def poly_degrees(poly: dict, parity: int | None = None) -> tuple[int, ...]:
    """Highest exponent of every variable (of the parity variable's square with ``parity``)."""
    return tuple(max(e[k] // (2 if k == parity else 1) for e in poly) for k in range(len(next(iter(poly)))))


def choose_split(b: PlanBuilder, lower: Callable[[tuple], int], degrees: Sequence[int],
                 max_extra_muls: int | None = None) -> tuple[tuple, int, int]:
    """The per-variable block sizes (``split`` of :func:`estrin`) of least pipeline depth.

    ``lower(split)`` builds a candidate into ``b`` and returns its result node (so a caller can
    wrap :func:`estrin`, e.g. with a parity split ``E(v**2) + v * O(v**2)``); ``degrees`` the
    highest exponent per variable. Every combination of block sizes (``None`` = Horner,
    1 .. degree) is built on a scratch copy (:meth:`PlanBuilder.trial`) and measured: the
    stage of its result, then the multipliers it adds to ``b`` (shared nodes already in ``b``
    are free). With ``max_extra_muls`` only candidates with at most that many multipliers more
    than Horner qualify (Horner always does). Returns ``(split, stage, multipliers)``.
    Cost: ``prod(degree + 1)`` trial builds. Nesting per variable gains little when every
    variable is ready together and the total degree is spread over 3 variables (the inner
    blocks' depths add up); it gains most on a late outer variable (e.g. rho2).
    """
    base = b.stages()
    start = len(b.nodes)
    best = None
    horner_muls = None
    for split in itertools.product(*[(None, *range(1, d + 1)) for d in degrees]):
        with b.trial():
            node = lower(split)
            stage = extend_stages(b.nodes, base[:start])[node]
            muls = sum(1 for n in b.nodes[start:] if n.op == "mul")
        if horner_muls is None:   # the first candidate is all-Horner
            horner_muls = muls
        if max_extra_muls is not None and muls - horner_muls > max_extra_muls:
            continue
        if best is None or (stage, muls) < best[1:]:
            best = (split, stage, muls)
    return best


def lower_poly(b: PlanBuilder, poly: dict, var_nodes: list[int], frac: int, coefficient=None,
               parity: int | None = None, max_extra_muls: int | None = None, guard: int = 0) -> int:
    """:func:`estrin` with the split :func:`choose_split` picks (least depth, then fewest
    multipliers, within ``max_extra_muls`` more than Horner if given)."""
    def lower(split):
        return estrin(b, poly, var_nodes, frac, coefficient, split, parity, guard)
    split, _, _ = choose_split(b, lower, poly_degrees(poly, parity), max_extra_muls)
    return lower(split)


def parity_split(poly: dict, k: int) -> tuple[dict, dict]:
    """Split ``poly`` into E and O with ``poly = E(v_k**2) + v_k * O(v_k**2)`` (exponents halved)."""
    even, odd = {}, {}
    for e, c in poly.items():
        h = e[:k] + (e[k] // 2,) + e[k + 1:]
        (odd if e[k] % 2 else even)[h] = c
    return even, odd
