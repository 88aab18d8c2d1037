"""Certified bounds of plans that cut a computed, rounded value (a feature) into table cells."""

import numpy as np
import pytest
from helpers import toy_robot

from ikseries.fit.certify import CertificationError, certify
from ikseries.fit.cut import feature_cuts
from ikseries.fit.horner import horner
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.sim.golden import evaluate, evaluate_ideal

CELL = 1 / 8    # table cell of the feature u, in its units


class _FeatureGeometry:
    """Reference 'angle' sin(u) with the feature u = a + b**2 / 4."""
    inputs = ("a", "b")
    servos = ("y",)

    def angles(self, xp, a, b):
        return (xp.sin(a + 0.25 * (b * b)),)


def _robot(tolerance=0.5):
    return toy_robot(_FeatureGeometry(), tolerance)


def _plan(ufrac=8, wrong=None, degree=2):
    """P(a, b) = p_m(t) on a in [0, 1], b in [-1, 1] (6 fractional bits each): the feature
    u = a + b**2 / 4 rounded half up to ``ufrac`` fractional bits, cut into table cells of
    width CELL, cell m, offset t in the cell, p_m the least-squares polynomial of sin over the
    cell (fitted a little beyond both ends); in cell ``wrong`` the constant term is 0.5 too
    large."""
    inputs = [PlanInput("a", "mm", 6, 0, 64, 7, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    a_n, b_n = b.input_nodes["a"], b.input_nodes["b"]
    quarter = b.round(b.reinterpret(b.mul(b_n, b_n), 14), ufrac)
    u = b.add(b.align(a_n, ufrac), quarter)
    cell, t = b.cell(u, ufrac - 3)
    s = np.linspace(-CELL / 8, CELL * 9 / 8, 41)
    coef = np.array([np.polynomial.polynomial.polyfit(s, np.sin(m * CELL + s), degree)
                     for m in range(b.nodes[cell].hi + 1)])
    if wrong is not None:
        coef[wrong, 0] += 0.5
    poly = {(e,): tuple(coef[:, e]) for e in range(degree + 1)}
    acc = horner(b, poly, [t], 20, lambda v, f: b.lut(cell, v, f))
    return b.build([PlanOutput("y", b.clamp(b.round(acc, 0), -10, 10), acc, "ticks", 1.0)])


def _errors(plan):
    """max |P - f| over every port value, of the ideal plan and of the integer accumulator."""
    a, bb = np.meshgrid(np.arange(0, 65), np.arange(-64, 65), indexing="ij")
    ports = {"a": a.ravel(), "b": bb.ravel()}
    acc = plan.outputs[0].preround
    f = np.sin(ports["a"] / 64 + 0.25 * (ports["b"] / 64) ** 2)
    ideal = evaluate_ideal(plan, ports, keep=[acc])[acc]
    hw = evaluate(plan, ports, keep=[acc])[acc] * 2.0 ** -plan.nodes[acc].frac
    return np.abs(ideal - f).max(), np.abs(hw - f).max()


def test_the_feature_cut_is_found_and_its_rounding_counted():
    plan = _plan()
    u = next(n.args[0] for n in plan.nodes if n.op == "index")
    assert feature_cuts(plan.nodes, range(len(plan.nodes))) == ((u, 5),)
    quant = plan.rounding_bounds()
    mask = next(i for i, n in enumerate(plan.nodes) if n.op == "mask")
    assert 0 < quant[u] == quant[mask] < 2.0 ** -8          # a floor to 8 bits (the half is ideal too)
    assert np.isfinite(quant[plan.outputs[0].preround])


@pytest.mark.parametrize("ufrac", [8, 10])
def test_a_feature_cut_is_certified_and_the_bound_holds_at_every_port(ufrac):
    """The feature's cell edges are curves across the certifier's cells: each cell's bound is
    its worst case's, the refinement converges, and the certified approximation plus rounding
    covers the integer plan's error at every port value."""
    plan = _plan(ufrac)
    ideal, hw = _errors(plan)
    s = certify(_robot(), plan, target_pu=1.5 * ideal + 1e-4).servos[0]
    assert s.converged and np.isfinite(s.approximation_pu)
    assert ideal <= s.approximation_pu <= 1.5 * ideal + 1e-4
    assert hw <= s.approximation_pu + s.rounding_pu


@pytest.mark.parametrize("wrong", [0, 4, 10])
def test_a_wrong_entry_of_a_feature_table_is_refused(wrong):
    """Cell 10 holds u = 1.25 only (a = 1, b = +-1): a corner."""
    bad = certify(_robot(tolerance=1.0), _plan(wrong=wrong))
    with pytest.raises(CertificationError, match=r"servo y: certified error"):
        bad.check(1.0)
    assert bad.servos[0].approximation_pu >= 0.49


def test_the_cases_reach_every_cell_the_rounded_feature_can_take():
    """A certifier cell whose ideal feature stays in cell 3 but comes within one rounding step
    of cell 4 has both cases (the hardware's rounded feature may be in either); one in the
    middle of cell 3 has one; one spanning more than MAX_CASES cells has no bound."""
    from ikseries.fit import centred as cn
    from ikseries.fit.certify import MAX_CASES, _error_function
    plan = _plan(ufrac=6)
    err = _error_function(plan, _robot(), 0)
    step = 2.0 ** -6
    # b = 0: u = a + half a step (the ideal of a round half up holds its half): cell 3 up to
    # a = 1/2 - step / 2, so a <= 1/2 - step keeps u a half step below the edge
    lo = np.array([[0.5 - 3 * step, 0.0], [0.5 - 3 * step, 0.0], [0.0, -1.0]])
    hi = np.array([[0.5 - step, 0.0], [0.5 - 2 * step, 0.0], [1.0, 1.0]])
    u = next(i for i, n in enumerate(plan.nodes) if n.op == "index")
    assert plan.rounding_bounds()[plan.nodes[u].args[0]] > step / 2
    rows, force, wild = err.cases(dict(zip("ab", cn.variables(lo, hi))), 3)
    cells = next(iter(force.values()))
    assert rows.tolist() == [0, 0, 1, 2] and cells[:3].tolist() == [3, 4, 3]
    assert wild.tolist() == [False, False, True] and MAX_CASES < 11


def test_a_port_cut_through_a_floor_is_split_into_cases_too():
    """A cut of an input narrowed by a floor shift is a cut chain of that input, but its
    rounding lets the hardware take the neighbour cell: it is a case split as well."""
    inputs = [PlanInput("a", "mm", 6, 0, 64, 7, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    narrow = b.align(b.input_nodes["a"], 4)                    # floor to 4 fractional bits
    cell, t = b.cell(narrow, 2)
    acc = b.add(b.lut(cell, tuple(float(m) for m in range(5)), 4), t)
    plan = b.build([PlanOutput("y", b.round(acc, 0), acc, "ticks", 1.0)])
    quant = plan.rounding_bounds()
    narrow = next(n.args[0] for n in plan.nodes if n.op == "index")
    assert plan.nodes[narrow].op == "shr" and quant[narrow] > 0
    assert feature_cuts(plan.nodes, range(len(plan.nodes))) == ()
    assert feature_cuts(plan.nodes, range(len(plan.nodes)), quant) == ((narrow, 2),)
