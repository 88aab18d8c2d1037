"""Certified error bound over the continuous workspace box."""
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import toy_robot

from ikseries.accuracy import measure, verification_points
from ikseries.fit import centred as cn
from ikseries.fit import interval as ia
from ikseries.fit.certify import (MISS_GRID, CertificationError, _initial_cells, _plan_function, _table_edges,
                                  certify, output_rounding)
from ikseries.fit.horner import horner
from ikseries.fit.plan import Plan, PlanBuilder, PlanInput, PlanOutput
from ikseries.robot import load_preset
from ikseries.sim.golden import evaluate_ideal

SIN1 = 1.0 - np.sin(1.0)   # sup over a in [0, 1] of |a - sin(a)|


class _SineGeometry:
    """Reference 'angle' sin(a) + b**2 over the math namespace, like Geometry.angles."""
    inputs = ("a", "b")
    servos = ("y",)

    def angles(self, xp, a, b):
        return (xp.sin(a) + b * b,)


def _robot(tolerance=0.5):
    return toy_robot(_SineGeometry(), tolerance)


def _plan(offset=0.0, floor_only=False, clamp=(-10, 10)):
    """P(a, b) = a + b**2 + offset on a in [0, 1], b in [-1, 1]: |P - f| = |a - sin a + offset|."""
    inputs = [PlanInput("a", "mm", 6, 0, 64, 7, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    a_n, b_n = b.input_nodes["a"], b.input_nodes["b"]
    acc = b.add(b.align(b.add(a_n, b.const(offset, 6)), 12), b.mul(b_n, b_n))
    out = b.align(acc, 0) if floor_only else b.clamp(b.round(acc, 0), *clamp)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


CELL = 1 / 8   # table cell of the piecewise plans, in units of input a


def _piecewise_plan(frac=6, offset=0.0, top=None, degree=1, wrong=None):
    """P(a, b) = p_m(t) + b**2 on a in [0, 1] (``frac`` bits), b in [-1, 1]: a + ``offset``
    (clamped to at most ``top`` if given) cut into table cells of width CELL, cell m, offset t in
    the cell, p_m the least-squares polynomial of sin over the cell, its coefficients looked up
    by cell; in cell ``wrong`` the constant term is 0.75 too large."""
    inputs = [PlanInput("a", "mm", frac, 0, 1 << frac, frac + 1, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    a_n, b_n = b.input_nodes["a"], b.input_nodes["b"]
    arg = b.add(a_n, b.const(offset, frac)) if offset else a_n
    if top is not None:
        arg = b.clamp(arg, 0, int(top * 2 ** frac))
    cell, t = b.cell(arg, frac - 3)
    s = np.linspace(0.0, CELL, 33)
    coef = np.array([np.polynomial.polynomial.polyfit(s, np.sin(m * CELL - offset + s), degree)
                     for m in range(b.nodes[cell].hi + 1)])
    if wrong is not None:
        coef[wrong, 0] += 0.75
    poly = {(e,): tuple(coef[:, e]) for e in range(degree + 1)}
    acc = b.add(horner(b, poly, [t], 14, lambda v, f: b.lut(cell, v, f)), b.align(b.mul(b_n, b_n), 14))
    return b.build([PlanOutput("y", b.clamp(b.round(acc, 0), -10, 10), acc, "ticks", 1.0)])


def _sampled_error(plan):
    """max |P - f| over every port value."""
    a, bb = np.meshgrid(np.arange(plan.inputs[0].lo, plan.inputs[0].hi + 1), np.arange(-64, 65), indexing="ij")
    acc = plan.outputs[0].preround
    p = evaluate_ideal(plan, {"a": a.ravel(), "b": bb.ravel()}, keep=[acc])[acc]
    return np.abs(p - np.sin(a.ravel() * 2.0 ** -plan.inputs[0].frac) - (bb.ravel() / 64) ** 2).max()


@pytest.mark.parametrize("offset", [0.0, 1 / 16])
def test_piecewise_bound_encloses_the_sampled_error_tightly(offset):
    """Every table cell converges: the certifier's cells never straddle a table edge (with
    offset 0 the box's upper end a = 1 is a table cell of its own)."""
    plan = _piecewise_plan(offset=offset)
    sampled = _sampled_error(plan)
    s = certify(_robot(), plan, target_pu=1.03 * sampled).servos[0]
    assert sampled <= s.approximation_pu <= 1.03 * sampled and s.converged and s.evaluated < 200
    assert output_rounding(plan, 0)[0] == 0.5 and s.rounding_pu < 1e-3


def test_piecewise_initial_cells_follow_the_table():
    plan = _piecewise_plan(offset=1 / 16)
    edges, cut = _table_edges(plan, range(len(plan.nodes)), ["a", "b"], [0.0, -1.0], [1.0, 1.0])
    assert cut == [True, False] and not len(edges[1])
    assert edges[0].tolist() == [m / 8 - 1 / 16 for m in range(1, 9)]
    lo, hi = _initial_cells([0.0, -1.0], [1.0, 1.0], [2, 2], edges, cut)
    a_sides = sorted(set(zip(lo[:, 0], hi[:, 0])))
    assert a_sides[0] == (0.0, 1 / 16) and a_sides[-2:] == [(15 / 16, 1.0), (1.0, 1.0)] and len(a_sides) == 11


@pytest.mark.parametrize("offset, wrong", [(1 / 16, 5), (0.0, 8)])
def test_piecewise_plan_with_a_wrong_table_entry_is_refused(offset, wrong):
    """Also the last table cell, which with offset 0 holds the single point a = 1."""
    bad = certify(_robot(tolerance=1.0), _piecewise_plan(offset=offset, wrong=wrong))
    with pytest.raises(CertificationError, match=r"servo y: certified error"):
        bad.check(1.0)
    s = bad.servos[0]
    assert s.approximation_pu >= 0.75
    cell = (wrong * CELL - offset, min(1.0, (wrong + 1) * CELL - offset))
    assert cell[0] <= s.worst["lo"]["a"] <= s.worst["hi"]["a"] <= cell[1]


@pytest.mark.parametrize("offset, top", [(0.0, None), (3 / 64, None), (1 / 16, 0.75)])
def test_piecewise_enclosures_hold_on_random_sub_boxes(offset, top):
    """index, mask, lut and the polynomial enclose their ideal values at every port value of
    random sub-boxes (half-open along a unless degenerate), aligned to the table, straddling it,
    and degenerate; a clamp of the cell argument at a table edge (top) included. A wrong entry
    makes the polynomial jump at the edges of cell 3: a derivative bound across them would miss
    it."""
    plan = _piecewise_plan(frac=10, offset=offset, top=top, degree=2, wrong=3)
    rng = np.random.default_rng(7)
    n = 60
    edges = np.arange(9) * CELL - offset
    edges = edges[(edges > 0) & (edges < 1)]
    lo_a = rng.uniform(0, 0.99, n)
    hi_a = np.minimum(lo_a + rng.uniform(0.005, 0.3, n), 1.0)
    i = rng.integers(0, len(edges) - 1, n // 3)                       # aligned to the table
    lo_a[:n // 3], hi_a[:n // 3] = edges[i], edges[i + 1]
    lo_a[-5:] = hi_a[-5:] = np.append(rng.integers(0, 1025, 4) / 1024, edges[2])  # degenerate
    lo_a[-6], hi_a[-6] = 0.75, 1.0
    b_lo = rng.uniform(-1, 0.8, n)
    b_hi = np.minimum(b_lo + rng.uniform(0.2, 1, n), 1.0)
    lo, hi = np.stack([lo_a, b_lo], 1), np.stack([hi_a, b_hi], 1)
    ports = {"a": np.repeat(np.arange(1025), 33), "b": np.tile(np.arange(-64, 65, 4), 1025)}
    x = ports["a"] / 1024
    y = ports["b"] / 64
    nodes = [k for k, nd in enumerate(plan.nodes) if nd.op in ("index", "mask", "lut")]
    nodes.append(plan.outputs[0].preround)
    ideal = evaluate_ideal(plan, ports, keep=nodes)
    inside = (((x >= lo_a[:, None]) & (x < hi_a[:, None])) | (x == lo_a[:, None])) & (
        (y >= b_lo[:, None]) & (y <= b_hi[:, None]))
    assert inside.any(axis=1).all()
    jumps = 0
    for values in (dict(zip("ab", cn.variables(lo, hi))), dict(zip("ab", ia.variables(lo, hi, order=2)))):
        for k in nodes:
            e = _plan_function(plan, k)(values)
            encl = [e]
            if isinstance(e, cn.Centred):   # and the mean-value form of its derivative bounds
                r = np.sum(np.nan_to_num(e.x.dmag(2), nan=np.inf) * e.h, axis=0)
                encl = [e.x, SimpleNamespace(lo=e.c.lo - r, hi=e.c.hi + r)]
            v = np.broadcast_to(ideal[k], x.shape)
            tol = 1e-12 * (1 + np.abs(v))
            for e in encl:
                held = (e.lo[:, None] <= v + tol) & (v - tol <= e.hi[:, None])
                assert np.all(~inside | held), plan.nodes[k].op
            if plan.nodes[k].op == "index":
                assert np.all(e.lo[:n // 3] == e.hi[:n // 3]) and np.all(e.lo[-5:] == e.hi[-5:])
                jumps += np.sum(e.lo < e.hi)
    assert jumps > 0                                                  # straddling boxes were seen


def _grid_plan(wrong=None):
    """P(a, b) ~ sin(a) + b**2 on a in [0, 1], b in [-1, 1] (6 fractional bits each) on a grid
    (:class:`~ikseries.fit.features.CutGrid`): a in cells of 1/8, b in cells of 1/4 (the last
    one the single point b = 1), per cell (i, j) a quadratic in the offsets (sin: least
    squares, b**2: exact), looked up by the grid's table address; in cell ``wrong`` = (i, j)
    the constant term is 0.75 too large."""
    from ikseries.fit.features import Cut, CutGrid
    inputs = [PlanInput("a", "mm", 6, 0, 64, 7, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    grid = CutGrid(Cut(0, "a", 3, 9), Cut(1, "b", 4, 9))
    address, (ta, tb) = grid.address(b, {i.name: i for i in inputs})
    t = np.linspace(-1, 1, 65)
    poly = {(0, 0): [], (1, 0): [], (2, 0): [], (0, 1): [], (0, 2): []}
    for i in range(9):
        sa = np.polynomial.polynomial.polyfit(t, np.sin(i / 8 + (t + 1) / 16), 2)
        for j in range(9):
            lo = -1 + j / 4                      # b = lo + (tb + 1) / 8
            c0 = sa[0] + (lo + 1 / 8) ** 2 + (0.75 if wrong == (i, j) else 0.0)
            for e, v in zip(poly, (c0, sa[1], sa[2], (lo + 1 / 8) / 4, 1 / 64)):
                poly[e].append(v)
    ta, tb = (b.align(v, 12) for v in (ta, tb))
    acc = horner(b, {e: tuple(v) for e, v in poly.items()}, [ta, tb], 14, lambda v, f: b.lut(address, grid.table(v), f))
    return b.build([PlanOutput("y", b.clamp(b.round(acc, 0), -10, 10), acc, "ticks", 1.0)])


def _grid_sampled_error(plan):
    """max |P - f| over every port value (every cell corner and edge, the box corners)."""
    a, bb = np.meshgrid(np.arange(0, 65), np.arange(-64, 65), indexing="ij")
    acc = plan.outputs[0].preround
    p = evaluate_ideal(plan, {"a": a.ravel(), "b": bb.ravel()}, keep=[acc])[acc]
    return np.abs(p - np.sin(a.ravel() / 64) - (bb.ravel() / 64) ** 2).max()


def test_grid_bound_holds_and_initial_cells_follow_both_tables():
    """A two-port grid: the certifier's initial cells are cut at both tables' edges (with a
    degenerate last slab along each), so every cell converges; the bound is at least the
    error at every port value (cell corners and edges, box corners) and close to it."""
    plan = _grid_plan()
    edges, cut = _table_edges(plan, range(len(plan.nodes)), ["a", "b"], [0.0, -1.0], [1.0, 1.0])
    assert cut == [True, True]
    assert edges[0].tolist() == [m / 8 for m in range(1, 8)] and edges[1].tolist() == [m / 4 - 1 for m in range(1, 8)]
    sampled = _grid_sampled_error(plan)
    s = certify(_robot(), plan, target_pu=1.05 * sampled).servos[0]
    assert s.converged and sampled <= s.approximation_pu <= 1.05 * sampled + 1e-3


@pytest.mark.parametrize("wrong", [(3, 5), (8, 8), (0, 8)])
def test_grid_plan_with_a_wrong_table_entry_is_refused(wrong):
    """Also in the cells holding the single points a = 1 or b = 1 (the box's upper corner)."""
    bad = certify(_robot(tolerance=1.0), _grid_plan(wrong=wrong))
    with pytest.raises(CertificationError, match=r"servo y: certified error"):
        bad.check(1.0)
    s = bad.servos[0]
    assert s.approximation_pu >= 0.74      # 0.75 less the cell's own (tiny) error
    i, j = wrong
    assert i / 8 <= s.worst["lo"]["a"] <= s.worst["hi"]["a"] <= min(1.0, (i + 1) / 8)
    assert j / 4 - 1 <= s.worst["lo"]["b"] <= s.worst["hi"]["b"] <= min(1.0, (j + 1) / 4 - 1)


def test_bound_encloses_a_known_sup_tightly():
    cert = certify(_robot(), _plan(), target_pu=SIN1 + 0.002)
    s = cert.servos[0]
    assert SIN1 <= s.approximation_pu <= SIN1 + 0.002
    assert s.converged and s.sampled_pu <= SIN1 + 1e-12
    assert s.worst["hi"]["a"] == 1.0                # the sup is at a = 1
    assert cert.box == {"a": (0.0, 1.0), "b": (-1.0, 1.0)}
    assert s.output_rounding_pu == 0.5 and s.clamp_pu == 0.0
    assert s.total_pu == pytest.approx(s.approximation_pu + s.rounding_pu + 0.5)


def test_budget_spent_still_gives_a_valid_bound():
    s = certify(_robot(), _plan(), target_pu=SIN1 / 2, max_cells=200).servos[0]
    assert not s.converged and s.approximation_pu >= SIN1 and s.evaluated <= 200


def test_a_plan_with_an_offset_is_refused():
    good = certify(_robot(tolerance=1.0), _plan())
    good.check(1.0)
    bad = certify(_robot(tolerance=1.0), _plan(offset=0.75))
    assert bad.servos[0].approximation_pu >= 0.75 + SIN1
    with pytest.raises(CertificationError, match=r"servo y: certified error 1\.\d+ pu exceeds the tolerance 1 pu"):
        bad.check(1.0)


def test_counterexamples_are_cells_whose_centre_errs_beyond_the_target():
    """A wrong plan's certificate names sampled counterexamples, each a real error above the
    target (|P - f| = a - sin a + 0.75 at its centre), at most one per region; a good plan's none."""
    assert certify(_robot(tolerance=1.0), _plan()).servos[0].misses == ()
    s = certify(_robot(tolerance=1.0), _plan(offset=0.75)).servos[0]
    assert s.misses and len(s.misses) <= MISS_GRID ** 2
    for lo, hi, err in s.misses:
        a = 0.5 * (lo[0] + hi[0])
        assert err == pytest.approx(a - np.sin(a) + 0.75, abs=1e-9) and err > s.target_pu
    assert max(m[2] for m in s.misses) == pytest.approx(s.sampled_pu)


def test_a_budget_per_starting_cell():
    """per_start raises the cell budget to that many times the starting cells (4 x 4 here)."""
    small = certify(_robot(), _plan(), target_pu=SIN1 / 2, max_cells=200).servos[0]
    big = certify(_robot(), _plan(), target_pu=SIN1 / 2, max_cells=200, per_start=100).servos[0]
    assert small.evaluated <= 200 < big.evaluated <= 1600


def test_output_rounding_follows_the_plan():
    assert output_rounding(_plan(), 0) == (0.5, None)           # the clamp never acts: dropped
    assert output_rounding(_plan(clamp=(0, 1)), 0) == (0.5, (0.0, 1.0))
    assert output_rounding(_plan(floor_only=True), 0) == (1 - 2.0 ** -12, None)


def test_output_rounding_refuses_a_sum_of_other_terms():
    """The output's sum may hold the accumulator's terms plus constants, nothing else."""
    plan = _plan()
    o = plan.outputs[0]
    other = next(i for i, n in enumerate(plan.nodes) if n.op == "mul")
    bad = Plan(plan.inputs, plan.nodes, [PlanOutput(o.name, o.node, other, o.unit, o.ticks_per_pu)], {})
    with pytest.raises(ValueError, match="must be a clamp over constant additions and shifts, not a 'add' node"):
        output_rounding(bad, 0)


def test_a_clamp_that_cuts_the_reference_is_counted():
    s = certify(_robot(), _plan(clamp=(0, 1))).servos[0]
    assert s.clamp_pu >= np.sin(1.0)                 # f reaches 1 + sin(1) > 1


@pytest.mark.parametrize("kwargs, words", [
    ({"target_pu": 0}, "target_pu must be a number > 0 pu or None, not 0"),
    ({"max_cells": 0}, "max_cells must be a positive integer, not 0"),
    ({"initial": 1.5}, "initial must be a positive integer, not 1.5"),
    ({"per_start": -1}, "per_start must be an integer >= 0, not -1"),
])
def test_bad_arguments(kwargs, words):
    with pytest.raises(ValueError, match=words):
        certify(_robot(), _plan(), **kwargs)


def test_check_rejects_a_bad_tolerance():
    with pytest.raises(ValueError, match="tolerance must be a number > 0 pu, not -1"):
        certify(_robot(), _plan()).check(-1)


def test_inputs_must_match_the_robot():
    robot = _robot()
    robot.workspace.inputs = (SimpleNamespace(name="a"), SimpleNamespace(name="c"))
    with pytest.raises(ValueError, match=r"plan inputs must be the robot's inputs \['a', 'c'\]"):
        certify(robot, _plan())


def test_real_plan_bound_is_at_least_the_sampled_error(robot, plan):
    """With a small cell budget the bound is loose, but never below the sampled error."""
    cert = certify(robot, plan, max_cells=6000)
    pts = verification_points(robot, n_points=40_000, n_face=1000, grid_points=20_000)
    sampled = measure(robot, plan, pts)["servos"]
    assert [s.name for s in cert.servos] == list(robot.servos)
    bounds = plan.rounding_bounds()
    for s, o in zip(cert.servos, plan.outputs):
        assert s.rounding_pu == bounds[o.preround] / o.ticks_per_pu
        assert s.approximation_pu >= sampled[s.name]["approximation"]
        assert s.approximation_pu >= s.sampled_pu > 0.5 * sampled[s.name]["approximation"]
        assert s.output_rounding_pu == 0.5 / robot.ticks_per_pu
    assert cert.box["theta"] == (-180.0, 180.0)


def _certified_within_tolerance(robot, plan):
    """The certificate the fit stored (certify at its default budget, run by fit_robot) holds
    every servo within the tolerance and above the error sampled on >= 10**6 points."""
    cert = plan.meta["certificate"]
    sampled = measure(robot, plan)["servos"]
    assert [s["name"] for s in cert["servos"]] == list(robot.servos)
    for s in cert["servos"]:
        assert s["converged"] and s["total_pu"] <= robot.fit.tolerance_pu, s
        assert s["approximation_pu"] >= sampled[s["name"]]["approximation"], s
        assert s["total_pu"] >= sampled[s["name"]]["total"], s


def test_default_plan_is_certified_within_tolerance(robot, plan):
    """Every servo of the cylinder leg, whose cos series is clamped near theta = +-180 deg
    (the clamp never acts in exact arithmetic: the centred evaluation must see that)."""
    _certified_within_tolerance(robot, plan)


def test_planar_arm_plan_is_certified_within_tolerance(tmp_path_factory):
    from helpers import shared_fit
    robot = load_preset("planar-arm")
    _certified_within_tolerance(robot, shared_fit(tmp_path_factory, "planar-arm", robot).plan)
