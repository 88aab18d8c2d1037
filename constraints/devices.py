"""The registry of device facts: every family, part, place-and-route target and primitive.

Collected from the family modules listed in :data:`FAMILY_MODULES`, in that order (which is
the order of every list and error message built from the registry). Other modules ask here
for a DSP size, a capacity, a Yosys command, nextpnr arguments or a primitive; a family name
the user chooses (``hardware.dsp = "ecp5"``) is the key.

Resource categories (:data:`CATEGORIES`) as each family's rules sort the Yosys cells:

========  ====================  ==========================  ===============================
category  iCE40 (UP5K)          ECP5                        Xilinx 7-series
========  ====================  ==========================  ===============================
LUT       SB_LUT4               LUT4, + 2 per CCU2C         LUT1..LUT6, LUT6_2, INV
FF        SB_DFF*               TRELLIS_FF, FD1P3*/FD1S3*   FD*E, FD*E_1, FDRSE, FDCPE, LD*
carry     SB_CARRY              CCU2C (2 bits each)         CARRY4 (4 bits each)
DSP       SB_MAC16              MULT18X18D, ALU54B, ALU24B  DSP48E1
BRAM      SB_RAM40_4K* (EBR)    DP16KD, PDPW16KD            RAMB18E1, RAMB36E1
SPRAM     SB_SPRAM256KA         -                           -
LUTRAM    -                     TRELLIS_DPR16X4             RAM32M/RAM64M/RAMnnX*, SRL*
mux       -                     PFUMX, L6MUX21              MUXF7, MUXF8
io        SB_IO*, SB_GB*        TRELLIS_IO, IB/OB/BB*, DCCA IBUF/OBUF/IOBUF/OBUFT, BUFG*
========  ====================  ==========================  ===============================

``LUT`` counts the look-up tables the logic occupies, the measure of the parts' capacity. On
the iCE40 and the 7-series an adder's sum bits are LUTs of their own beside the hard carry
cells; an ECP5 CCU2C occupies both LUT4s of its slice (:attr:`Family.ripple_luts`).
``synth_xilinx`` inserts I/O and clock buffers for the top module (hence "io"); the Lattice
scripts do not. ``mux`` cells are hard wide-function multiplexers that use no extra LUTs.
"""
from __future__ import annotations

from . import ecp5, ice40, xc7
from .facts import CATEGORIES, Family, Nextpnr, Part, PnrDevice, Primitive

__all__ = ["CATEGORIES", "FAMILY_MODULES", "FAMILIES", "PARTS", "PNR_DEVICES", "PRIMITIVES", "FIT_DEVICES",
           "Family", "Nextpnr", "Part", "PnrDevice", "Primitive", "family", "part", "pnr_device", "primitive",
           "dsp_size", "reference_part", "family_primitives", "multiplier_families", "pnr_families", "lookup"]

#: the family modules, each defining FAMILY, PARTS, PNR_DEVICES and PRIMITIVES
FAMILY_MODULES = (ice40, ecp5, xc7)

#: family name -> :class:`Family` (the synthesis targets, the ``hardware.dsp`` choices)
FAMILIES: dict[str, Family] = {m.FAMILY.name: m.FAMILY for m in FAMILY_MODULES}
#: part name -> :class:`Part` (the ``hardware.fit_device`` choices)
PARTS: dict[str, Part] = {p.name: p for m in FAMILY_MODULES for p in m.PARTS}
#: place-and-route target name -> :class:`PnrDevice`
PNR_DEVICES: dict[str, PnrDevice] = {d.name: d for m in FAMILY_MODULES for d in m.PNR_DEVICES}
#: primitive name -> :class:`Primitive`
PRIMITIVES: dict[str, Primitive] = {p.name: p for m in FAMILY_MODULES for p in m.PRIMITIVES}
#: part name -> its family name
FIT_DEVICES: dict[str, str] = {name: p.family for name, p in PARTS.items()}


def lookup(table: dict, what: str, name):
    """``table[name]``; ValueError "``what`` must be one of <keys>, not <name>" when absent."""
    if not isinstance(name, str) or name not in table:
        raise ValueError(f"{what} must be one of {', '.join(table)}, not {name!r}")
    return table[name]


def family(name: str) -> Family:
    """The family called ``name`` (one of :data:`FAMILIES`)."""
    return lookup(FAMILIES, "family", name)


def part(name: str) -> Part:
    """The part called ``name`` (one of :data:`PARTS`)."""
    return lookup(PARTS, "part", name)


def pnr_device(name: str) -> PnrDevice:
    """The place-and-route target called ``name`` (one of :data:`PNR_DEVICES`)."""
    return lookup(PNR_DEVICES, "device", name)


def primitive(name: str) -> Primitive:
    """The vendor primitive called ``name`` (one of :data:`PRIMITIVES`)."""
    return lookup(PRIMITIVES, "primitive", name)


def dsp_size(name: str) -> tuple[int, int]:
    """Signed operand widths of one DSP block of family ``name``."""
    return family(name).dsp


def reference_part(name: str) -> Part:
    """The part a family's synthesis results are checked against: its first in :data:`PARTS`."""
    family(name)
    return next(p for p in PARTS.values() if p.family == name)


def family_primitives(name: str, role: str | None = None) -> tuple[Primitive, ...]:
    """The vendor primitives of family ``name`` the exported Verilog may instantiate (those of
    :attr:`Primitive.role` ``role``, or all)."""
    family(name)
    return tuple(p for p in PRIMITIVES.values() if p.family == name and role in (None, p.role))


def multiplier_families() -> tuple[str, ...]:
    """The families with a DSP multiplier primitive (the ``dsp_registers`` choices)."""
    return tuple(dict.fromkeys(p.family for p in PRIMITIVES.values() if p.role == "multiplier"))


def pnr_families() -> tuple[Family, ...]:
    """The families nextpnr places and routes."""
    return tuple(f for f in FAMILIES.values() if f.nextpnr is not None)
