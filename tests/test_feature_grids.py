"""Cells of computed features (fit.table_entries >= FEATURE_GRID_ENTRIES): the cut, the fit,
the certificate and the hardware."""
import dataclasses

import numpy as np
import pytest
from helpers import shared_fit, simulate_bit_exact

from ikseries.fit.features import FEATURE_GRID_ENTRIES, Cut, CutGrid, FeatureCut
from ikseries.fit.structure import FeatureSet
from ikseries.hdl.evaluator import PlanEvaluator
from ikseries.robot import RobotError, load_preset, with_fit
from ikseries.robot_parts import TABLE_ENTRIES, FitOptions
from ikseries.sim.targets import corner_targets, random_targets


def test_feature_cut_cells_and_offsets():
    cut = FeatureCut(0, "rho2", 2)                  # 8 cells of 1/4 over [-1, 1)
    assert cut.cells == cut.entries == 8 and cut.cuts == (cut,) and cut.port is None
    v = np.array([-1.0, -0.76, -0.75, 0.1, 0.999, 1.0])
    sel, off = cut.offsets(v, 0)
    assert sel.tolist() == [0, 1] and off.tolist() == pytest.approx([-1.0, 0.92])
    sel, off = cut.offsets(v, 7)                     # the last cell holds the range's top
    assert sel.tolist() == [4, 5] and off.tolist() == pytest.approx([0.992, 1.0])


def test_a_cell_holding_one_face_of_samples_only_is_widened():
    """A cell is fitted on its own rows only if they are enough and not all on one curve of its
    cut variables: samples of the cylinder's rim face (x**2 + y**2 = r**2) leave a fit free
    across the rim, where the cell still holds targets."""
    from ikseries.fit.search import MIN_CELL_ROWS, Rows, _spread
    rng = np.random.default_rng(1)
    cuts = (FeatureCut(0, "x", 4), FeatureCut(1, "y", 4))
    phi = rng.uniform(0.1, 0.2, 200)
    z = rng.uniform(-1, 1, 200)
    rim = np.column_stack([np.cos(phi) * 0.9, np.sin(phi) * 0.9, z])
    inside = np.column_stack([rng.uniform(-1, 1, (200, 2)), z])
    assert not _spread(Rows(rim, z), cuts)
    assert _spread(Rows(np.vstack([rim, inside[:20]]), np.r_[z, z[:20]]), cuts)
    assert not _spread(Rows(inside[:MIN_CELL_ROWS - 1], z[:MIN_CELL_ROWS - 1]), cuts)
    assert _spread(Rows(inside[:MIN_CELL_ROWS], z[:MIN_CELL_ROWS]), cuts)


def test_a_feature_set_cut_in_cells_of_a_feature_and_a_port():
    fs = FeatureSet("radial", ("rho2", "z"), ("any", "even"))
    port = type("P", (), {"name": "z", "lo": 0, "hi": 255})()
    g = fs.feature_piecewise(0, 3, (1, port, 4))
    assert isinstance(g.cut, CutGrid) and isinstance(g.cut.a, FeatureCut) and isinstance(g.cut.b, Cut)
    assert g.allowed == ("any", "any") and g.cut.cells == 16 * 4
    assert g.structure() == "radial, 16x4 cells in rho2 x z"
    rec = g.piecewise_record()
    assert rec["grid"][0] == {"feature": "rho2", "variable": "rho2", "cells": 16, "cell_width": 0.125}
    assert rec["grid"][1]["input"] == "z"
    with pytest.raises(ValueError, match="a cut grid needs two variables, not variable 0 twice"):
        CutGrid(FeatureCut(0, "rho2", 1), FeatureCut(0, "rho2", 2))


@pytest.mark.parametrize("value", [8, 5000, 16.0, True, "64"])
def test_table_entries_must_be_an_integer_in_range(value):
    with pytest.raises(RobotError, match=rf"fit.table_entries must be an integer from 16 to 4096, not {value!r}"):
        FitOptions(table_entries=value).validate()


def test_the_default_table_entries_leave_records_as_they_were():
    assert "table_entries" not in FitOptions().record() and TABLE_ENTRIES == 16
    assert FitOptions(table_entries=64).record()["table_entries"] == 64


@pytest.fixture(scope="module")
def feature_fit(tmp_path_factory):
    robot = with_fit(load_preset("hexapod-leg"), table_entries=FEATURE_GRID_ENTRIES)
    return robot, shared_fit(tmp_path_factory, "hexapod-leg-feature-grids", robot)


def test_radial_servos_take_cells_of_rho2_and_fewer_multipliers(feature_fit, tmp_path_factory):
    """The femur and tibia of a hexapod leg depend on (rho2, z) only: on a grid over rho2
    (computed and rounded in the plan) and z they need a lower degree and fewer products
    than the small tables allow, and the plan is certified within the tolerance."""
    robot, fit = feature_fit
    small = shared_fit(tmp_path_factory, "hexapod-leg", load_preset("hexapod-leg"))
    cuts = {sf.name: sf.features.cut for sf in fit.servos}
    feature = [n for n, c in cuts.items() if c is not None and any(isinstance(x, FeatureCut) for x in c.cuts)]
    assert feature and all(c.entries <= FEATURE_GRID_ENTRIES for c in cuts.values() if c is not None)
    assert fit.plan.count("mul") < small.plan.count("mul")
    cert = fit.plan.meta["certificate"]
    assert all(s["total_pu"] <= robot.fit.tolerance_pu for s in cert["servos"])


def test_a_feature_grid_plan_is_bit_exact_in_the_pipelined_core(feature_fit):
    _, fit = feature_fit
    plan = fit.plan
    targets = {k: np.concatenate([corner_targets(plan, port_extremes=True)[k], v])
               for k, v in random_targets(plan, 300, np.random.default_rng(5)).items()}
    core = PlanEvaluator(plan)
    res = simulate_bit_exact(core, plan, targets, ready_prob=0.7, valid_prob=0.8, seed=3)
    assert res.latencies.min() == core.latency


def test_a_feature_grid_plan_is_deterministic(feature_fit):
    from ikseries.fit.fitter import fit_robot
    robot, fit = feature_fit
    again = fit_robot(dataclasses.replace(robot))
    assert again.plan.dumps() == fit.plan.dumps()


@pytest.mark.parametrize("entries", [16, 1024])
def test_a_long_table_coordinate_stage_is_built_for_depth(entries):
    """With long tables the cylindrical stage multiplies R * 2D (from the input) by cos beside
    R cos, and keeps no clamp that saves no bit: rho2 is two stages after cos, not four."""
    from ikseries.fit.features import CylindricalStage
    from ikseries.fit.plan import PlanBuilder
    from ikseries.fit.ports import plan_inputs
    robot = with_fit(load_preset("cylinder-leg"), table_entries=entries)
    stage = CylindricalStage(robot, 1e-6, table=True)
    b = PlanBuilder(plan_inputs(robot))
    stage.build(b, 16, 16)
    rho2 = stage._rho2_node(b)
    clamps = [n for n in b.nodes if n.op == "clamp" and b.nodes[n.args[0]].op != "input"]
    gap = b.stage(rho2) - b.stage(stage._cos)
    assert (gap, len(clamps)) == ((2, 0) if entries >= FEATURE_GRID_ENTRIES else (3, 2))
