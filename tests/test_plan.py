"""Evaluation plan: interval analysis, certified rounding bound, serialisation."""
import itertools
import json

import numpy as np
import pytest

from helpers import all_ports, check_exhaustively, grid_reference, tiny_grid_plan, tiny_piecewise_plan, tiny_plan
from ikseries.fit.horner import parity_split
from ikseries.fit.certify import output_rounding
from ikseries.fit.plan import Plan, PlanBuilder, PlanInput, PlanOutput, bits_for
from ikseries.sim import golden


@pytest.mark.parametrize("seed", range(5))
def test_every_node_stays_in_its_interval_for_every_port_value(seed):
    plan = tiny_plan(seed)
    vals = golden.evaluate(plan, all_ports(plan))
    for k, n in enumerate(plan.nodes):
        v = np.asarray(vals[k])
        assert v.min() >= n.lo and v.max() <= n.hi, (k, n.op)


@pytest.mark.parametrize("seed", range(5))
def test_rounding_bound_holds_exhaustively(seed):
    plan = tiny_plan(seed)
    ports = all_ports(plan)
    iv, fv = golden.evaluate(plan, ports), golden.evaluate_ideal(plan, ports)
    bound = plan.rounding_bounds()
    pre = plan.outputs[0].preround
    for k in plan.cone(pre):
        err = np.abs(np.asarray(iv[k]) * 2.0 ** -plan.nodes[k].frac - fv[k])
        assert err.max() <= bound[k] * (1 + 1e-12) + 1e-12, (k, plan.nodes[k].op)


def test_ideal_evaluation_is_the_float_polynomial():
    plan = tiny_plan(1)
    ports = all_ports(plan)
    a = np.clip(ports["a"], 0, 12) / 4 / 4
    bb = np.clip(ports["b"], -10, 9) / 2 / 16
    rng = np.random.default_rng(1)
    poly = {(i, j): float(rng.normal() * 50) for i in range(4) for j in range(3) if i + j <= 4}
    want = sum(c * a ** i * bb ** j for (i, j), c in poly.items())
    got = golden.evaluate_ideal(plan, ports)[plan.outputs[0].preround]
    assert np.allclose(got, want, rtol=0, atol=1e-9)


def test_json_round_trip_and_tamper_detection():
    plan = tiny_plan(2)
    text = plan.dumps()
    again = Plan.from_json(json.loads(text))
    assert again.dumps() == text
    d = json.loads(text)
    d["nodes"][-1]["hi"] += 1
    with pytest.raises(ValueError, match="does not match the recomputed"):
        Plan.from_json(d)
    d = json.loads(text)
    d["version"] = 99
    with pytest.raises(ValueError, match="plan version must be one of 1, 2, not 99"):
        Plan.from_json(d)


def test_bits_for():
    assert bits_for(0, 0) == (1, False)
    assert bits_for(0, 255) == (8, False)
    assert bits_for(-128, 127) == (8, True)
    assert bits_for(-129, 0) == (9, True)
    assert bits_for(-1, 128) == (9, True)
    for lo, hi in itertools.product(range(-70, 70, 7), repeat=2):
        if lo <= hi:
            w, s = bits_for(lo, hi)
            rng = (-(1 << (w - 1)), (1 << (w - 1)) - 1) if s else (0, (1 << w) - 1)
            assert rng[0] <= lo and hi <= rng[1]
            w2 = w - 1
            if w2 >= 1:
                rng2 = (-(1 << (w2 - 1)), (1 << (w2 - 1)) - 1) if s else (0, (1 << w2) - 1)
                assert not (rng2[0] <= lo and hi <= rng2[1])


def test_parity_split():
    poly = {(1, 0, 0): 1.0, (0, 1, 2): 2.0, (2, 2, 0): 3.0, (0, 3, 0): 4.0}
    even, odd = parity_split(poly, 1)
    assert even == {(1, 0, 0): 1.0, (2, 1, 0): 3.0}
    assert odd == {(0, 0, 2): 2.0, (0, 1, 0): 4.0}


def test_input_outside_its_port_is_rejected():
    plan = tiny_plan(0)
    with pytest.raises(ValueError, match="input a must fit its 4-bit port"):
        golden.evaluate(plan, {"a": np.array([16]), "b": np.array([0])})


