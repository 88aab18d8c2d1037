"""Horner/Estrin mix (fit/horner.py): exact ideal value, intervals and rounding bound checked
exhaustively over every port value, depth below Horner's, split choice."""
import itertools

import numpy as np
import pytest

from helpers import TINY_INPUTS, check_exhaustively, tiny_ideal_vars, tiny_lowered_plan, tiny_vars
from ikseries.fit.horner import choose_split, estrin, horner, lower_poly, parity_split, poly_degrees
from ikseries.fit.plan import PlanBuilder, PlanOutput


def random_poly(seed, nvars, degree, parity=None, odd_only=False):
    """Random total-degree polynomial (some terms dropped); with ``odd_only`` variable
    ``parity`` has only odd powers."""
    rng = np.random.default_rng(seed)
    poly = {e: float(rng.normal() * 50) for e in itertools.product(range(degree + 1), repeat=nvars)
            if sum(e) <= degree and rng.random() < 0.8}
    if odd_only:
        poly = {e: c for e, c in poly.items() if e[parity] % 2} or {(0,) * parity + (1,) + (0,) * (nvars - parity - 1): 1.0}
    return poly or {(0,) * nvars: 1.0}


CASES = [  # (vars, total degree, parity variable, odd powers only, split)
    (1, 6, None, False, 1), (1, 6, None, False, 2), (1, 7, None, False, 3), (1, 5, 0, False, 1),
    (2, 4, None, False, 1), (2, 5, None, False, (2, 1)), (2, 5, 1, True, (1, None)), (2, 4, 0, False, 2),
    (3, 3, None, False, 1), (3, 4, 1, False, (1, 2, 1)), (3, 4, 2, True, (None, 1, None)),
]


@pytest.mark.parametrize("case", CASES, ids=str)
@pytest.mark.parametrize("guard", [0, 3])
def test_estrin_is_the_float_polynomial_and_its_bound_holds_exhaustively(case, guard):
    nvars, degree, parity, odd_only, split = case
    poly = random_poly(degree * 10 + nvars, nvars, degree, parity, odd_only)
    plan = tiny_lowered_plan(lambda b, vs: estrin(b, poly, vs, 5, split=split, parity=parity, guard=guard), nvars)

    def want(ports):
        v = tiny_ideal_vars(ports, nvars)
        return sum(c * np.prod([x ** k for x, k in zip(v, e)], axis=0) for e, c in poly.items())
    check_exhaustively(plan, want)


def test_estrin_without_split_is_horner():
    poly = random_poly(3, 2, 5)
    h = tiny_lowered_plan(lambda b, vs: horner(b, poly, vs, 5))
    e = tiny_lowered_plan(lambda b, vs: estrin(b, poly, vs, 5, split=None))
    big = tiny_lowered_plan(lambda b, vs: estrin(b, poly, vs, 5, split=9))   # blocks longer than the degree
    assert e.dumps() == h.dumps() == big.dumps()


@pytest.mark.parametrize("nvars,degree", [(1, 5), (1, 8), (2, 5), (3, 5)])
def test_estrin_is_shallower_than_horner(nvars, degree):
    poly = random_poly(nvars, nvars, degree)
    poly[(degree,) + (0,) * (nvars - 1)] = 1.5   # degree reached in the outer variable
    h = tiny_lowered_plan(lambda b, vs: horner(b, poly, vs, 5), nvars)
    e = tiny_lowered_plan(lambda b, vs: estrin(b, poly, vs, 5, split=1), nvars)
    auto = tiny_lowered_plan(lambda b, vs: lower_poly(b, poly, vs, 5), nvars)
    assert auto.depth <= min(e.depth, h.depth)
    if nvars < 3:
        assert e.depth < h.depth and e.count("mul") > h.count("mul")
    # 3 variables of total degree 5, all ready together: nesting Estrin per variable adds
    # up to Horner's 2 stages per degree (a known limit of the per-variable split)


