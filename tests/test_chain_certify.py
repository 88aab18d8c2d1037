"""Proven enclosures of a chain's IK (Krawczyk per cell) and the certified fit of a chain."""
import copy
import dataclasses
import re
import time
from types import SimpleNamespace

import numpy as np
import pytest

from ikseries.chain import Chain, Joint, Tool
from ikseries.chain.enclose import ChainEnclosureError
from ikseries.fit import centred as cn
from ikseries.fit import interval as ia
from ikseries.fit.certify import UnboundedCellError, certify
from ikseries.fit.plan import PlanBuilder, PlanInput, PlanOutput
from ikseries.calibration import Calibration
from ikseries.kinematics import NUMPY_MATH
from ikseries.robot import load_preset, parse_robot
from test_chain import CYLINDER_CHAIN, HEXAPOD_CHAIN, _arm4, _planar, _robot_data


def _cells(rng, lo, hi, n, width):
    """n random cells of the box [lo, hi], each side up to ``width`` of the box's."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    w = (hi - lo) * width * rng.uniform(0.2, 1.0, (n, len(lo)))
    a = lo + (hi - lo - w) * rng.random((n, len(lo)))
    return a, a + w


def _float_ik(chain, pts):
    return np.stack(chain.angles(NUMPY_MATH, *pts.T), 1)


def _fd(chain, pts, step):
    """Central finite differences (n_pts, n_joints, n_in) and second ones (n_pts, n_joints, pairs)."""
    n_in = pts.shape[1]
    unit = np.eye(n_in) * step
    d1 = np.stack([(_float_ik(chain, pts + u) - _float_ik(chain, pts - u)) / (2 * step) for u in unit], 2)
    q0 = _float_ik(chain, pts)
    d2 = []
    for j, k in zip(*ia.hessian_pairs(n_in)):
        uj, uk = unit[j], unit[k]
        d2.append((_float_ik(chain, pts + uj + uk) - _float_ik(chain, pts + uj - uk) - _float_ik(chain, pts - uj + uk)
                   + _float_ik(chain, pts - uj - uk)) / (4 * step * step) if j != k else
                  (_float_ik(chain, pts + uj) - 2 * q0 + _float_ik(chain, pts - uj)) / (step * step))
    return d1, np.stack(d2, 2)


CHAINS = {
    "planar": (_planar(ranges=((-170, 170), (0, 170))), [40, -20], [70, 20]),
    "hexapod": (parse_robot(_robot_data("hexapod-leg", HEXAPOD_CHAIN)).geometry, [54, -40, -20], [94, 40, 30]),
    "cylinder": (parse_robot(_robot_data("cylinder-leg", CYLINDER_CHAIN)).geometry, [20, -90, -20], [60, 90, 20]),
    "arm4-phi": (_arm4(None), [60, -40, 0, -40], [120, 40, 60, -20]),
}


@pytest.mark.parametrize("name", CHAINS)
def test_enclosure_contains_the_newton_solution_and_its_derivatives(name):
    """Over random cells (sides up to 1/40 of the box) the cell enclosure (centred form: value,
    gradient, Hessian) holds the continued Newton solution and its finite-difference
    derivatives at random points of the cell, and the centre enclosure those at the centre."""
    chain, lo, hi = CHAINS[name]
    rng = np.random.default_rng(5)
    clo, chi = _cells(rng, lo, hi, 40, 1 / 40)
    with ia.lenient():
        q = chain.angles(cn.MATH, *cn.variables(clo, chi))
    proven = ~np.isnan(q[0].x.lo)
    assert proven.mean() > 0.8, proven.mean()
    c, _ = cn.centres(clo, chi)
    step = 1e-3 * float(np.min(np.subtract(hi, lo)))
    for pts, part in [(c, "c")] + [(clo + (chi - clo) * rng.random(clo.shape), "x") for _ in range(2)]:
        ref = _float_ik(chain, pts)
        d1, d2 = _fd(chain, pts, step)
        for i, qi in enumerate(q):
            e = getattr(qi, part)
            slack = 1e-9 * (1 + np.abs(ref[:, i]))
            assert np.all(((e.lo - slack <= ref[:, i]) & (ref[:, i] <= e.hi + slack))[proven])
            assert np.all(((e.d[0] - 1e-5 <= d1[:, i].T) & (d1[:, i].T <= e.d[1] + 1e-5))[:, proven])
            if part == "x":
                assert np.all(((e.h[0] - 1e-3 <= d2[:, i].T) & (d2[:, i].T <= e.h[1] + 1e-3))[:, proven])
    # the centre enclosure is as tight as the float solution (the Newton residual)
    assert max(float(np.max((qi.c.hi - qi.c.lo)[proven])) for qi in q) < 1e-9


def test_interval_namespace_gives_the_point_enclosure():
    chain, lo, hi = CHAINS["hexapod"]
    pts = np.array([[74.0, 0.0, 0.0], [60.0, 30.0, 20.0]])
    q = chain.angles(ia.MATH, *ia.variables(pts, pts, order=1))
    ref = _float_ik(chain, pts)
    for i, qi in enumerate(q):
        assert np.all((qi.lo <= ref[:, i] + 1e-12) & (ref[:, i] - 1e-12 <= qi.hi)) and np.all(qi.hi - qi.lo < 1e-10)
        assert qi.order == 1 and qi.d[0].shape == (3, 2)


def test_a_cell_with_a_singular_pose_is_refused_naming_it():
    # a 50 + 30 mm arm: at (80, 0) the elbow is straight, the Jacobian singular
    chain = _planar(ranges=((-170, 170), (0, 170)))
    lo, hi = np.array([[70.0, -2.0], [40.0, 0.0]]), np.array([[80.0, 2.0], [41.0, 1.0]])
    with pytest.raises(ChainEnclosureError, match=r"^the chain's IK is not enclosed over the targets \(x in \[70, 80\], "
                                                  r"z in \[-2, 2\]\): the Krawczyk test K\(Q\) inside Q failed after 6 "
                                                  r"inflations of Q \(the Jacobian is near-singular over the cell, or "
                                                  r"the cell is too large\)$"):
        chain.angles(cn.MATH, *cn.variables(lo, hi))
    with ia.lenient():      # the certifier's mode: the cell gets NaN bounds (it is split), the other one not
        q = chain.angles(cn.MATH, *cn.variables(lo, hi))
    assert np.isnan(q[0].x.lo[0]) and not np.isnan(q[0].x.lo[1])


def test_a_centre_off_the_home_branch_is_named():
    chain = _planar(60, 30)          # the path from the home tip to (-50, 10) crosses the folded pose
    p = np.array([[-50.0, 10.0]])
    with pytest.raises(ChainEnclosureError, match=r"^the chain's IK is not enclosed over the targets \(x in \[-50, -50\], "
                                                  r"z in \[10, 10\]\): the Newton IK continued from the home pose does "
                                                  r"not reach the centre on the home pose's branch$"):
        chain.angles(ia.MATH, *ia.variables(p, p, order=1))


def _chain_robot(chain, tolerance=0.5):
    """A robot with ``chain`` and an identity calibration (pulse = angle in deg, 1 tick per pu)."""
    n = len(chain.joints)
    return SimpleNamespace(
        geometry=chain, servos=chain.servos, fit=SimpleNamespace(tolerance_pu=tolerance),
        workspace=SimpleNamespace(inputs=tuple(SimpleNamespace(name=k) for k in chain.inputs)),
        joint_calibration=Calibration.linear((0.0,) * n, (1,) * n, neutral_pulse_pu=0.0, pu_per_degree=1.0))


def _zero_plan(lo, hi):
    """P = 0 for the servo s1 of a chain with inputs x in [lo[0], hi[0]], z in [lo[1], hi[1]]."""
    b = PlanBuilder([PlanInput("x", "mm", 2, int(lo[0] * 4), int(hi[0] * 4), 10, True),
                     PlanInput("z", "mm", 2, int(lo[1] * 4), int(hi[1] * 4), 10, True)])
    acc = b.align(b.const(0.0, 0), 0)
    return b.build([PlanOutput("s1", acc, acc, "ticks", 1.0)])


def test_certify_refuses_a_box_with_a_singular_pose_naming_the_cell():
    robot = _chain_robot(_planar(ranges=((-170, 170), (0, 170))))
    with pytest.raises(UnboundedCellError, match=r"^servo s1: no finite error bound over the cell \(x in \[[\d.]+, [\d.]+\], "
                                                 r"z in \[-?[\d.]+, -?[\d.]+\]\) once the cell budget is spent: the "
                                                 r"chain's IK is not enclosed there: the Krawczyk test K\(Q\) inside Q "
                                                 r"failed after 6 inflations of Q \(the Jacobian is near-singular over "
                                                 r"the cell, or the cell is too large\)$"):
        certify(robot, _zero_plan((60, -4), (80, 4)), max_cells=300, target_pu=1e-3)


def test_certify_bounds_a_chain_plan_like_its_own_error():
    """P = 0 against the planar arm's shoulder: the certified bound is sup |s1| over the box
    (a box off the singular poses)."""
    chain = _planar(ranges=((-170, 170), (0, 170)))
    robot = _chain_robot(chain)
    axes = np.meshgrid(np.linspace(40, 70, 61), np.linspace(-20, 20, 81), indexing="ij")
    sampled = float(np.max(np.abs(chain.ik(*axes)[0])))
    cert = certify(robot, _zero_plan((40, -20), (70, 20)), max_cells=20_000, target_pu=sampled + 0.05)
    s = cert.servos[0]
    assert s.converged and sampled <= s.approximation_pu <= sampled + 0.05


def test_the_same_plan_is_certified_alike_against_the_cylinder_chain(robot, plan):
    """The default plan (cylinder-leg) against the cylinder leg as a chain, on a small box
    of the workspace: both certify it within the tolerance, with bounds within 10 % of each
    other (0.424 / 0.433 / 0.437 pu against 0.440 / 0.433 / 0.437 pu, after 336 / 5402 / 1606
    and 3296 / 23136 / 18194 evaluated cells)."""
    chain_robot = parse_robot(_robot_data("cylinder-leg", CYLINDER_CHAIN))
    inputs = {i.name: i for i in plan.inputs}
    small = dataclasses.replace(plan, inputs=[dataclasses.replace(
        inputs[k], lo=int(lo * 2 ** inputs[k].frac), hi=int(hi * 2 ** inputs[k].frac))
        for k, (lo, hi) in (("r", (10, 30)), ("theta", (-20, 20)), ("z", (10, 30)))])
    a, b = certify(robot, small), certify(chain_robot, small)
    a.check(robot.fit.tolerance_pu)
    b.check(robot.fit.tolerance_pu)
    for s, t in zip(a.servos, b.servos):
        assert s.converged and t.converged and abs(t.approximation_pu / s.approximation_pu - 1) < 0.1, (s, t)


@pytest.mark.long
def test_hexapod_chain_certifies_the_closed_form_plan_alike(tmp_path_factory):
    """The hexapod-leg preset's plan against the same leg as a chain, at the full default
    budget: both certified within the tolerance, the bounds within 1 % of each other."""
    from helpers import shared_fit
    closed = load_preset("hexapod-leg")
    plan = shared_fit(tmp_path_factory, "hexapod-leg", closed).plan
    chain_robot = parse_robot(_robot_data("hexapod-leg", HEXAPOD_CHAIN))
    t0 = time.process_time()
    cert = certify(chain_robot, plan)
    cert.check(closed.fit.tolerance_pu)
    stored = {s["name"]: s["approximation_pu"] for s in plan.meta["certificate"]["servos"]}
    for s in cert.servos:
        assert stored[s.name] <= s.approximation_pu <= 1.01 * stored[s.name], (s.name, stored[s.name], s)
    print(f"chain certification of the closed-form plan: {time.process_time() - t0:.1f} s CPU")


@pytest.mark.long
def test_hexapod_chain_is_fitted_and_certified_end_to_end():
    """``fit_robot`` on the hexapod leg as a chain, at the preset's tolerance: certified within
    it, every servo converged, and the bound at least the error sampled on >= 10**6 points."""
    from ikseries.accuracy import measure
    from ikseries.fit.fitter import fit_robot
    robot = parse_robot(_robot_data("hexapod-leg", HEXAPOD_CHAIN))
    plan = fit_robot(robot).plan
    sampled = measure(robot, plan)["servos"]
    for s in plan.meta["certificate"]["servos"]:
        assert s["converged"] and sampled[s["name"]]["total"] <= s["total_pu"] <= robot.fit.tolerance_pu, s
