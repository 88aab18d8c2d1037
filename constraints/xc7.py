"""Xilinx 7-series: the family and its reference part, the XC7A35T (synthesis only).

Capacities from the 7-series overview (Xilinx DS180): the XC7A35T has 20800 LUT6, 41600 FF,
90 DSP48E1 (25 x 18 signed) and 50 RAMB36 (counted as 100 RAMB18). nextpnr does not place
this family here.
"""
from __future__ import annotations

from .facts import Family, Part

__all__ = ["FAMILY", "PARTS", "PNR_DEVICES", "PRIMITIVES"]

FAMILY = Family(
    name="xc7", title="Xilinx 7-series", label="xc7", dsp=(25, 18), dsp_cell="DSP48E1",
    yosys="synth_xilinx -family xc7 -flatten",
    rules=(("LUT", r"LUT[1-6]|LUT6_2|INV"),
           ("FF", r"FD(RE|SE|CE|PE|RSE|CPE)(_1)?|LD(CE|PE|CPE)"),
           ("carry", r"CARRY4|CARRY8|MUXCY|XORCY"),
           ("DSP", r"DSP48\w*|MULT18X18\w*"),
           ("BRAM", r"RAMB\w+"),
           ("LUTRAM", r"RAM\d+X\d+\w*|RAM(32|64)M\d*|SRL\w+"),
           ("mux", r"MUXF[5-9]"),
           ("io", r"I?BUF\w*|OBUF\w*|IOBUF\w*|BUFG\w*|BUFH\w*")),
    carry_cell="CARRY4", carry_bits=4, lut_inputs=6)

XC7A35T = Part("xc7a35t", "xc7", "XC7A35T", (("LUT", 20800), ("FF", 41600), ("DSP", 90), ("BRAM", 100)))

PARTS = (XC7A35T,)
PNR_DEVICES = ()
PRIMITIVES = ()