def test_piecewise_coefficient_tables_through_estrin():
    """Per-cell coefficients (lut, as tiny_piecewise_plan) with the mix: the float polynomial
    of each cell, intervals and bound hold, shallower than Horner."""
    rng = np.random.default_rng(4)
    poly = {(i, j): tuple(float(v) for v in rng.normal(size=4) * 50)
            for i in range(6) for j in range(3) if i + j <= 5}
    plans = {}
    for name, split in (("horner", None), ("estrin", 1)):
        b = PlanBuilder(TINY_INPUTS[:2])
        cell, off = b.cell(b.input_nodes["a"], 2)
        t = b.add(b.reinterpret(off, 1), b.const(-1.0, 1))    # offset in the cell, in [-1, 0.5]
        bn = b.reinterpret(b.input_nodes["b"], 5)
        acc = estrin(b, poly, [t, bn], 5, lambda v, f, b=b, cell=cell: b.lut(cell, v, f), split=split)
        out = b.clamp(b.round(acc, 0), -100, 100)
        plans[name] = b.build([PlanOutput("y", out, acc, "ticks", 1.0)])

    def want(ports):
        a = np.clip(ports["a"], 0, 12)
        cell, tt = a >> 2, ((a & 3) - 2) / 2
        bb = np.clip(ports["b"], -10, 9) / 2 / 16
        return sum(np.asarray(c)[cell] * tt ** i * bb ** j for (i, j), c in poly.items())
    for plan in plans.values():
        assert plan.count("lut") > 0
        check_exhaustively(plan, want)
    assert plans["estrin"].depth < plans["horner"].depth


def test_choose_split_least_depth_then_fewest_multipliers_within_an_allowance():
    poly = random_poly(5, 2, 6)
    poly[(6, 0)] = 2.0
    b = PlanBuilder(TINY_INPUTS[:2])
    vs = tiny_vars(b, 2)
    n = len(b.nodes)

    def lower(split):
        return estrin(b, poly, vs, 5, split=split)
    degrees = poly_degrees(poly)
    _, stage, muls = choose_split(b, lower, degrees)
    assert len(b.nodes) == n   # trials leave nothing behind
    rows = []
    for s in itertools.product(*[(None, *range(1, d + 1)) for d in degrees]):
        with b.trial():
            node = lower(s)
            rows.append((b.stages()[node], sum(1 for x in b.nodes[n:] if x.op == "mul")))
    assert (stage, muls) == min(rows)
    horner_stage, horner_muls = rows[0]
    assert stage < horner_stage
    assert choose_split(b, lower, degrees, max_extra_muls=0)[2] == horner_muls
    for extra in range(muls - horner_muls + 1):
        s, st, m = choose_split(b, lower, degrees, max_extra_muls=extra)
        assert m - horner_muls <= extra
        assert st == min(r[0] for r in rows if r[1] - horner_muls <= extra)
    assert poly_degrees({(1, 3): 1.0, (4, 1): 2.0}, parity=1) == (4, 1)


def _parity_horner(b, poly, vs, k, frac):
    """``E(v**2) + v * O(v**2)`` with nested Horner (the fitter's lowering before the mix)."""
    v2 = b.mul(vs[k], vs[k], b.frac(vs[k]))
    even, odd = parity_split(poly, k)
    vars_ = vs[:k] + [v2] + vs[k + 1:]
    acc = horner(b, even, vars_, frac) if even else None
    if odd:
        o = b.mul(vs[k], horner(b, odd, vars_, frac), frac)
        acc = o if acc is None else b.add(acc, o)
    return acc


def test_estrin_parity_without_split_is_the_fitters_lowering():
    """``estrin(parity=k)`` builds exactly the ``E(v**2) + v * O(v**2)`` Horner nodes."""
    poly = random_poly(7, 2, 5)
    fitter_plan = tiny_lowered_plan(lambda b, vs: _parity_horner(b, poly, vs, 1, 5))
    ours = tiny_lowered_plan(lambda b, vs: estrin(b, poly, vs, 5, parity=1))
    assert ours.dumps() == fitter_plan.dumps()
