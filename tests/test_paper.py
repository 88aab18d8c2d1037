"""The integer power series paper's procedure (fit/baselines/paper.py) and the plan comparison."""
import json
from decimal import Decimal

import numpy as np
import pytest
from ikseries.fit.baselines.comparison import compare, render_comparison
from ikseries.fit.baselines.paper import (
    R_ORDER,
    SIG_FIGS,
    THETA_TERMS,
    Z_ORDER,
    cut_sig_figs,
    evaluate_servo,
    fit_paper,
    horner_multiplications,
    paper_errors,
    paper_plan,
)
from ikseries.fit.plan import Plan
from ikseries.sim import golden
from ikseries.sim.targets import corner_targets, random_targets

from ikseries.accuracy import measure


@pytest.fixture(scope="module")
def pfit(robot):
    return fit_paper(robot)


@pytest.fixture(scope="module")
def pplan(robot, pfit):
    return paper_plan(robot, pfit)


@pytest.fixture(scope="module")
def points(robot):
    rng = np.random.default_rng(3)
    return {i.name: rng.integers(i.lo, i.hi + 1, 30_000) for i in robot.workspace.inputs}


def _real(robot, ports):
    return [ports[i.name] * 2.0 ** -i.frac_bits for i in robot.workspace.inputs]


# -- term structure ---------------------------------------------------------------------------
def test_term_structure_is_the_papers(pfit):
    by = {s.name: s for s in pfit.servos}
    even = range(0, 2 * THETA_TERMS, 2)
    grid3 = {(i, j, k) for i in range(R_ORDER + 1) for j in even for k in range(Z_ORDER + 1)}
    for name in ("s2", "s3"):
        s = by[name]
        assert s.allowed == ["any", "even", "any"]
        assert set(s.terms) == grid3 and len(s.terms) == 200            # the paper's table
        zeros = set(s.terms) - set(s.poly)
        assert len(zeros) == 35                                         # "of these, 35 are zero"
        assert zeros == {(0, j, k) for j in even if j > 0 for k in range(Z_ORDER + 1)}  # R = 0 circle
    s1 = by["s1"]
    assert s1.allowed == ["any", "odd", "none"]                         # odd in theta, no Z
    assert {e[1] for e in s1.terms} == {0} | set(range(1, 2 * THETA_TERMS, 2))
    assert all(e[2] == 0 for e in s1.terms) and len(s1.terms) == 9 * (R_ORDER + 1)
    assert set(s1.poly) == {(0, 0, 0)} | {(i, j, 0) for i in range(1, R_ORDER + 1)
                                          for j in range(1, 2 * THETA_TERMS, 2)}


def test_counts_are_pinned(pfit):
    assert pfit.counts() == {"s1": {"terms": 45, "nonzero_terms": 33, "multiplications": 41},
                             "s2": {"terms": 200, "nonzero_terms": 165, "multiplications": 172},
                             "s3": {"terms": 200, "nonzero_terms": 165, "multiplications": 172}}


def test_multiplication_count_is_the_plans(robot, pfit, pplan):
    shared = 1   # theta**2, computed once for all servos
    for s, o in zip(pfit.servos, pplan.outputs):
        muls = sum(1 for i in pplan.cone(o.preround) if pplan.nodes[i].op == "mul")
        assert muls == horner_multiplications(s.poly, s.allowed[1]) == s.multiplications
    assert pplan.count("mul") == sum(s.multiplications for s in pfit.servos) - (len(pfit.servos) - 1) * shared


# -- the three steps ---------------------------------------------------------------------------
def test_uncut_series_passes_through_every_circle(robot, pfit):
    """Steps 2 and 3 interpolate: on each of the paper's circles the 3-variable series is the
    circle's theta series, whose error is at most the worst circle's."""
    uncut = pfit.uncut()
    th = pfit.grid.dense_theta()
    for k, s in enumerate(uncut.servos):
        planes = pfit.grid.z if s.allowed[2] != "none" else pfit.grid.z[:1]
        worst = 0.0
        for r in pfit.grid.r:
            for z in planes:
                rr, zz = np.full(th.shape, r), np.full(th.shape, z)
                worst = max(worst, float(np.max(np.abs(evaluate_servo(s, rr, th, zz)
                                                       - robot.pulses_pu(rr, th, zz)[k]))))
        assert worst <= s.circle_error_pu + 1e-6
        assert worst >= s.circle_error_pu - 1e-6


def test_chebyshev_variant_interpolates_at_its_points(robot):
    """Cramer's rule at the eight theta points, five cylinders and five planes: the uncut
    series equals the exact pulses at every grid point (negative theta by symmetry)."""
    fit = fit_paper(robot, "chebyshev").uncut()
    g = fit.grid
    rr, tt, zz = (a.ravel() for a in np.meshgrid(g.r, g.theta + tuple(-t for t in g.theta), g.z, indexing="ij"))
    ref = robot.pulses_pu(rr, tt, zz)
    for k, s in enumerate(fit.servos):
        assert np.max(np.abs(evaluate_servo(s, rr, tt, zz) - ref[k])) < 1e-6


def test_seven_significant_figures(pfit):
    for s in pfit.servos:
        for e, c in s.poly.items():
            u = s.unrounded[e]
            digits = Decimal(repr(c)).normalize().as_tuple().digits
            assert len(digits) <= SIG_FIGS, (s.name, e, c)
            half_unit = 0.5 * 10.0 ** (np.floor(np.log10(abs(u))) - (SIG_FIGS - 1))
            assert abs(c - u) <= half_unit * (1 + 1e-9), (s.name, e, c, u)


