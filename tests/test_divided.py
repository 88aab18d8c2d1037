"""Divided differences (path mode) on the planar arm."""
import math

import numpy as np
import pytest

from ikseries.fit.baselines.divided import (DEFAULT_CASES, PathCase, divided_differences, incidence_weights, nearest_turn,
                                  newton_derivatives, newton_eval, newton_to_power, path_interpolant, path_report,
                                  render_markdown, run_divided_differences)
from ikseries.kinematics import CylinderLeg
from ikseries.planar_arm import PlanarArm

P = np.polynomial.polynomial


# -- Newton interpolation -----------------------------------------------------------------------
def test_known_divided_differences():
    # f = x**2 on 0, 1, 2: f[0] = 0, f[0,1] = 1, f[0,1,2] = 1
    np.testing.assert_array_equal(divided_differences([0.0, 1.0, 2.0], [0.0, 1.0, 4.0]), [0.0, 1.0, 1.0])


def test_four_nodes_reproduce_a_cubic_exactly():
    rng = np.random.default_rng(5)
    for _ in range(20):
        coef = rng.normal(size=4) * 10
        nodes = np.sort(rng.uniform(-20, 20, 4))
        c = divided_differences(nodes, P.polyval(nodes, coef))
        np.testing.assert_allclose(newton_to_power(nodes, c), coef, rtol=1e-9, atol=1e-9)
        x = np.linspace(-25, 25, 101)
        np.testing.assert_allclose(newton_eval(nodes, c, x), P.polyval(x, coef), rtol=1e-10, atol=1e-8)


def test_a_quartic_leaves_the_nodal_product_times_its_leading_coefficient():
    """f - p3 = a4 * prod(x - x_i) for a quartic f: the interpolant is exact at the nodes only."""
    coef = [1.0, -2.0, 0.5, 3.0, 0.25]
    nodes = np.array([-10.0, 0.0, 10.0, 20.0])
    c = divided_differences(nodes, P.polyval(nodes, coef))
    x = np.linspace(-15, 25, 81)
    rest = P.polyval(x, coef) - newton_eval(nodes, c, x)
    np.testing.assert_allclose(rest, 0.25 * np.prod([x - n for n in nodes], axis=0), rtol=1e-9, atol=1e-7)
    assert np.max(np.abs(rest)) > 1000


def test_newton_derivatives_match_the_power_form():
    nodes = [-15.0, -5.0, 0.0, 10.0]
    c = divided_differences(nodes, [3.0, -1.0, 4.0, 1.5])
    pw = newton_to_power(nodes, c)
    x = np.linspace(-20, 15, 36)
    p, dp, d2p = newton_derivatives(nodes, c, x)
    np.testing.assert_allclose(p, P.polyval(x, pw), atol=1e-10)
    np.testing.assert_allclose(dp, P.polyval(x, P.polyder(pw)), atol=1e-10)
    np.testing.assert_allclose(d2p, P.polyval(x, P.polyder(pw, 2)), atol=1e-10)


@pytest.mark.parametrize("nodes, values, message", [
    ([0.0, 1.0, 1.0], [1.0, 2.0, 3.0], "nodes must be distinct, not [0.0, 1.0, 1.0]"),
    ([0.0, 1.0], [1.0, 2.0, 3.0], "values must have one entry per node (2), not [1.0, 2.0, 3.0]"),
    ([], [], "nodes must be a non-empty 1-D sequence of numbers, not []"),
    ([0.0, math.inf], [1.0, 2.0], "nodes and values must be finite, not [0.0, inf] and [1.0, 2.0]"),
])
def test_bad_nodes_are_one_line_errors(nodes, values, message):
    with pytest.raises(ValueError) as e:
        divided_differences(nodes, values)
    assert str(e.value) == message


