"""The kinds of device fact: families, parts, place-and-route targets and vendor primitives.

Each family module (:mod:`ikseries.constraints.ice40`, ...) fills these frozen dataclasses with
its own numbers; :mod:`ikseries.constraints.devices` collects them into the registry.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

__all__ = ["CATEGORIES", "Family", "Nextpnr", "Part", "PnrDevice", "Primitive", "check_operands", "dsp_limbs"]

#: resource categories of a synthesised design; every raw Yosys cell falls in exactly one
#: (unknown cells in "other")
CATEGORIES = ("LUT", "FF", "carry", "DSP", "BRAM", "SPRAM", "LUTRAM", "mux", "io", "other")


@dataclass(frozen=True)
class Nextpnr:
    """How nextpnr places and routes a family.

    Parameters
    ----------
    flavour : str
        nextpnr architecture (``nextpnr-<flavour>``, YoWASP package ``yowasp-nextpnr-<flavour>``).
    pin_file : str
        Name of the pin constraint file.
    pin_args : tuple of str
        nextpnr arguments that read ``pin_file`` (and let it place every other pin).
    clock_pin_text : str
        Text of ``pin_file`` placing the clock port ``{port}`` on pin ``{pin}``.
    """
    flavour: str
    pin_file: str
    pin_args: tuple[str, ...]
    clock_pin_text: str

    @property
    def binary(self) -> str:
        return f"nextpnr-{self.flavour}"

    @property
    def package(self) -> str:
        """The YoWASP distribution that provides the WebAssembly build."""
        return f"yowasp-nextpnr-{self.flavour}"

    @property
    def module(self) -> str:
        return f"yowasp_nextpnr_{self.flavour}"

    @property
    def runner(self) -> str:
        """The function of :attr:`module` that runs nextpnr on an argv list."""
        return f"run_nextpnr_{self.flavour}"

    @property
    def env(self) -> str:
        """Environment variable naming a native nextpnr to use instead (split on whitespace)."""
        return f"IKSERIES_NEXTPNR_{self.flavour.upper()}"

    def clock_constraint(self, port: str, pin: str) -> str:
        """Contents of :attr:`pin_file` placing clock ``port`` on ``pin``."""
        return self.clock_pin_text.format(port=port, pin=pin)


@dataclass(frozen=True)
class Family:
    """An FPGA family as synthesis and the evaluators see it.

    Parameters
    ----------
    name : str
        Registry name, the value of ``hardware.dsp`` and the Yosys target name.
    title : str
        Device label of Yosys results (the family's reference part for single-part families).
    label : str
        The family in prose ("ECP5").
    dsp : (int, int)
        Signed operand widths of one DSP multiplier block.
    dsp_cell : str
        Yosys cell of that block.
    yosys : str
        Yosys synthesis command, without ``-top``.
    rules : tuple of (str, str)
        (category of :data:`CATEGORIES`, regex over Yosys cell types) in order; the first full
        match wins.
    carry_cell : str
        Yosys cell of the hard carry chain.
    carry_bits : int
        Adder bits per :attr:`carry_cell`.
    ripple_luts : int
        LUTs each carry cell occupies besides its own cell (ECP5 CCU2C: a slice in ripple mode
        uses both of its LUT4s); counted in ``LUT``.
    nextpnr : Nextpnr or None
        Place and route, None where nextpnr has no such architecture.
    lc_note : str
        What nextpnr's placed logic cell ("LC") is on this family (empty without nextpnr).
    lut_inputs : int
        Inputs of one look-up table (LUT4: 4): a LUT holds a ROM of ``2**lut_inputs`` one-bit words.
    wide_lut_inputs : int
        Inputs of the widest function one logic level builds: LUTs joined by the slice's hard
        multiplexers (``mux`` cells, which cost no LUT and little delay); 0: no such
        multiplexers (:attr:`lut_inputs`). A ROM of at most :attr:`rom_level_words` words is
        read through one level.
    """
    name: str
    title: str
    label: str
    dsp: tuple[int, int]
    dsp_cell: str
    yosys: str
    rules: tuple[tuple[str, str], ...]
    carry_cell: str
    carry_bits: int
    ripple_luts: int = 0
    nextpnr: Nextpnr | None = None
    lc_note: str = ""
    lut_inputs: int = 4
    wide_lut_inputs: int = 0

    @property
    def rom_level_words(self) -> int:
        """Words of the deepest ROM read through one logic level (:attr:`wide_lut_inputs`)."""
        return 1 << (self.wide_lut_inputs or self.lut_inputs)

    def dsp_blocks(self, a_bits: int, b_bits: int) -> int:
        """DSP blocks of one signed ``a_bits`` x ``b_bits`` product: 1 if the operands fit
        :attr:`dsp` (either orientation), else the limb pairs of the split the cores make
        (:func:`dsp_limbs` per operand; the orientation with fewer)."""
        return min(dsp_limbs(a_bits, x) * dsp_limbs(b_bits, y) for x, y in (self.dsp, self.dsp[::-1]))

    def categorise(self, cells: dict[str, int]) -> tuple[dict[str, int], dict[str, int]]:
        """Sort raw ``num_cells_by_type`` into :data:`CATEGORIES`.

        ``$scopeinfo`` is ignored. Returns ``(counts, other_cells)``; ``sum(counts.values())``
        equals the raw total without $scopeinfo plus :attr:`ripple_luts` per carry cell, which
        ``LUT`` includes.
        """
        counts = dict.fromkeys(CATEGORIES, 0)
        other: dict[str, int] = {}
        for name, n in cells.items():
            if name == "$scopeinfo":
                continue
            for cat, rx in self.rules:
                if re.fullmatch(rx, name):
                    counts[cat] += int(n)
                    break
            else:
                counts["other"] += int(n)
                other[name] = other.get(name, 0) + int(n)
        counts["LUT"] += self.ripple_luts * counts["carry"]
        return counts, other


@dataclass(frozen=True)
class Part:
    """A device of a family with its capacities (the vendor's data sheet).

    Parameters
    ----------
    name : str
        Registry name, the value of ``hardware.fit_device``.
    family : str
        Its :class:`Family` name.
    part : str
        The vendor's part name.
    capacity : tuple of (str, int)
        Category of :data:`CATEGORIES` -> how many the part has, for the categories it limits.
    """
    name: str
    family: str
    part: str
    capacity: tuple[tuple[str, int], ...]

    @property
    def capacities(self) -> dict[str, int]:
        return dict(self.capacity)

    def overflows(self, counts: dict) -> dict[str, tuple[int, int]]:
        """Categories where ``counts`` exceed the part: {category: (used, available)}."""
        return {k: (counts.get(k, 0), v) for k, v in self.capacity if counts.get(k, 0) > v}


@dataclass(frozen=True)
class PnrDevice:
    """A place-and-route target: a part in a package, its nextpnr options, pins and limits.

    Parameters
    ----------
    name : str
        Registry name ("<part>-<package>").
    family : str
        Its :class:`Family` name (nextpnr flavour, Yosys target).
    description : str
    nextpnr_args : tuple of str
        nextpnr arguments selecting the part and package.
    user_io : int
        User I/O pins of the package.
    clock_pin : str
        A global-buffer-capable pin of a common board for the clock.
    cell_limits : tuple of (str, str or None, int)
        Resource -> (regex over Yosys cell types, capacity), checked before nextpnr; regex None:
        the category of :meth:`Family.categorise`.
    bels : tuple of (str, str)
        Report column -> nextpnr utilisation key (BEL type).
    part : str
        Its :class:`Part` name.
    """
    name: str
    family: str
    description: str
    nextpnr_args: tuple[str, ...]
    user_io: int
    clock_pin: str
    cell_limits: tuple[tuple[str, str | None, int], ...]
    bels: tuple[tuple[str, str], ...]
    part: str


@dataclass(frozen=True)
class Primitive:
    """A vendor primitive the exported Verilog may instantiate, with its simulation model.

    Parameters
    ----------
    name : str
        Verilog module name of the primitive.
    family : str
        Its :class:`Family` name.
    operand_bits : int
        Signed width of each multiplier operand port (0 for a table).
    product_bits : int
        Width of the product port (0 for a table).
    model : str
        File name of the behavioural model in ``ikseries/sim/models/`` (package data).
    instance : callable
        A multiplier (``role`` "multiplier"): ``instance(m, a, b, product, enable)`` -> the
        Amaranth ``Instance`` of one registered multiplication ``product = a * b`` in the sync
        domain (operand and product registers inside the primitive, clock enable ``enable``,
        cleared by the domain's reset: at every clock edge the values of fabric registers reset
        synchronously), its ports connected to the operands and ``product`` in ``m``'s comb
        domain; ValueError (one line, :func:`check_operands`) for an operand wider than
        :attr:`operand_bits`. A table (``role`` "table"): ``instance(m, name, addr, data, init,
        read_enable, output_enable)`` adds to ``m`` the blocks of a read-only table whose word
        ``addr`` is on ``data`` two enabled clock edges later (a read enabled by
        ``read_enable``, then the block's output register enabled by ``output_enable``,
        cleared by the domain's reset).
    role : str
        "multiplier" (the DSP products of ``dsp_registers``) or "table" (the coefficient tables
        of a core with registered tables).
    min_depth : int
        A table primitive: the fewest words a table put on it has; shallower tables stay in the
        fabric, where the family's synthesis maps them to LUTs (0 for a multiplier).
    """
    name: str
    family: str
    operand_bits: int
    product_bits: int
    model: str
    instance: Callable
    role: str = "multiplier"
    min_depth: int = 0
    shapes: tuple[tuple[int, int], ...] = ()

    def shape(self, depth: int) -> tuple[int, int]:
        """The configuration (data bits, words) of a table primitive for a table of ``depth``
        words: the widest one that holds them (the fewest blocks side by side)."""
        if isinstance(depth, bool) or not isinstance(depth, int) or not self.shapes or \
                not 1 <= depth <= self.shapes[-1][1]:
            deepest = self.shapes[-1][1] if self.shapes else 0
            raise ValueError(f"depth must be an integer in [1, {deepest}] (one {self.name} deep), not {depth!r}")
        return next(s for s in self.shapes if s[1] >= depth)

    def blocks(self, depth: int, width: int) -> int:
        """Blocks of a table primitive holding ``depth`` words of ``width`` bits side by side."""
        return -(-width // self.shape(depth)[0])

    @property
    def model_path(self) -> Path:
        """Path of :attr:`model`, a file of the ``ikseries.sim`` package."""
        return Path(__file__).resolve().parent.parent / "sim" / "models" / self.model


def dsp_limbs(bits: int, operand_bits: int) -> int:
    """Limbs of a signed ``bits``-bit operand cut for signed DSP ports of ``operand_bits``: low
    limbs of ``operand_bits - 1`` bits (zero-extended, never negative), a signed top limb with
    the rest, so ``n`` limbs hold ``(operand_bits - 1) * n + 1`` signed bits (the split of
    :func:`ikseries.hdl.limbmul.limb_split` and of the modulo core's wide products)."""
    return max(1, -(-(bits - 1) // (operand_bits - 1)))


def check_operands(name: str, operand_bits: int, product_bits: int, a, b, product) -> None:
    """Refuse operands ``a``, ``b`` (Amaranth values) wider than the ``operand_bits`` signed
    ports of primitive ``name``, or a ``product`` narrower than their exact product (at most
    ``product_bits``), with one line naming the width."""
    for what, v in (("a", a), ("b", b)):
        if len(v) > operand_bits:
            raise ValueError(f"{what} must be at most {operand_bits} bits signed (the {name} operand), "
                             f"not {len(v)} bits")
    need = min(len(a) + len(b), product_bits)
    if len(product) < need:
        raise ValueError(f"product must be at least {need} bits (a {len(a)} x {len(b)}-bit signed product "
                         f"on the {name}), not {len(product)} bits")
