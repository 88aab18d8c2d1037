"""Every preset fits within its tolerance and its plan runs bit-exactly in the RTL."""
import numpy as np
import pytest

from ikseries.accuracy import measure
from ikseries.build import build
from ikseries.fit.fitter import fit_robot, output_multipliers
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.robot import load_preset
from ikseries.sim import golden
from ikseries.sim.amaranth_sim import simulate_leg
from ikseries.sim.targets import corner_targets, random_targets

OTHER_PRESETS = ["hexapod-leg", "quadruped-hind", "quadruped-fore"]


@pytest.mark.parametrize("name", OTHER_PRESETS)
def test_preset_fits_within_tolerance_and_simulates_bit_exact(name):
    robot = load_preset(name)
    plan, fits = fit_robot(robot)
    assert [o.name for o in plan.outputs] == list(robot.servos)
    acc = measure(robot, plan)
    assert acc["points"] >= min(1_000_000, np.prod([i.hi - i.lo + 1 for i in robot.workspace.inputs]))
    for s, e in acc["servos"].items():
        assert e["total"] <= robot.fit.tolerance_pu, (s, e)
    # the fit certifies the error over the continuous box (and refuses a plan that fails)
    for s in plan.meta["certificate"]["servos"]:
        assert s["converged"] and s["total_pu"] <= robot.fit.tolerance_pu, s
        assert s["approximation_pu"] >= acc["servos"][s["name"]]["approximation"], s
    assert all(m <= 100 for m in output_multipliers(plan).values())
    t = {k: np.concatenate([c, r]) for (k, c), r in
         zip(corner_targets(plan, port_extremes=True).items(), random_targets(plan, 200, 7).values())}
    core = PlanEvaluator(plan)
    res = simulate_leg(core, t)
    exp = golden.outputs(plan, t)
    for s in exp:
        assert np.array_equal(res.outputs[s], exp[s]), s
    assert set(res.latencies.tolist()) == {core.latency}


def test_planar_arm_builds_end_to_end(tmp_path, tmp_path_factory, monkeypatch):
    """The whole `ikseries build` pipeline on a 2-input, 2-servo robot (no synthesis/cocotb),
    from the run's fit of that robot (the build's own fit step is what the cylinder-leg builds
    test)."""
    import ikseries.steps
    from helpers import shared_fit
    robot = load_preset("planar-arm")
    fit = shared_fit(tmp_path_factory, "planar-arm", robot)
    monkeypatch.setattr(ikseries.steps, "fit_robot", lambda r, progress, **options: fit)
    rep = build(robot, tmp_path / "arm", synth=False, cocotb=[], progress=lambda m: None)
    assert all(s["error_pu"]["total"] <= robot.fit.tolerance_pu for s in rep.record()["servos"])
    assert (tmp_path / "arm" / "planar_arm_core.v").read_text().count("pwm_s") >= 2