# -- incidence weights and the path interpolant ---------------------------------------------------
def test_incidence_weights():
    assert incidence_weights(0.0, -35.0) == (0.0, 1.0)  # vertical path: all y
    assert incidence_weights(25.0, 0.0) == (1.0, 0.0)
    assert incidence_weights(25.0, 25.0) == (0.5, 0.5)
    wx, wy = incidence_weights(30.0, -15.0)
    assert math.isclose(wx, 2 / 3) and math.isclose(wy, 1 / 3)
    with pytest.raises(ValueError) as e:
        incidence_weights(0.0, 0.0)
    assert str(e.value) == "path direction must be a finite non-zero vector, not (0.0, 0.0)"


def test_vertical_path_interpolant_is_all_y():
    case = next(c for c in DEFAULT_CASES if c.slope is None)
    xs, ys = case.node_points()
    ip = path_interpolant(xs, ys, [1.0, 4.0, 2.0, 3.0])
    assert (ip.wx, ip.wy) == (0.0, 1.0) and ip.cx == () and len(ip.cy) == 4
    # no x dependence at all: the same value at any x
    np.testing.assert_array_equal(ip(np.full(5, -80.0), ys[:1].repeat(5)), ip(np.full(5, 7.0), ys[:1].repeat(5)))


@pytest.mark.parametrize("case", DEFAULT_CASES, ids=lambda c: c.name)
def test_interpolant_reproduces_the_node_angles(case):
    arm = PlanarArm(phi=case.phi)
    xs, ys = case.node_points()
    for a in arm.ik(xs, ys):
        ip = path_interpolant(xs, ys, a)
        np.testing.assert_allclose(ip(xs, ys), a, rtol=0, atol=1e-11)
        # on the path P_x(x(t)) + P_y(y(t)) is the cubic interpolant in the path parameter t
        t = np.linspace(-5, 40, 46)
        x, y = case.points(t)
        tn = case.parameter(xs, ys)
        np.testing.assert_allclose(ip(x, y), newton_eval(tn, divided_differences(tn, a), t), atol=1e-9)


def test_off_path_nodes_are_rejected():
    with pytest.raises(ValueError, match=r"^nodes must lie on one straight path, not \[\(0.0, 0.0\), \(1.0, 2.0\), "):
        path_interpolant([0.0, 1.0, 2.0], [0.0, 2.0, 1.0], [1.0, 2.0, 3.0])


def test_nearest_turn():
    np.testing.assert_allclose(nearest_turn([350.0, 10.0, 190.0], 0.0), [-10.0, 10.0, -170.0])
    assert nearest_turn(5.0, 360.0) == 365.0


@pytest.mark.parametrize("kw, message", [
    ({"nodes": (1.0, 1.0)}, "PathCase.nodes must be a tuple of >= 2 distinct finite numbers, not (1.0, 1.0)"),
    ({"nodes": [0.0, 1.0]}, "PathCase.nodes must be a tuple of >= 2 distinct finite numbers, not [0.0, 1.0]"),
    ({"phi": "up"}, "PathCase.phi must be a finite number, not 'up'"),
    ({"slope": math.nan}, "PathCase.slope must be a finite number or None, not nan"),
    ({"box": ((0.0, -1.0), (0.0, 1.0))},
     "PathCase.box must be ((x_min, x_max), (y_min, y_max)) with min < max, not ((0.0, -1.0), (0.0, 1.0))"),
])
def test_bad_case_is_a_one_line_error(kw, message):
    args = dict(name="c", phi=90.0, slope=1.0, offset=40.0, nodes=(-15.0, 10.0), box=((-15.0, 10.0), (25.0, 50.0)))
    args.update(kw)
    with pytest.raises(ValueError) as e:
        PathCase(**args)
    assert str(e.value) == message


# -- the report -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def result():
    return run_divided_differences(PlanarArm())


