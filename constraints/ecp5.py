"""Lattice ECP5: the family, the LFE5U-25F, its CABGA381 package and the MULT18X18D primitive.

Capacities from the ECP5 family data sheet (Lattice FPGA-DS-02012): the LFE5U-25F has 24288
LUT4 (one FF each), 28 18 x 18 multipliers (MULT18X18D; ALU54B/ALU24B are counted with them
in the ``DSP`` category, 14 ALU54B are checked on their own before place and route) and 56 EBR
(18 kbit). A CCU2C carry cell is a slice in ripple mode: it occupies both of the slice's LUT4s,
so ``LUT`` counts 2 per CCU2C, the way Lattice's map report counts LUT4s ("logic" plus
"ripple") against the device.
"""
from __future__ import annotations

from .facts import Family, Nextpnr, Part, PnrDevice, Primitive, check_operands

__all__ = ["FAMILY", "PARTS", "PNR_DEVICES", "PRIMITIVES"]

FAMILY = Family(
    name="ecp5", title="ECP5", label="ECP5", dsp=(18, 18), dsp_cell="MULT18X18D",
    yosys="synth_ecp5",
    rules=(("LUT", r"LUT4"),
           ("mux", r"PFUMX|L6MUX21"),
           ("FF", r"TRELLIS_FF|FD1[PS]3\w+"),
           ("carry", r"CCU2C"),
           ("DSP", r"MULT18X18D|MULT9X9D|ALU54B|ALU24B"),
           ("BRAM", r"DP16KD|PDPW16KD"),
           ("LUTRAM", r"TRELLIS_DPR16X4|DPR16X4C|SPR16X4C"),
           ("io", r"TRELLIS_IO|[IO]B\w*|BB\w*|DCCA|DCSC|[IO]LVDS")),
    carry_cell="CCU2C", carry_bits=2, ripple_luts=2,
    nextpnr=Nextpnr("ecp5", "pins.lpf", ("--lpf", "pins.lpf", "--lpf-allow-unconstrained"),
                    'LOCATE COMP "{port}" SITE "{pin}";\nIOBUF PORT "{port}" IO_TYPE=LVCMOS33;\n'),
    lc_note="ECP5 LUT4 slots including carry halves")

LFE5U_25F = Part("ecp5-25f", "ecp5", "LFE5U-25F", (("LUT", 24288), ("FF", 24288), ("DSP", 28), ("BRAM", 56)))

PARTS = (LFE5U_25F,)

_cap = LFE5U_25F.capacities
#: clock pin G2: the ULX3S's 25 MHz oscillator
PNR_DEVICES = (
    PnrDevice("ecp5-25f-cabga381", "ecp5", "Lattice ECP5 LFE5U-25F, CABGA381 package",
              ("--25k", "--package", "CABGA381"), 197, "G2",
              (("LUT", None, _cap["LUT"]), ("FF", r"TRELLIS_FF|FD1[PS]3\w+", _cap["FF"]),
               ("DSP", r"MULT18X18D", _cap["DSP"]), ("ALU54B", r"ALU54B", 14),
               ("BRAM", r"DP16KD|PDPW16KD", _cap["BRAM"])),
              (("LC", "TRELLIS_COMB"), ("FF", "TRELLIS_FF"), ("DSP", "MULT18X18D"), ("BRAM", "DP16KD"),
               ("IO", "TRELLIS_IO")), LFE5U_25F.name),
)


def mult18x18d(m, a, b, product, enable):
    """A MULT18X18D computing ``product = a * b`` two enabled clock edges later: its input
    (A, B) and output registers clocked by the sync domain, clock enable ``enable``, cleared
    synchronously by the domain's reset. ``a`` and ``b`` (at most 18 bits signed) and
    ``product`` are connected to its ports in ``m``'s comb domain; returns the ``Instance``."""
    from amaranth.hdl import ClockSignal, Const, Instance, ResetSignal, Signal, signed
    check_operands("MULT18X18D", 18, 36, a, b, product)
    sa, sb, out = Signal(signed(18)), Signal(signed(18)), Signal(36)
    m.d.comb += [sa.eq(a), sb.eq(b), product.eq(out.as_signed())]
    regs = {f"p_REG_{r}_{f}": v for r in ("INPUTA", "INPUTB", "OUTPUT")
            for f, v in (("CLK", "CLK0"), ("CE", "CE0"), ("RST", "RST0"))}
    return Instance(
        "MULT18X18D", **regs, p_REG_INPUTC_CLK="NONE", p_REG_PIPELINE_CLK="NONE", p_GSR="DISABLED",
        p_CLK0_DIV="ENABLED", p_SOURCEB_MODE="B_SHIFT", p_RESETMODE="SYNC",
        **{f"i_A{k}": sa[k] for k in range(18)}, **{f"i_B{k}": sb[k] for k in range(18)},
        **{f"i_C{k}": Const(0, 1) for k in range(18)},
        i_SIGNEDA=Const(1, 1), i_SIGNEDB=Const(1, 1), i_SOURCEA=Const(0, 1), i_SOURCEB=Const(0, 1),
        i_CLK0=ClockSignal(), i_CE0=enable, i_RST0=ResetSignal(),
        **{f"o_P{k}": out[k] for k in range(36)})


PRIMITIVES = (Primitive("MULT18X18D", "ecp5", 18, 36, "MULT18X18D.v", mult18x18d),)
