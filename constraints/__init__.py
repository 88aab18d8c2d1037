"""Device facts and clock constraints of the exported core.

:mod:`~ikseries.constraints.devices` is the one registry of device facts: DSP operand sizes,
cell categorisation for resource counts, Yosys synthesis commands, nextpnr binaries and
arguments, parts with their capacities, place-and-route packages and vendor primitives with
their simulation models. Nothing outside this package names such a fact; it asks the registry
(``devices.family("ecp5").dsp``, ``devices.part("ice40-up5k").capacities``, ...).
:mod:`~ikseries.constraints.timing` writes the SDC/XDC clock constraint.

Adding a device
---------------
Write one module here named for the family (see :mod:`~ikseries.constraints.ecp5`) defining

- ``FAMILY``: a :class:`~ikseries.constraints.facts.Family` (DSP size, Yosys command, cell
  rules, carry cell, nextpnr flavour and pin-file format or None);
- ``PARTS``: its :class:`~ikseries.constraints.facts.Part` tuple (data-sheet capacities; the
  first is the family's reference part), or add a part to an existing family's tuple;
- ``PNR_DEVICES``: :class:`~ikseries.constraints.facts.PnrDevice` entries (package, nextpnr
  arguments, user I/O, clock pin, limits checked before nextpnr), possibly empty;
- ``PRIMITIVES``: :class:`~ikseries.constraints.facts.Primitive` entries whose model files go
  in ``sim/models/`` (package data), possibly empty;

add the module to ``FAMILY_MODULES`` in :mod:`~ikseries.constraints.devices`, and pin its
numbers in ``tests/test_devices.py`` (DSP size, each part's capacity, the categorisation of its
cells). Every choice list (``hardware.dsp``, ``hardware.fit_device``, ``ikseries report
--pnr`` devices, synthesis targets) follows from the registry.
"""