def test_rounding_bound_scales_with_a_binary_point_change():
    """Reinterpreting a value to fewer fractional bits multiplies its real error, to more
    bits divides it; the bound must follow both ways (exhaustively checked)."""
    inputs = [PlanInput("a", "mm", 0, 0, 63, 6, False)]
    b = PlanBuilder(inputs)
    a = b.reinterpret(b.input_nodes["a"], 6)             # a / 64
    p = b.mul(a, b.const(0.3, 7), 6)                     # rounded const, truncated product
    up = b.reinterpret(p, 2)                             # x 16: error x 16
    down = b.reinterpret(p, 10)                          # / 16
    plan = b.build([PlanOutput("u", up, up, "ticks", 1.0), PlanOutput("d", down, down, "ticks", 1.0)])
    ports = all_ports(plan)
    iv, fv = golden.evaluate(plan, ports), golden.evaluate_ideal(plan, ports)
    bound = plan.rounding_bounds()
    for o in plan.outputs:
        k = o.node
        err = np.abs(np.asarray(iv[k]) * 2.0 ** -plan.nodes[k].frac - fv[k]).max()
        assert err <= bound[k] * (1 + 1e-12)
        assert bound[k] <= 4 * err   # and not wildly pessimistic
    assert bound[plan.outputs[0].node] == 256 * bound[plan.outputs[1].node]


def test_constants_added_in_turn_are_one_adder():
    """``(x + c1) + c2`` and ``c2 + (c1 + x)`` are built as ``x + (c1 + c2)``: one adder, one
    stage, the same integers and ideal values; rounded constants keep their ideal sum, and
    constants summing to 0 leave ``x`` itself."""
    inputs = [PlanInput("a", "mm", 0, 0, 63, 6, False)]
    b = PlanBuilder(inputs)
    a = b.reinterpret(b.input_nodes["a"], 6)
    x = b.mul(a, a)                                       # 12 fractional bits
    one = b.add(b.add(x, b.const(0.3, 12)), b.const(-1.7, 12))
    other = b.add(b.const(1.25, 6), b.add(b.const(0.5, 12), x))   # a constant aligned first
    assert b.add(b.add(x, b.const(0.75, 12)), b.const(-0.75, 12)) == x
    plan = b.build([PlanOutput("one", one, one, "ticks", 1.0), PlanOutput("other", other, other, "ticks", 1.0)])
    assert plan.count("add") == 2 and plan.depth == plan.stages()[x] + 1
    for o, c in (("one", 0.3 - 1.7), ("other", 1.75)):
        n = plan.nodes[plan.outputs[[p.name for p in plan.outputs].index(o)].node]
        k = n.args[1] if plan.nodes[n.args[1]].op == "const" else n.args[0]
        assert abs((plan.nodes[k].ideal if plan.nodes[k].ideal is not None else plan.nodes[k].param / 4096) - c) < 1e-15
    check_exhaustively(plan, want=lambda ports: ports["a"].astype(float) ** 2 / 4096 + 0.3 - 1.7)


def test_a_term_ready_last_is_added_last():
    """``(a + p) + q``, with the product ``p`` of ``a`` ready after ``a`` and ``q``, is built as
    ``(a + q) + p``: one stage fewer, as many adders, the same integers and rounding bound."""
    inputs = [PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("b", "mm", 0, -8, 7, 4, True)]
    b = PlanBuilder(inputs)
    a, q = b.input_nodes["a"], b.input_nodes["b"]
    p = b.mul(b.mul(a, a), a)                            # stage 3
    total = b.add(b.add(a, p), q)
    plan = b.build([PlanOutput("t", total, total, "ticks", 1.0)])
    assert plan.count("add") == 2 and plan.depth == plan.stages()[plan.outputs[0].node] == 4
    assert plan.nodes[plan.outputs[0].node].op == "add"
    check_exhaustively(plan, want=lambda ports: ports["a"] + ports["a"] ** 3 + ports["b"])


