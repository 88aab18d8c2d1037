"""The entry-point registry shared by architectures and geometries."""
import re

import pytest

from ikseries.geometry import ENTRY_POINT_GROUP, Geometry, geometry_class, geometry_names, geometry_type
from ikseries.kinematics import CylinderLeg
from ikseries.plugins import load_registered, registered


def test_a_group_lists_its_entry_points_by_name():
    eps = registered(ENTRY_POINT_GROUP)
    assert list(eps) == sorted(eps) == geometry_names()
    assert "cylinder-leg" in eps and eps["cylinder-leg"].load() is CylinderLeg


def test_a_registered_name_loads_its_class():
    assert load_registered(ENTRY_POINT_GROUP, "cylinder-leg", "geometry.type") is CylinderLeg
    assert all(issubclass(geometry_class(n), Geometry) for n in geometry_names())
    assert geometry_type(CylinderLeg()) == "cylinder-leg"


@pytest.mark.parametrize("name", ["hexapod", 3, ["cylinder-leg"], None])
def test_an_unregistered_name_is_one_line_naming_it(name):
    with pytest.raises(ValueError, match=r"^geometry.type must be one of chain, cylinder-leg, hexapod-leg, "
                                         r"planar-arm, quadruped-fore, quadruped-hind, urdf, not " + re.escape(repr(name)) + "$"):
        geometry_class(name)


def test_a_group_without_entry_points_says_so():
    with pytest.raises(ValueError, match=r"^widget must name an entry point of group ikseries.no-such-group "
                                         r"\(none is installed\), not 'x'$"):
        load_registered("ikseries.no-such-group", "x", "widget")
