"""The ``Geometry`` interface: the reference kinematics of one limb type, and its registry.

A geometry is a frozen dataclass whose float fields are the ``[geometry]`` fields of a robot
description (each must be > 0 unless named in ``signed_fields``); its constructor may raise
``ValueError("<field> must be ..., not ...")`` for inconsistent values. It gives, in float64:

- ``ik(*coords)``: joint angles in degrees, one array per servo, for arrays of target
  coordinates in the order of ``inputs``; raises :class:`ikseries.kinematics.UnreachableError`
  (one line naming the first bad target) where the limb cannot reach or a joint leaves its range;
- ``angles(xp, *coords)``: the same IK as a pure formula over a math namespace ``xp`` (``sqrt``,
  ``atan2``, ``acos``, ... as in :data:`ikseries.kinematics.NUMPY_MATH`), so that the certifier
  and the reachability proof run it on intervals with derivatives;
- ``fk(*angles)``: the tip for joint angles (exact, for tests and reports);
- ``workspace_error(name, lo, hi)``: a message for a workspace range it cannot take, else None.

Cylindrical geometries (``coordinates = "cylindrical"``) also map their targets to a Cartesian
frame (:class:`CylindricalGeometry`), which the fit's coordinate stage computes in hardware.

The closed-form geometries also take :class:`ikseries.joints.JointConventions` (the optional
``joint_ranges``, ``zero_offsets`` and ``angle_directions`` fields): their ``ik``, ``angles`` and
``fk`` then work in each servo's own angles, and ``joint_ranges`` is what ``ik`` and the
reachability proof check.

Geometries register under the entry-point group ``ikseries.geometries`` (``pyproject.toml``),
by the name a robot description gives as ``geometry.type``. Adding a geometry is one module with
a subclass of :class:`Geometry` plus one line in ``pyproject.toml``; its tests check ``ik``
against ``fk`` and its reachability errors.
"""
from __future__ import annotations

import abc
from typing import ClassVar

from .plugins import load_registered, registered

__all__ = ["ENTRY_POINT_GROUP", "Geometry", "CylindricalGeometry", "geometry_names", "geometry_class",
           "geometry_type"]

ENTRY_POINT_GROUP = "ikseries.geometries"


class Geometry(abc.ABC):
    """Reference kinematics of one limb type (see the module docstring)."""

    #: "cartesian" (targets are frame coordinates) or "cylindrical" (see CylindricalGeometry)
    coordinates: ClassVar[str] = "cartesian"
    #: target input names (workspace fields, port suffixes) and their units
    inputs: ClassVar[tuple[str, ...]]
    input_units: ClassVar[tuple[str, ...]]
    #: servo names (port suffixes) and what each joint is
    servos: ClassVar[tuple[str, ...]]
    servo_names: ClassVar[tuple[str, ...]]
    #: [geometry] fields that may be zero or negative (an angle, an offset)
    signed_fields: ClassVar[tuple[str, ...]] = ()

    @abc.abstractmethod
    def angles(self, xp, *coords) -> tuple:
        """Joint angles (deg) as a formula over the math namespace ``xp``."""

    @abc.abstractmethod
    def ik(self, *coords):
        """Joint angles (deg) per servo for target arrays; raises UnreachableError."""

    @abc.abstractmethod
    def fk(self, *angles) -> tuple:
        """Target coordinates of joint angles (deg)."""

    def workspace_error(self, name: str, lo: float, hi: float) -> str | None:
        """A message for a workspace range of input ``name`` this geometry cannot take, or None."""
        return None


class CylindricalGeometry(Geometry):
    """A geometry whose targets are cylindrical coordinates around a neutral point; the fit's
    coordinate stage maps them to the Cartesian frame these methods define."""

    coordinates = "cylindrical"
    cartesian_names: ClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def to_cartesian(self, *coords) -> tuple:
        """Frame coordinates of targets."""

    @abc.abstractmethod
    def from_cartesian(self, *frame) -> tuple:
        """Targets of frame coordinates."""

    @abc.abstractmethod
    def angles_cartesian(self, xp, *frame) -> tuple:
        """Joint angles (deg) of frame coordinates, as a formula over ``xp``."""

    @abc.abstractmethod
    def ik_cartesian(self, *frame):
        """Joint angles (deg) of frame coordinate arrays; raises UnreachableError."""

    @abc.abstractmethod
    def fk_cartesian(self, *angles) -> tuple:
        """Frame coordinates of joint angles (deg)."""


def geometry_names() -> list[str]:
    """``geometry.type`` names of the registered geometries, sorted."""
    return list(registered(ENTRY_POINT_GROUP))


def geometry_class(name) -> type[Geometry]:
    """The registered geometry class of ``geometry.type = name``."""
    return load_registered(ENTRY_POINT_GROUP, name, "geometry.type")


def geometry_type(geometry: Geometry) -> str:
    """The registered name of ``geometry``'s class."""
    for name, ep in registered(ENTRY_POINT_GROUP).items():
        if type(geometry) is ep.load():
            return name
    raise ValueError(f"geometry must be an instance of a registered geometry class, not {geometry!r}")