def test_a_constant_after_a_shift_joins_the_sum_under_it():
    """``((a**2 + c1) >> s) + c2`` is built as ``(a**2 + (c1 + c2 * 2**s)) >> s``: one adder, the
    same integers (floor commutes with adding a multiple of 2**s)."""
    inputs = [PlanInput("a", "mm", 0, -40, 63, 7, True)]
    b = PlanBuilder(inputs)
    a = b.input_nodes["a"]
    y = b.add(b.mul(a, a), b.const(-3.0, 0))
    z = b.add(b.reinterpret(b.align(y, -4), 2), b.const(0.75, 2))    # (y >> 4) / 4 + 3/4
    plan = b.build([PlanOutput("z", z, z, "ticks", 1.0)])
    assert plan.count("add") == 1 and plan.nodes[plan.outputs[0].node].op != "add"
    ports = all_ports(plan)
    want = ((np.clip(ports["a"], -40, 63).astype(np.int64) ** 2 - 3) >> 4) + 3   # the port clamped
    assert np.array_equal(golden.evaluate(plan, ports)[plan.outputs[0].node], want)
    check_exhaustively(plan)


def test_the_rounding_half_joins_a_term_ready_before_the_last_product():
    """``round(a + p)``, ``p`` a product: the half is added to ``a`` while ``p`` is computed, so
    the output is one stage after ``p``; the accumulator ``a + p`` stays in the plan for the
    certifier only (not :meth:`Plan.live`), and the output is its rounding, bit for bit."""
    inputs = [PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("b", "mm", 0, -8, 7, 4, True)]
    b = PlanBuilder(inputs)
    a, q = (b.reinterpret(b.input_nodes[k], 2) for k in "ab")
    p = b.mul(q, q)
    acc = b.add(b.align(a, 4), p)
    out = b.round(acc, 0)
    plan = b.build([PlanOutput("y", out, acc, "ticks", 1.0)])
    o = plan.outputs[0]
    assert o.preround not in plan.live() and plan.count("add") == 2
    assert plan.depth == plan.stages()[o.preround] == 3     # input 1, product 2, sum 3: no 4th
    iv = golden.evaluate(plan, all_ports(plan))
    assert np.array_equal(iv[o.node], (np.asarray(iv[o.preround]) + 8) >> 4)
    assert output_rounding(plan, 0) == (0.5, None)


def test_the_rounding_half_is_stored_in_a_table_of_the_sum():
    """``round(p + (q + lut(i)))``: the half joins the table's entries (``lut'(i) = lut(i) +
    half``), the additions above it rebuilt, so no constant is added in hardware; the
    accumulator keeps the original table for the certifier, which sees the output as the
    accumulator plus the half, bit for bit."""
    inputs = [PlanInput("a", "mm", 0, 0, 15, 4, False), PlanInput("b", "mm", 0, -8, 7, 4, True)]
    b = PlanBuilder(inputs)
    a, q = (b.reinterpret(b.input_nodes[k], 2) for k in "ab")
    cell, _ = b.cell(b.input_nodes["a"], 2)
    table = b.lut(cell, [0.3, -1.1, 2.0, 0.7], 4)           # rounded: ideal values kept
    acc = b.add(b.mul(q, q), b.add(b.align(a, 4), table))
    out = b.round(acc, 0)
    plan = b.build([PlanOutput("y", out, acc, "ticks", 1.0)])
    live = plan.live()
    assert not any(plan.nodes[i].op == "const" for i in live)
    (new,) = [i for i in live if plan.nodes[i].op == "lut"]
    o = plan.outputs[0]
    (orig,) = [i for i in plan.cone(o.preround) if plan.nodes[i].op == "lut"]
    assert orig not in live and orig != new
    assert plan.nodes[new].param == tuple(v + 8 for v in plan.nodes[orig].param)
    assert plan.nodes[new].ideal == tuple(v + 0.5 for v in plan.nodes[orig].ideal)
    iv = golden.evaluate(plan, all_ports(plan))
    assert np.array_equal(iv[o.node], (np.asarray(iv[o.preround]) + 8) >> 4)
    assert output_rounding(plan, 0) == (0.5, None)
    check_exhaustively(plan)


@pytest.mark.parametrize("seed", range(3))
def test_piecewise_plan_intervals_and_rounding_bound_hold_exhaustively(seed):
    plan = tiny_piecewise_plan(seed)
    assert plan.count("lut") > 0 and plan.count("index") == 1 and plan.count("mask") == 1
    check_exhaustively(plan)


