"""What a servo's evaluation costs the hardware that will run it: the model the fitter minimises.

The fitter tries candidate structures (variables, degrees, terms) per servo and keeps the
cheapest that meets the approximation budget. "Cheapest" is asked of a :class:`CostModel`, which
an architecture offers (:meth:`ikseries.hdl.architectures.Architecture.cost_model`): it is the
architecture that knows what a product, an addition or a table read costs it. The model prices
a trial plan holding the one servo (its coordinate stage included), built from the structure
alone before any coefficient is fitted; a model whose price depends on the coefficients' values
(:attr:`CostModel.prices_values`) prices the structures found again with their fitted
coefficients (:func:`ikseries.fit.formats.fitted_cost`).

A cost model that changes which structure is chosen changes the fitted plan, so it is part of
the fit. Every architecture offers :class:`MultiplierCount` by default, which the fit's cache
key (``ikseries.robot.Robot.fit_record``) does not name, so that keys of plans fitted before
the models existed stay the same; any other model's :meth:`CostModel.record` is part of that
key. The modulo-scheduled and pipelined architectures offer :class:`DeviceCost` with
``hardware.cost = "device"`` (``tests/test_architectures.py`` checks that every other
architecture offers the default).

The structure search bounds its effort by multiplications whatever the model
(:data:`ikseries.fit.search.MAX_COST`) and compares costs with a margin counted in products
(``FINALIST_MARGIN``): every model's unit is one product on one multiplier.
"""
from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import ClassVar

from ..constraints.devices import Part, family, family_primitives, part
from .ops import OPS
from .plan import Plan, lut_groups, stored_field

__all__ = ["CostModel", "MultiplierCount", "DeviceCost", "Usage", "DEFAULT_COST_MODEL", "COSTS"]


class CostModel(abc.ABC):
    """The price of evaluating one output of a plan on some hardware."""

    #: name in records and messages
    name: ClassVar[str]
    #: what the fit chooses per servo, in the plan's method record ("with the fewest multipliers")
    objective: ClassVar[str]
    #: the price depends on the coefficients' values (the widths of tables and operands), not
    #: only on the operations: the search then reprices its finalists with their fitted
    #: coefficients (:func:`ikseries.fit.search.fit_servo`)
    prices_values: ClassVar[bool] = False

    @abc.abstractmethod
    def cost(self, plan, output: str) -> float:
        """Cost of evaluating output ``output`` of ``plan``: every operation of its cone."""

    def record(self) -> dict:
        """JSON-ready description."""
        return {"cost_model": self.name}

    def label(self, cost: float) -> str:
        """``cost`` in progress messages: "12 multipliers"."""
        return f"{cost:g} {self.name}"


@dataclass(frozen=True)
class MultiplierCount(CostModel):
    """One unit per multiplication (``mul`` operation) in the output's cone.

    Products dominate every polynomial architecture so far: the pipelined core spends a
    multiplier (a DSP block or a LUT array) on each, the modulo-scheduled core one multiplier
    issue slot per product and interval, the folded core one cycle of a multiplier unit;
    additions, shifts and clamps are cheap beside them.
    """
    name: ClassVar[str] = "multipliers"
    objective: ClassVar[str] = "with the fewest multipliers"

    def cost(self, plan, output: str) -> float:
        node = next(o.node for o in plan.outputs if o.name == output)
        return sum(1 for i in plan.cone(node) if plan.nodes[i].op == "mul")


@dataclass(frozen=True)
class Usage:
    """Resources an output's cone takes on a device, before any sharing (:meth:`DeviceCost.usage`).

    Attributes
    ----------
    products : int
        Multiplications.
    dsp : int
        DSP blocks of those products, one each (:meth:`ikseries.constraints.facts.Family.dsp_blocks`).
    bram : int
        Block RAM blocks of the tables deep enough for the family's table primitive.
    ports : int
        Block RAM read ports: one per block (a ROM word of a table read is on every block side
        by side; the cores use one port of each, the other is free).
    lut : int
        LUTs of additions, clamps, the sums of split products' partial products, the tables in
        the fabric and, on a shared multiplier, its operand multiplexers.
    ff : int
        Flip-flops of each registered node's own register (delay registers not counted).
    slow_tables : int
        Tables in the fabric deeper than one logic level reads
        (:attr:`~ikseries.constraints.facts.Family.rom_level_words`) on a family with a table
        primitive, shallower than its ``min_depth``: synthesis builds each as a LUT ROM of
        several levels or on a block RAM read without its output register, whichever it
        prefers at the table's width.
    """
    products: int = 0
    dsp: int = 0
    bram: int = 0
    ports: int = 0
    lut: int = 0
    ff: int = 0
    slow_tables: int = 0