def test_cut_sig_figs_rounds_to_nearest():
    assert cut_sig_figs(123456789.0) == 123456800.0
    assert cut_sig_figs(-0.000123456749) == -0.0001234567
    assert cut_sig_figs(2.5e-30, 1) == 2e-30          # ties to even
    assert cut_sig_figs(0.0) == 0.0
    with pytest.raises(ValueError, match="digits must be a positive integer, not 0"):
        cut_sig_figs(1.0, 0)


def test_bad_theta_fit_is_refused(robot):
    with pytest.raises(ValueError, match="theta_fit must be one of .*, not 'spline'"):
        fit_paper(robot, "spline")


def test_fit_is_deterministic(robot, pfit):
    again = fit_paper(robot)
    assert [s.poly for s in again.servos] == [s.poly for s in pfit.servos]


# -- the plan ------------------------------------------------------------------------------------
def test_plan_matches_the_float_series_within_the_certified_bound(robot, pfit, pplan, points):
    real = _real(robot, points)
    pre = {o.preround for o in pplan.outputs}
    iv = golden.evaluate(pplan, points, pre | {o.node for o in pplan.outputs})
    bounds = pplan.rounding_bounds()
    limits = robot.pulse_limits_ticks()
    tpp = robot.ticks_per_pu
    for s, o in zip(pfit.servos, pplan.outputs):
        lo, hi = limits[o.name]
        want = evaluate_servo(s, *real)                         # pu, the paper's series
        got_pre = iv[o.preround] * 2.0 ** -pplan.nodes[o.preround].frac / tpp
        bound = bounds[o.preround] / tpp
        assert 0 < bound <= 0.1 * robot.fit.tolerance_pu
        assert np.max(np.abs(got_pre - want)) <= bound + 1e-6
        got = iv[o.node] / tpp
        assert np.max(np.abs(got - np.clip(want, lo / tpp, hi / tpp))) <= bound + 0.5 / tpp + 1e-6


def test_no_node_of_the_paper_plan_leaves_its_interval(pplan):
    c = corner_targets(pplan, port_extremes=True)
    r = random_targets(pplan, 5_000, 9)
    vals = golden.evaluate(pplan, {k: np.concatenate([c[k], r[k]]) for k in c})
    for k, n in enumerate(pplan.nodes):
        v = np.asarray(vals[k])
        assert n.lo <= v.min() and v.max() <= n.hi, (k, n.op)


def test_plan_meta_and_json_round_trip(pfit, pplan):
    m = pplan.meta
    assert m["method"]["name"] == "paper" and m["method"]["theta_fit"] == "minimax"
    assert m["method"]["deviations"][0].startswith("theta step: on each circle the near-minimax")
    for s, ms in zip(pfit.servos, m["servos"]):
        assert ms["terms"] == len(s.terms) and ms["accumulator_frac_bits"] == s.frac
        assert {tuple(c["exponents"]): c["value"] for c in ms["coefficients"]} == s.poly
    again = Plan.from_json(json.loads(pplan.dumps()))
    assert again.dumps() == pplan.dumps()


def test_plan_for_another_robot_is_refused(robot, pfit):
    import dataclasses
    other = dataclasses.replace(robot, name="other-leg")
    with pytest.raises(ValueError, match="fit must be of robot 'other-leg', not of 'cylinder-leg'"):
        paper_plan(other, pfit)


# -- accuracy ------------------------------------------------------------------------------------
def test_sampled_error_is_finite_and_sane(robot, pfit, pplan, points):
    """The plan's exact-arithmetic error is the float series' error, within 1 % of the servo's
    pulse range, and the emitted error within that plus the certified bound and half a tick."""
    real = _real(robot, points)
    ref = robot.pulses_pu(*real)
    fl = paper_errors(robot, pfit, points)["servos"]
    acc = measure(robot, pplan, points)["servos"]
    for k, s in enumerate(pfit.servos):
        e = fl[s.name]["max_error_pu"]
        assert np.isfinite(e)
        assert acc[s.name]["approximation"] == pytest.approx(e, abs=1e-6)
        assert e <= 0.01 * np.ptp(ref[k])
        assert acc[s.name]["total"] <= e + s.bound_pu + 0.5 / robot.ticks_per_pu + 1e-9


def test_compare_reports_both_methods(robot, pplan, small_plan, points):
    res = compare(robot, small_plan, pplan, points)
    for method, figs in res["methods"].items():
        for name, f in figs["servos"].items():
            assert f["multiplications"] == f["shared_multiplications"] + f["own_multiplications"]
            assert f["coefficient_bits_max"] <= f["coefficient_bits_total"]
            assert f["max_error_pu"] >= 0
    paper = res["methods"]["paper"]["servos"]
    assert [paper[s]["shared_multiplications"] for s in ("s1", "s2", "s3")] == [1, 1, 1]   # theta**2
    assert paper["s2"]["terms"] == 165
    md = render_comparison(res)
    for method, figs in res["methods"].items():
        for name, f in figs["servos"].items():
            ok = "yes" if f["max_error_pu"] <= robot.fit.tolerance_pu else "**no**"
            assert f"| {name} | {method} | {f['terms']} |" in md
            assert any(line.startswith(f"| {name} | {method} |") and line.endswith(f"| {ok} |")
                       for line in md.splitlines())


def test_compare_refuses_plans_of_other_servos(robot, pplan, small_plan):
    import dataclasses
    renamed = dataclasses.replace(pplan, outputs=[dataclasses.replace(o, name=o.name + "x")
                                                  for o in pplan.outputs])
    with pytest.raises(ValueError, match="plans must have the same servos"):
        compare(robot, small_plan, renamed)