def test_piecewise_plan_is_the_float_polynomial_of_each_cell():
    plan = tiny_piecewise_plan(4, shift=2, degree=2)
    ports = all_ports(plan)
    a = np.clip(ports["a"], 0, 12)
    cell, t = a >> 2, ((a & 3) - 2) / 2
    bb = np.clip(ports["b"], -10, 9) / 2 / 16
    rng = np.random.default_rng(4)
    poly = {(i, j): rng.normal(size=4) * 50 for i in range(3) for j in range(3) if i + j <= 2}
    want = sum(c[cell] * t ** i * bb ** j for (i, j), c in poly.items())
    got = golden.evaluate_ideal(plan, ports)[plan.outputs[0].preround]
    assert np.allclose(got, want, rtol=0, atol=1e-9)
    assert Plan.from_json(json.loads(plan.dumps())).dumps() == plan.dumps()


@pytest.mark.parametrize("seed, shifts", [(0, (2, 2)), (1, (1, 3)), (2, (3, 1))])
def test_grid_plan_is_the_float_polynomial_of_each_cell(seed, shifts):
    """A two-port grid: at every port value (every cell corner and edge, out-of-range values
    clamped) the ideal value is the float polynomial of cell (i, j) in both offsets; the
    intervals and rounding bound hold; the table address is i * 2**bits + j with no product,
    and the JSON form round-trips."""
    plan, grid, poly = tiny_grid_plan(seed, shifts)
    assert plan.count("index") == 2 and plan.count("mask") == 2 and plan.count("mul") <= 2 * len(poly)
    ports = all_ports(plan)
    got = golden.evaluate_ideal(plan, ports)[plan.outputs[0].preround]
    assert np.allclose(got, grid_reference(grid, poly, ports), rtol=0, atol=1e-9)
    check_exhaustively(plan)
    assert Plan.from_json(json.loads(plan.dumps())).dumps() == plan.dumps()


def test_grid_table_pads_each_row_with_its_last_entry():
    from ikseries.fit.features import Cut, CutGrid
    grid = CutGrid(Cut(0, "a", 2, 3), Cut(None, "b", 2, 3))
    assert (grid.cells, grid.bits, grid.entries) == (9, 2, 11)
    assert grid.table(range(9)) == (0, 1, 2, 2, 3, 4, 5, 5, 6, 7, 8)
    assert CutGrid(Cut(0, "a", 2, 2), Cut(1, "b", 1, 4)).table(range(8)) == tuple(range(8))
    with pytest.raises(ValueError, match="a cut grid needs two ports, not 'a' twice"):
        CutGrid(Cut(0, "a", 2, 3), Cut(1, "a", 1, 3))


def test_lut_and_cell_operations_check_their_operands():
    b = PlanBuilder([PlanInput("a", "mm", 2, 0, 12, 4, False)])
    a = b.input_nodes["a"]
    cell, off = b.cell(a, 2)
    assert (b.nodes[cell].lo, b.nodes[cell].hi) == (0, 3) and (b.nodes[off].lo, b.nodes[off].hi) == (0, 3)
    with pytest.raises(ValueError, match=r"lut index must be an integer in \[0, 2\], not \[0, 3\]"):
        b.lut(cell, [1.0, 2.0, 3.0], 0)
    with pytest.raises(ValueError, match="lut table must be a non-empty tuple of integers"):
        b._append("lut", (cell,), 0, (), None)
    lut = b.lut(cell, [0.5, 1.0, -2.0, 0.25], 1)
    assert (b.nodes[lut].lo, b.nodes[lut].hi) == (-4, 2)
    assert b.nodes[lut].ideal == (0.5, 1.0, -2.0, 0.25)


# -- products narrowed to DSP operands (PlanBuilder(operand_bits=...)) --------------------------

def _operand_widths(plan):
    def sw(n):
        w, s = bits_for(n.lo, n.hi)
        return w if s else w + 1
    return [tuple(sw(plan.nodes[a]) for a in n.args) for n in plan.nodes if n.op == "mul"]


