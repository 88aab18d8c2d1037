"""Generic serial chains of revolute joints: description, exact FK, numeric reference IK.

- :mod:`.frames`: FK, the tip Jacobian and its derivatives as pure formulas over a math namespace;
- :mod:`.model`: the :class:`Chain` geometry (``geometry.type = "chain"`` or ``"urdf"``);
- :mod:`.solve`: damped Newton continued from the home pose;
- :mod:`.checks`: the workspace box check (singularity, branch, second solution);
- :mod:`.enclose`: the certifier's proven enclosure of the IK per cell (a Krawczyk step);
- :mod:`.parse`: the ``[geometry]`` table of a chain, and :mod:`.urdf` for one read from a URDF.
"""
from .model import Chain, Joint, Tool, TARGETS

__all__ = ["Chain", "Joint", "Tool", "TARGETS"]