def _floats(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _floats(v)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from _floats(v)
    elif isinstance(obj, float):
        yield obj


def _on_path(case, at):
    if case.slope is None:
        return math.isclose(at["x"], case.offset)
    return math.isclose(at["y"], case.slope * at["x"] + case.offset, abs_tol=1e-9)


def test_three_cases_have_finite_figures(result):
    assert [c["case"] for c in result["cases"]] == [c.name for c in DEFAULT_CASES]
    values = list(_floats(result))
    assert len(values) > 300 and all(math.isfinite(v) for v in values)


@pytest.mark.parametrize("k", range(3))
def test_fk_error_is_reported_with_its_location_on_the_path(result, k):
    case, rep = DEFAULT_CASES[k], result["cases"][k]
    fk = rep["fk"]
    assert 0 < fk["max_position_error"] < 1 and _on_path(case, fk["at"])
    t_nodes = rep["nodes"]["t"]
    assert min(t_nodes) <= fk["at"]["t"] <= max(t_nodes)
    # the figure is the FK error of the divided-differences angles at that point
    arm = PlanarArm(phi=case.phi)
    at = fk["at"]
    ips = [path_interpolant(rep["nodes"]["x"], rep["nodes"]["y"], j["node_angles_deg"]) for j in rep["joints"].values()]
    x, y = arm.fk(*(ip(at["x"], at["y"]) for ip in ips))
    assert math.isclose(math.hypot(x - at["x"], y - at["y"]), fk["max_position_error"], rel_tol=1e-9)


@pytest.mark.parametrize("k", range(3))
def test_joint_figures_are_consistent(result, k):
    case, rep = DEFAULT_CASES[k], result["cases"][k]
    for j in rep["joints"].values():
        assert j["node_residual_deg"] < 1e-9
        assert j["max_error_pu"] == pytest.approx(20 * j["max_error_deg"]) and _on_path(case, j["at"])
        # the minimax cubic in the path parameter beats the interpolating cubic
        assert 0 < j["minimax_path"]["max_error_deg"] < j["max_error_deg"]
        # the separable path formula is not a workspace fit: a 2-D cubic does far better over the box
        ws = j["workspace"]
        assert ws["minimax_cubic"]["max_error_deg"] < ws["divided_differences"]["max_error_deg"]
        assert ws["minimax_to_tolerance"]["meets_tolerance"]
        r = j["rates"]
        assert r["max_error"]["velocity_t"] < 0.1 * r["max_abs"]["exact_velocity_t"]
        if case.slope is None:
            assert "per_x" not in r["at_nodes"] and "per_y" in r["at_nodes"]
    assert rep["incidence_weights"] == ({"x": 0.0, "y": 1.0} if case.slope is None else rep["incidence_weights"])


def test_wrap_of_the_0_360_output_is_flagged_and_bridged(result):
    """On the phi = 45 path link 2 crosses +x: ik wraps, the report uses the continuous branch."""
    rep = result["cases"][1]
    assert rep["joints"]["s2"]["wraps_0_360"] and not rep["joints"]["s1"]["wraps_0_360"]
    a = rep["joints"]["s2"]["node_angles_deg"]
    assert a[0] > 0 > a[-1] and rep["joints"]["s2"]["max_error_deg"] < 1


def test_report_rejects_other_geometries():
    with pytest.raises(TypeError, match=r"^geometry must be a PlanarArm, not CylinderLeg\("):
        path_report(CylinderLeg(), DEFAULT_CASES[0])
    with pytest.raises(ValueError, match=r"^samples must be an integer >= 8, not 3$"):
        path_report(PlanarArm(), DEFAULT_CASES[0], samples=3)


def test_markdown_lists_every_case(result):
    md = render_markdown(result)
    for c in DEFAULT_CASES:
        assert f"## {c.name}: phi = {c.phi:g} deg, {c.line}" in md
    assert md.count("FK position error along the path") == 3 and "(wraps 0/360)" in md


def test_bench_script_prints_and_writes_json(tmp_path, capsys):
    import importlib.util
    import json
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "bench" / "divided_differences.py"
    spec = importlib.util.spec_from_file_location("bench_divided_differences", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "dd.json"
    mod.main(["--json", str(out), "--samples", "101", "--grid", "11"])
    rec = json.loads(out.read_text())
    assert rec["method"] == "divided-differences" and rec["preset"] == "planar-arm" and len(rec["cases"]) == 3
    assert "## phi180-vertical" in capsys.readouterr().out
    with pytest.raises(SystemExit, match=r"^--preset must name a planar-arm robot, not 'cylinder-leg'$"):
        mod.main(["--preset", "cylinder-leg", "--json", str(out)])
