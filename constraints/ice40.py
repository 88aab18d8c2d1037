"""Lattice iCE40 UltraPlus: the family, the iCE40UP5K, its SG48 package and the SB_MAC16 primitive.

Capacities from the iCE40 UltraPlus family data sheet (Lattice FPGA-DS-02008): the iCE40UP5K
has 5280 logic cells (one LUT4 + one FF each, so LUT and FF are each checked against 5280),
8 DSP blocks (SB_MAC16, 16 x 16 signed), 30 EBR (4 kbit) and 4 SPRAM (256 kbit).
"""
from __future__ import annotations

from .facts import Family, Nextpnr, Part, PnrDevice, Primitive, check_operands

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


#: SB_MAC16 parameters of :func:`sb_mac16`: a signed 16 x 16 multiplier with its A and B input
#: registers and the 32-bit product register of the 16 x 16 pipeline (``rH``) on the output;
#: the C/D holding registers, the 8 x 8 product registers and the accumulator's output
#: registers are bypassed (Lattice TN1295, the iCE40 DSP function usage guide; Yosys's
#: ``ice40/cells_sim.v``)
SB_MAC16_PARAMETERS = {
    "NEG_TRIGGER": 0, "C_REG": 0, "A_REG": 1, "B_REG": 1, "D_REG": 0,
    "TOP_8x8_MULT_REG": 0, "BOT_8x8_MULT_REG": 0,
    "PIPELINE_16x16_MULT_REG1": 0, "PIPELINE_16x16_MULT_REG2": 1,
    "TOPOUTPUT_SELECT": 3, "TOPADDSUB_LOWERINPUT": 0, "TOPADDSUB_UPPERINPUT": 0, "TOPADDSUB_CARRYSELECT": 0,
    "BOTOUTPUT_SELECT": 3, "BOTADDSUB_LOWERINPUT": 0, "BOTADDSUB_UPPERINPUT": 0, "BOTADDSUB_CARRYSELECT": 0,
    "MODE_8x8": 0, "A_SIGNED": 1, "B_SIGNED": 1,
}
_PARAM_BITS = {"TOPOUTPUT_SELECT": 2, "TOPADDSUB_LOWERINPUT": 2, "TOPADDSUB_CARRYSELECT": 2,
               "BOTOUTPUT_SELECT": 2, "BOTADDSUB_LOWERINPUT": 2, "BOTADDSUB_CARRYSELECT": 2}


def sb_mac16(m, a, b, product, enable):
    """An SB_MAC16 computing ``product = a * b`` two enabled clock edges later: its A and B
    input registers and its 16 x 16 product register (:data:`SB_MAC16_PARAMETERS`), clocked
    by the sync domain, clock enable ``enable``. The registers are cleared by the domain's
    reset on IRSTTOP/IRSTBOT, which the SB_MAC16 applies asynchronously: at every clock edge
    the same values as the fabric's synchronously reset registers, the reset being synchronous
    to the clock. ``a`` and ``b`` (at most 16 bits signed) and ``product`` are connected to its
    ports in ``m``'s comb domain; returns the ``Instance``."""
    from amaranth.hdl import ClockSignal, Const, Instance, ResetSignal, Signal, signed
    check_operands("SB_MAC16", 16, 32, a, b, product)
    sa, sb, out = Signal(signed(16)), Signal(signed(16)), Signal(32)
    m.d.comb += [sa.eq(a), sb.eq(b), product.eq(out.as_signed())]
    params = {f"p_{k}": Const(v, _PARAM_BITS.get(k, 1)) for k, v in SB_MAC16_PARAMETERS.items()}
    zero = Const(0, 1)
    return Instance(
        "SB_MAC16", **params,
        i_CLK=ClockSignal(), i_CE=enable, i_A=sa, i_B=sb, i_C=Const(0, 16), i_D=Const(0, 16),
        **{f"i_{h}HOLD": zero for h in "ABCD"},
        i_IRSTTOP=ResetSignal(), i_IRSTBOT=ResetSignal(), i_ORSTTOP=zero, i_ORSTBOT=zero,
        i_OLOADTOP=zero, i_OLOADBOT=zero, i_ADDSUBTOP=zero, i_ADDSUBBOT=zero,
        i_OHOLDTOP=zero, i_OHOLDBOT=zero, i_CI=zero, i_ACCUMCI=zero, i_SIGNEXTIN=zero,
        o_O=out)


PRIMITIVES = (Primitive("SB_MAC16", "ice40", 16, 32, "SB_MAC16.v", sb_mac16),)
