"""Lower a multivariable polynomial to plan operations by nested Horner evaluation."""
from __future__ import annotations

from .plan import PlanBuilder

__all__ = ["horner", "parity_split"]


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


def parity_split(poly: dict, k: int) -> tuple[dict, dict]:
    """Split ``poly`` into E and O with ``poly = E(v_k**2) + v_k * O(v_k**2)`` (exponents halved)."""
    even, odd = {}, {}
    for e, c in poly.items():
        h = e[:k] + (e[k] // 2,) + e[k + 1:]
        (odd if e[k] % 2 else even)[h] = c
    return even, odd