@dataclass(frozen=True)
class DeviceCost(CostModel):
    """The share of a device an output's evaluation takes, at the architecture's rate.

    Built from the registry (:mod:`ikseries.constraints.devices`) for part ``part``: its
    family's DSP operand size and LUT inputs, its table primitive (the shapes and the fewest
    words of a table put on it, :attr:`~ikseries.constraints.facts.Primitive.min_depth`), the
    part's capacities. :meth:`usage` counts what the output's cone takes; :meth:`cost` prices
    each resource as the fraction of the part's capacity it uses, products divided between the
    ``interval`` targets a modulo-scheduled multiplier serves (tables, adders and registers
    are not shared), and scales the sum so that one product on one DSP block at interval 1
    costs 1 (the unit of :class:`MultiplierCount` and of the search's bounds; a constant
    factor, so structures are ordered as by the device fraction).

    A product takes one DSP block if its operands fit the family's DSP size, else one per limb
    pair of the split the cores make, plus an adder per extra pair. A table of at least the
    table primitive's ``min_depth`` words (the ECP5's DP16KD; the rule of
    :func:`ikseries.hdl.tables.table_registered` and of the family's own synthesis of a
    registered ROM) takes blocks of it, every ``lut`` node read at one index side by side
    (:func:`ikseries.fit.plan.lut_groups`); a shallower table, or any table on a family without
    a table primitive in the registry, is a LUT ROM: per bit ``ceil(words / 2**lut_inputs)``
    LUTs (an estimate: the multiplexers above the first LUT are free on the ECP5, LUTs on the
    iCE40; constant bits cost none). The iCE40 has none: its modulo and folded cores keep
    their tables in the fabric, but Yosys may put a deep table of the pipelined core (a
    ``Memory`` read port) on SB_RAM40_4K, which this model prices as LUTs. The
    iCE40UP5K's SPRAM is not priced as table memory: the bitstream cannot initialise it
    (SB_SPRAM256KA has no initial-value parameters, unlike SB_RAM40_4K's INIT_0..F; Yosys's
    ``ice40/cells_sim.v`` model leaves its contents undefined at power-up), so a ROM there
    needs a loader writing it after configuration, which no core has.

    Timing at the rate asked: at ``interval`` 1 the clock is the rate, and a table read from
    the fabric is one pipeline stage. One logic level reads a table of up to the family's
    :attr:`~ikseries.constraints.facts.Family.rom_level_words` (the ECP5's LUT4s through PFUMX
    and L6MUX21: 64 words); a deeper one shallower than the table primitive's ``min_depth``
    stays out of the modulo core's registered block RAMs, and Yosys builds it either as LUTs of
    several levels or on a DP16KD read without its output register (clock-to-out 5.6 ns
    against 0.97), as it prefers at the table's width (see ``DP16KD_MIN_DEPTH``). Such a
    structure (:attr:`Usage.slow_tables`) is priced infinite at interval 1 on a family with a
    table primitive: it is chosen only if nothing else fits. At a longer interval, and on a
    family without a table primitive, tables are priced as area only, and so are the
    pipelined core's block RAM reads, which no core registers.

    Widths: the search prices a structure on its trial plan (:func:`ikseries.fit.lowering.structure_cost`:
    stand-in coefficients at 16 fractional bits, before any is fitted), whose operand and table
    widths are not the fitted plan's. As the model prices values (:attr:`prices_values`), the
    search ranks every structure it found, and its pruned finalists, by their prices with their
    fitted coefficients in the narrowest formats for the servo alone
    (:func:`ikseries.fit.formats.fitted_cost`); tables are priced at the bits their ROM stores
    (:func:`~ikseries.fit.plan.stored_field`).

    Measured (fit17). The ECP5 one-per-clock core, ``python bench/pareto.py --designs modulo1dt
    --devices ecp5 --seeds 1,2,3 --jobs 1 --timeout 300 --cost device``: before these rules it
    chose for s2 a 16 x 6 grid in rho2 x z (126-word tables, one 20-bit table on a DP16KD read
    without its output register, the critical path) over 32 x 21 cells: 24 DSP, 10 EBR, 1151
    LUT, 1933 FF, Fmax 147.3 / 149.9 / 149.1 MHz (seeds 1-3), 20 cycles, 134.1 ns. Now it
    chooses the multiplier count's plan, node for node: 24 DSP, 12 EBR, 691 LUT, 1737 FF, seed 1
    router past 300 s, 227.1 / 217.3 MHz, 20 cycles, 92.0 ns, the default's figures (the fit,
    certified: 49.8 s of CPU against 39.8). On the default cylinder-leg (exact products,
    ``python bench/fit_benchmark.py cylinder-leg --cost device``: pipelined, the iCE40UP5K's
    model) its plan took 58 products, 173 SB_MAC16 blocks, 6397 LUTs and 3916 FFs by this model
    against the multiplier count's 57, 173, 6391 and 3841 (before: 60, 197, 7327, 4109), in
    13.2-14.2 s of CPU against 6.0-6.8 (another engineer's runs beside it; before: 14.8); fitted
    (uncertified) with ``hardware.dsp = "ecp5"``, 60 products and 105 ECP5 blocks against 57 and
    103. It ties at best: the per-servo formats and the pruning (on stand-in costs) are not the
    whole plan's. So it is not the default (``hardware.cost = "multipliers"``).

    Parameters
    ----------
    part : str
        A part of :data:`ikseries.constraints.devices.PARTS` with DSP, LUT and FF capacities
        (and BRAM if its family has a table primitive).
    interval : int
        Targets each multiplier serves (the modulo core's initiation interval; 1 for the
        pipelined core).
    """
    part: str
    interval: int = 1
    name: ClassVar[str] = "device"
    prices_values: ClassVar[bool] = True
    objective: ClassVar[str] = "taking the least of the device (DSP blocks, block RAM, LUTs, FFs)"

    def __post_init__(self):
        dev: Part = part(self.part)
        if isinstance(self.interval, bool) or not isinstance(self.interval, int) or self.interval < 1:
            raise ValueError(f"interval must be an integer >= 1, not {self.interval!r}")
        need = ("DSP", "LUT", "FF") + (("BRAM",) if self._table_primitive else ())
        missing = [k for k in need if dev.capacities.get(k, 0) <= 0]
        if missing:
            raise ValueError(f"part must have {', '.join(need)} capacities (the resources priced), not "
                             f"{self.part!r} (no {', '.join(missing)})")

    @property
    def _family(self):
        return family(part(self.part).family)

    @property
    def _table_primitive(self):
        return next(iter(family_primitives(part(self.part).family, "table")), None)

    def record(self) -> dict:
        return {"cost_model": self.name, "part": self.part, "interval": self.interval}

    def label(self, cost: float) -> str:
        return f"cost {cost:.4g} ({self.part}, in DSP blocks)"

    def cost(self, plan, output: str) -> float:
        u = self.usage(plan, output)
        if u.slow_tables and self.interval == 1:
            return math.inf    # at one target per clock the clock is the rate: see the class docstring
        cap = part(self.part).capacities
        fabric = u.lut / cap["LUT"] + u.ff / cap["FF"] + (u.bram / cap["BRAM"] if u.bram else 0.0)
        return u.dsp / self.interval + fabric * cap["DSP"]

    def usage(self, plan: Plan, output: str | None = None) -> Usage:
        """What the cone of output ``output`` of ``plan`` takes (:class:`Usage`), unshared; None:
        every output's (:meth:`~ikseries.fit.plan.Plan.live`, what the core evaluates)."""
        cone = plan.live() if output is None else plan.cone(next(o.node for o in plan.outputs if o.name == output))
        fam, nodes, shared = self._family, plan.nodes, self.interval > 1
        products = dsp = lut = ff = 0
        for i in sorted(cone):
            n = nodes[i]
            kind = OPS[n.op].kind
            if kind in ("logic", "product", "port"):
                ff += n.width          # the node's own register
            if kind == "product":
                wa, wb = (nodes[a].signed_width for a in n.args)
                blocks = fam.dsp_blocks(wa, wb)
                products, dsp = products + 1, dsp + blocks
                lut += (blocks - 1) * (wa + wb) + (wa + wb if shared else 0)   # partial sums; operand selection
            elif n.op == "add":
                lut += n.width          # one LUT per bit (a sum LUT beside a carry cell, or a CCU2C half)
            elif n.op == "clamp":
                lut += 3 * n.width      # two comparisons and the selection
        bram, table_lut, table_ff, slow = self._tables(plan, cone)
        return Usage(products, dsp, bram, bram, lut + table_lut, ff + table_ff, slow)

    def _tables(self, plan: Plan, cone: set) -> tuple[int, int, int, int]:
        """(block RAM blocks, LUTs, FFs, slow tables (:attr:`Usage.slow_tables`)) of the tables
        read in ``cone``: per index, one ROM of its ``lut`` nodes side by side, ``index.hi + 1``
        words of the bits the evaluators store (:func:`~ikseries.fit.plan.stored_field`)."""
        prim, fam, bram, lut, ff, slow = self._table_primitive, self._family, 0, 0, 0, 0
        for index, luts in lut_groups(plan).items():
            luts = [i for i in luts if i in cone]
            if not luts:
                continue
            depth, width = plan.nodes[index].hi + 1, sum(stored_field(plan, i)[0] for i in luts)
            if prim is not None and prim.min_depth <= depth <= prim.shapes[-1][1]:
                bram += prim.blocks(depth, width)      # its output register is in the block
            else:
                lut += width * -(-depth // (1 << fam.lut_inputs))
                ff += width
                slow += prim is not None and fam.rom_level_words < depth < prim.min_depth
        return bram, lut, ff, slow


DEFAULT_COST_MODEL = MultiplierCount()
#: the models a robot description chooses by name (``hardware.cost``), the default first
COSTS = (MultiplierCount.name, DeviceCost.name)
