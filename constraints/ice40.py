"""Lattice iCE40 UltraPlus: the family, the iCE40UP5K and its SG48 package.

Capacities from the iCE40 UltraPlus family data sheet (Lattice FPGA-DS-02008): the iCE40UP5K
has 5280 logic cells (one LUT4 + one FF each, so LUT and FF are each checked against 5280),
8 DSP blocks (SB_MAC16, 16 x 16 signed), 30 EBR (4 kbit) and 4 SPRAM (256 kbit).
"""
from __future__ import annotations

from .facts import Family, Nextpnr, Part, PnrDevice

__all__ = ["FAMILY", "PARTS", "PNR_DEVICES", "PRIMITIVES"]

FAMILY = Family(
    name="ice40", title="iCE40UP5K", label="iCE40", dsp=(16, 16), dsp_cell="SB_MAC16",
    yosys="synth_ice40 -dsp",
    rules=(("LUT", r"SB_LUT4"),
           ("FF", r"SB_DFF\w*"),
           ("carry", r"SB_CARRY"),
           ("DSP", r"SB_MAC16"),
           ("BRAM", r"SB_RAM40_4K\w*"),
           ("SPRAM", r"SB_SPRAM256KA"),
           ("io", r"SB_IO\w*|SB_GB\w*")),
    carry_cell="SB_CARRY", carry_bits=1,
    nextpnr=Nextpnr("ice40", "pins.pcf", ("--pcf", "pins.pcf", "--pcf-allow-unconstrained"),
                    "set_io {port} {pin}\n"),
    lc_note="iCE40 logic cells (LUT4 + FF + carry each)")

UP5K = Part("ice40-up5k", "ice40", "iCE40UP5K",
            (("LUT", 5280), ("FF", 5280), ("DSP", 8), ("BRAM", 30), ("SPRAM", 4)))

PARTS = (UP5K,)

_cap = UP5K.capacities
#: clock pin 35: the iCEBreaker's 12 MHz oscillator, a global buffer input
PNR_DEVICES = (
    PnrDevice("ice40-up5k-sg48", "ice40", "Lattice iCE40UP5K, SG48 package",
              ("--up5k", "--package", "sg48"), 39, "35",
              (("LUT", None, _cap["LUT"]), ("FF", r"SB_DFF\w*", _cap["FF"]), ("DSP", r"SB_MAC16", _cap["DSP"]),
               ("BRAM", r"SB_RAM40_4K\w*", _cap["BRAM"]), ("SPRAM", r"SB_SPRAM256KA", _cap["SPRAM"])),
              (("LC", "ICESTORM_LC"), ("DSP", "ICESTORM_DSP"), ("BRAM", "ICESTORM_RAM"),
               ("SPRAM", "ICESTORM_SPRAM"), ("IO", "SB_IO")), UP5K.name),
)

PRIMITIVES = ()
