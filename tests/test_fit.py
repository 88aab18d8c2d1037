"""The fitted plan of the default robot: accuracy, structure, certified bounds, determinism."""
import dataclasses

import numpy as np
import pytest

from ikseries.accuracy import measure, verification_points
from ikseries.fit.fitter import Budget, FitError, fit_robot


@pytest.fixture(scope="module")
def accuracy(robot, plan):
    return measure(robot, plan)


def test_every_servo_within_tolerance_on_a_million_points(robot, accuracy):
    assert accuracy["points"] >= 1_000_000
    for name, e in accuracy["servos"].items():
        assert e["total"] <= robot.tolerance_pu, (name, e)
        # the split is consistent: total <= sum of the parts
        assert e["total"] <= e["approximation"] + e["quantization"] + e["rounding"] + 1e-9
        assert e["rounding"] <= 0.5 / robot.ticks_per_pu + 1e-12


def test_measured_quantization_within_certified_bound(robot, plan, accuracy):
    bounds = plan.rounding_bounds()
    for o in plan.outputs:
        cert = bounds[o.preround] / o.ticks_per_pu
        assert accuracy["servos"][o.name]["quantization"] <= cert
        assert cert <= Budget.split(robot.tolerance_pu, robot.ticks_per_pu).quantization


def test_symmetry_and_unused_variables_are_found(fitted):
    _, fits = fitted
    by = {f.name: f for f in fits}
    assert by["s1"].allowed == ["any", "odd", "none"]      # odd in theta, independent of Z
    assert by["s2"].allowed == by["s3"].allowed == ["any", "even", "any"]
    for f in fits:
        par = f.allowed[1]
        for e in f.poly:
            assert par != "even" or e[1] % 2 == 0
            assert par != "odd" or e[1] % 2 == 1 or sum(e) == 0
            assert f.allowed[2] != "none" or e[2] == 0


def test_verification_points_cover_grid_faces_and_range(robot):
    pts = verification_points(robot)
    for i in robot.inputs:
        v = pts[i.name]
        assert v.min() == i.lo and v.max() == i.hi
        assert np.count_nonzero(v == i.lo) >= 10_000 and np.count_nonzero(v == i.hi) >= 10_000


def test_fit_is_deterministic(small_robot, small_plan):
    again, _ = fit_robot(small_robot)
    assert again.dumps() == small_plan.dumps()


def test_tolerance_below_output_rounding_is_refused(robot):
    with pytest.raises(FitError, match="tolerance 0.01 pu leaves no approximation budget"):
        fit_robot(dataclasses.replace(robot, tolerance_pu=0.01))


def test_looser_tolerance_gives_a_smaller_plan(plan, small_plan):
    assert small_plan.count("mul") < plan.count("mul")


def test_no_node_of_the_real_plan_leaves_its_interval(plan):
    """Every intermediate of the generated datapath stays inside the interval its width was
    sized from, at every corner (port extremes included) and at random targets."""
    from ikseries.sim import golden
    from ikseries.sim.targets import corner_targets, random_targets
    c = corner_targets(plan, port_extremes=True)
    r = random_targets(plan, 20_000, 5)
    vals = golden.evaluate(plan, {k: np.concatenate([c[k], r[k]]) for k in c})
    for k, n in enumerate(plan.nodes):
        v = np.asarray(vals[k])
        assert n.lo <= v.min() and v.max() <= n.hi, (k, n.op, n.lo, n.hi, v.min(), v.max())
        if n.op != "const":
            assert n.width <= 62
