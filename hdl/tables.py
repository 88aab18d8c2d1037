"""Registered coefficient tables of the modulo-scheduled core: which tables are registered and
the ROM that reads them (a block RAM primitive with its output register, or its fabric twin)."""
from __future__ import annotations

from amaranth.hdl import Signal, unsigned
from amaranth.lib.memory import Memory

from ..constraints.devices import family_primitives
from ..fit.plan import Plan
from .evaluator import lut_fields, lut_rom_init

__all__ = ["default_registered_depth", "registered_rom", "rotated_table", "table_primitive", "table_registered"]


def table_primitive(dsp_registers: str | None):
    """The block RAM primitive a core with ``dsp_registers`` puts its registered tables on: the
    family's primitive of role "table" (:data:`ikseries.constraints.devices.PRIMITIVES`), or
    None (no family, or one without: the tables are fabric ``Memory``)."""
    if dsp_registers is None:
        return None
    return next(iter(family_primitives(dsp_registers, "table")), None)


def default_registered_depth(dsp_registers: str | None) -> int | None:
    """The fewest words of a registered table in a core with ``dsp_registers`` by default: its
    block RAM primitive's :attr:`~ikseries.constraints.facts.Primitive.min_depth`, None (no
    registered table) without one."""
    prim = table_primitive(dsp_registers)
    return None if prim is None else prim.min_depth


def table_registered(plan: Plan, i: int, registered_depth: int | None) -> bool:
    """Table read ``i`` is registered: its table (as deep as its index's range) has at least
    ``registered_depth`` words (None: no table is)."""
    return registered_depth is not None and plan.nodes[plan.nodes[i].args[0]].hi + 1 >= registered_depth


def rotated_table(plan: Plan, index: int, words: list, rotation: int) -> list:
    """``words`` (one per value of cell number ``index``) laid out for a cell number
    ``rotation`` lower, taken modulo the index's ``2**width`` (a negative one wraps): word ``j``
    at ``(j - rotation) mod 2**width``, 0 where no value lands."""
    n = plan.nodes[index]
    size = 1 << n.width
    out = [0] * size
    for j in range(n.lo, n.hi + 1):
        out[(j - rotation) % size] = words[j]
    return out


def registered_rom(m, plan: Plan, index: int, luts: list[int], addr, read, out, primitive,
                   rotation: int = 0) -> dict:
    """The ROM of the ``luts`` read at node ``index`` (:func:`~ikseries.hdl.evaluator.lut_rom_init`),
    added to ``m``: word ``addr`` read at a clock edge where ``read`` is high, then taken by
    its output register at an edge where ``out`` is high (cleared by the domain's reset). On
    the block RAM ``primitive`` (its own output register), or with None a ``Memory`` read port
    followed by a fabric register, the same timing and values. Each lut's value in the output
    register (:func:`~ikseries.hdl.evaluator.lut_fields`). ``rotation``: ``addr`` is the cell
    number that many below the plan's, wrapped (:func:`rotated_table`).

    Latency
    -------
    Two enabled clock edges (``read``, then ``out``) from ``addr`` to the word.

    Throughput
    ----------
    One read per clock edge where ``read`` is high.
    """
    init, width = lut_rom_init(plan, index, luts)
    if rotation:
        init = rotated_table(plan, index, init, rotation)
    data = Signal(width, name=f"lut{index}_data")
    if primitive is not None:
        primitive.instance(m, f"lut{index}", addr, data, init, read, out)
    else:        # the same in the fabric: data is the output register
        m.submodules[f"lut{index}"] = rom = Memory(shape=unsigned(width), depth=len(init), init=init)
        port = rom.read_port(domain="sync")
        m.d.comb += [port.addr.eq(addr), port.en.eq(read)]
        with m.If(out):
            m.d.sync += data.eq(port.data)
    return lut_fields(plan, luts, data)