@pytest.mark.parametrize("make", [tiny_plan, tiny_piecewise_plan])
@pytest.mark.parametrize("cap", [(7, 7), (9, 6)])
def test_operand_bits_cap_every_product_and_the_rounding_bound_still_holds(make, cap):
    plan = make(1, operand_bits=cap)
    exact = make(1)
    assert any(max(w) > max(cap) for w in _operand_widths(exact))   # the cap has work to do
    for wa, wb in _operand_widths(plan):
        lo, hi = sorted((wa, wb))
        assert lo <= min(cap) and hi <= max(cap), (wa, wb)
    ports = all_ports(plan)
    iv, fv = golden.evaluate(plan, ports), golden.evaluate_ideal(plan, ports)
    bound = plan.rounding_bounds()
    for k in plan.cone(plan.outputs[0].preround):
        v = np.asarray(iv[k])
        assert v.min() >= plan.nodes[k].lo and v.max() <= plan.nodes[k].hi, k
        err = np.abs(v * 2.0 ** -plan.nodes[k].frac - fv[k])
        assert err.max() <= bound[k] * (1 + 1e-12) + 1e-12, (k, plan.nodes[k].op)
    # the ideal function is the same polynomial: narrowing only rounds
    assert np.allclose(golden.evaluate_ideal(exact, ports)[exact.outputs[0].preround],
                       fv[plan.outputs[0].preround], rtol=0, atol=1e-9)


def test_operand_bits_round_constants_and_tables_again_from_their_ideal_values():
    b = PlanBuilder([PlanInput("a", "mm", 0, -100, 100, 8, True)], operand_bits=(8, 8))
    x = b.input_nodes["a"]
    k = b.const(1234.56789, 4)                              # 16 signed bits
    p = b.mul(k, x)
    n = b.nodes[b.nodes[p].args[0]]
    assert n.op == "const" and n.ideal == 1234.56789 and n.param == round(1234.56789 * 2 ** n.frac)
    assert b.signed_width(b.nodes[p].args[0]) == 8
    cell, off = b.cell(b.input_nodes["a"], 6)               # cells -2..1
    t = b.lut(b.add(cell, b.const(2, 0)), [1000.25, -999.5, 3.0, 0.125], 2)
    q = b.mul(t, off)
    n = b.nodes[b.nodes[q].args[0]]
    assert n.op == "lut" and n.ideal == (1000.25, -999.5, 3.0, 0.125) and b.signed_width(b.nodes[q].args[0]) <= 8
    sq = b.mul(b.const(77.0, 0), b.const(77.0, 0))         # equal operands stay one node
    assert b.nodes[sq].args[0] == b.nodes[sq].args[1]


def test_operand_bits_give_the_wider_port_to_the_wider_operand():
    b = PlanBuilder([PlanInput("a", "mm", 0, -2 ** 22, 2 ** 22 - 1, 23, True),
                     PlanInput("c", "mm", 0, -2 ** 19, 2 ** 19 - 1, 20, True)], operand_bits=(25, 18))
    p = b.mul(b.input_nodes["c"], b.input_nodes["a"])
    assert [b.signed_width(a) for a in b.nodes[p].args] == [18, 23]


@pytest.mark.parametrize("bad", [(18,), (18, 1), "18x18", (18.0, 18), (True, 18)])
def test_operand_bits_must_be_a_pair_of_widths(bad):
    with pytest.raises(ValueError, match=r"operand_bits must be None or a pair of signed widths >= 2 "
                                         r"such as \(18, 18\), not "):
        PlanBuilder([], operand_bits=bad)


def test_operand_bits_clamp_the_narrowed_value_when_the_bounds_allow():
    """floor(clamp(x, L, H) / 2**s) == clamp(floor(x / 2**s), L / 2**s, H / 2**s) when 2**s
    divides L and H: the narrow clamp is used (exhaustively equal to the wide one)."""
    inputs = [PlanInput("a", "mm", 0, -3000, 3000, 13, True)]
    wide = PlanBuilder(inputs)
    x = wide.add(wide.input_nodes["a"], wide.const(7, 0))
    c = wide.clamp(x, -2048, 2048)
    ref = wide.build([PlanOutput("y", wide.align(c, -2), c, "ticks", 1.0)])
    nb = PlanBuilder(inputs, operand_bits=(11, 11))
    x = nb.add(nb.input_nodes["a"], nb.const(7, 0))
    p = nb.mul(nb.clamp(x, -2048, 2048), nb.const(3.0, 0))
    op = nb.nodes[nb.nodes[p].args[0]]
    assert op.op == "clamp" and op.param == (-512, 512) and nb.signed_width(nb.nodes[p].args[0]) <= 11
    plan = nb.build([PlanOutput("y", nb.nodes[p].args[0], nb.nodes[p].args[0], "ticks", 1.0)])
    ports = all_ports(plan)
    assert np.array_equal(golden.outputs(plan, ports)["y"], golden.outputs(ref, ports)["y"])
