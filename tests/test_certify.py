"""Certified error bound over the continuous workspace box."""
from types import SimpleNamespace

import numpy as np
import pytest

from ikseries.accuracy import measure, verification_points
from ikseries.fit.certify import CertificationError, certify, output_rounding
from ikseries.fit.fitter import fit_robot
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.kinematics import Calibration
from ikseries.robot import load_preset

SIN1 = 1.0 - np.sin(1.0)   # sup over a in [0, 1] of |a - sin(a)|


class _SineGeometry:
    """Reference 'angle' sin(a) + b**2 over the math namespace, like Geometry.angles."""
    inputs = ("a", "b")
    servos = ("y",)

    def angles(self, xp, a, b):
        return (xp.sin(a) + b * b,)


def _robot(tolerance=0.5):
    """A robot with the geometry above and an identity calibration (pulse = angle)."""
    return SimpleNamespace(
        geometry=_SineGeometry(), servos=("y",), tolerance_pu=tolerance,
        inputs=(SimpleNamespace(name="a"), SimpleNamespace(name="b")),
        calibration=Calibration(neutral_angles=(0.0,), directions=(1,), neutral_pulse_pu=0.0,
                                pu_per_degree=1.0))


def _plan(offset=0.0, floor_only=False, clamp=(-10, 10)):
    """P(a, b) = a + b**2 + offset on a in [0, 1], b in [-1, 1]: |P - f| = |a - sin a + offset|."""
    inputs = [PlanInput("a", "mm", 6, 0, 64, 7, False), PlanInput("b", "mm", 6, -64, 64, 8, True)]
    b = PlanBuilder(inputs)
    a_n, b_n = b.input_nodes["a"], b.input_nodes["b"]
    acc = b.add(b.align(b.add(a_n, b.const(offset, 6)), 12), b.mul(b_n, b_n))
    out = b.align(acc, 0) if floor_only else b.clamp(b.round(acc, 0), *clamp)
    return b.build([PlanOutput("y", out, acc, "ticks", 1.0)])


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


def test_output_rounding_follows_the_plan():
    assert output_rounding(_plan(), 0) == (0.5, None)           # the clamp never acts: dropped
    assert output_rounding(_plan(clamp=(0, 1)), 0) == (0.5, (0.0, 1.0))
    assert output_rounding(_plan(floor_only=True), 0) == (1 - 2.0 ** -12, None)


def test_a_clamp_that_cuts_the_reference_is_counted():
    s = certify(_robot(), _plan(clamp=(0, 1))).servos[0]
    assert s.clamp_pu >= np.sin(1.0)                 # f reaches 1 + sin(1) > 1


@pytest.mark.parametrize("kwargs, words", [
    ({"target_pu": 0}, "target_pu must be a number > 0 pu or None, not 0"),
    ({"max_cells": 0}, "max_cells must be a positive integer, not 0"),
    ({"initial": 1.5}, "initial must be a positive integer, not 1.5"),
])
def test_bad_arguments(kwargs, words):
    with pytest.raises(ValueError, match=words):
        certify(_robot(), _plan(), **kwargs)


def test_check_rejects_a_bad_tolerance():
    with pytest.raises(ValueError, match="tolerance must be a number > 0 pu, not -1"):
        certify(_robot(), _plan()).check(-1)


def test_inputs_must_match_the_robot():
    robot = _robot()
    robot.inputs = (SimpleNamespace(name="a"), SimpleNamespace(name="c"))
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
    cert = certify(robot, plan)                       # the default budget
    cert.check(robot.tolerance_pu)
    sampled = measure(robot, plan)["servos"]          # >= 10**6 points
    for s in cert.servos:
        assert s.converged and s.total_pu <= robot.tolerance_pu, s
        assert s.approximation_pu >= sampled[s.name]["approximation"], s
        assert s.total_pu >= sampled[s.name]["total"], s


def test_default_plan_is_certified_within_tolerance(robot, plan):
    """Every servo of the cylinder leg, whose cos series is clamped near theta = +-180 deg
    (the clamp never acts in exact arithmetic: the centred evaluation must see that)."""
    _certified_within_tolerance(robot, plan)


def test_planar_arm_plan_is_certified_within_tolerance():
    robot = load_preset("planar-arm")
    _certified_within_tolerance(robot, fit_robot(robot)[0])
