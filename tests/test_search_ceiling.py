"""The fitter's cost ceiling: no structure above ``MAX_COST`` multipliers is tried, and where no
whole polynomial fits under it, cells are still searched before the fit is refused."""
import pytest

import ikseries.fit.search as search
from ikseries.fit.fitter import FitError, fit_robot
from ikseries.robot import load_preset


def test_cells_are_cut_where_no_whole_polynomial_fits_under_the_ceiling(monkeypatch):
    # planar-arm's servos win with 3 cells in y at 13 multipliers; no whole polynomial costs <= 14
    monkeypatch.setattr(search, "MAX_COST", 14)
    seen = []
    plan = fit_robot(load_preset("planar-arm"), seen.append, jobs=1, certified=False).plan
    assert [s["multipliers"] for s in plan.meta["servos"]] == [13, 13]
    assert all(s["piecewise"]["cells"] == 3 for s in plan.meta["servos"])
    assert sum("no whole polynomial of at most 14 multipliers" in m for m in seen) == 2


def test_a_ceiling_below_every_structure_refuses_the_fit(monkeypatch):
    monkeypatch.setattr(search, "MAX_COST", 3)
    with pytest.raises(FitError, match=r"servo s1: no polynomial of at most 3 multipliers \(total degree "
                                       r"<= 12, whole or in cells\) reaches the approximation budget"):
        fit_robot(load_preset("planar-arm"), jobs=1, certified=False)
