"""Partly folded evaluator: the plan's dataflow pipelined, its multiplications shared by a
modulo schedule (one target every ``initiation_interval`` cycles on fewer multipliers)."""
from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import Array, Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..constraints.devices import dsp_size
from ..fit.ops import OPS, node_shape
from ..fit.plan import Plan, under
from .evaluator import input_layout, lut_groups, node_expression, output_layout
from .limbmul import check_dsp, check_dsp_registers
from .outbuffer import OutputBuffer
from .planmemo import per_plan
from .tables import default_registered_depth, registered_rom, rotated_table, table_primitive, table_registered

__all__ = ["ModuloEvaluator", "ModuloSchedule", "modulo_schedule", "modulo_latency", "modulo_stream_rule", "stall_free",
           "MUL_LATENCY", "WIDE_MUL_LATENCY", "CLAMP_LATENCY", "TABLE_LATENCY", "REGISTERED_TABLE_LATENCY",
           "BUFFER_LATENCY"]

#: cycles from reading a multiplication's operands to the first cycle its product can be read:
#: operand registers at the multiplier inputs, then the product register. Consumers scheduled in
#: that cycle read the product register itself (a bypass); the node's own register captures the
#: product at the end of it for later readers
MUL_LATENCY = 2
#: the same for a product wider than one DSP block: operand registers, the registered partial
#: products of the limbs, their registered sum
WIDE_MUL_LATENCY = 3
#: cycles of a clamp: its comparisons registered (with the value), then the selection
CLAMP_LATENCY = 2
#: cycles of a table read: the ROM's synchronous read is the node's register
TABLE_LATENCY = 1
#: the same with registered tables: the ROM's read, then its output register (on the ECP5 the
#: block RAM's own, REGMODE "OUTREG": 0.97 ns clock-to-out instead of 5.6 ns)
REGISTERED_TABLE_LATENCY = 2
#: cycles the output buffer of a core that never stalls (:func:`stall_free`) adds: the
#: pipeline's last cycle writes the buffer, whose first-word-fall-through read is valid the
#: next cycle
BUFFER_LATENCY = 1


def stall_free(initiation_interval: int) -> bool:
    """Whether a modulo core at ``initiation_interval`` never stalls its pipeline.

    At 1 every register of the pipeline would load under the backpressure enable, whose
    fanout, not the arithmetic, limits the clock on the ECP5 (measured: 198.8 against
    228.5 MHz median with the enable tied high). Such a core runs unconditionally and
    buffers its outputs instead (:class:`ModuloEvaluator`). Slower cores keep the enable:
    their pipelines are short in targets and the iCE40 they are built for has no LUT RAM
    for the buffer.
    """
    return initiation_interval == 1


def modulo_stream_rule(initiation_interval: int) -> str:
    """The stream rule (:data:`~ikseries.hdl.architectures.STREAM_RULES`) of a modulo core at
    ``initiation_interval``: ``"buffered"`` when it never stalls (:func:`stall_free`)."""
    return "buffered" if stall_free(initiation_interval) else "modulo"


def modulo_latency(schedule: ModuloSchedule) -> int:
    """Cycles from a target's input transfer to its output transfer, the output buffer of a
    stall-free core (:func:`stall_free`) included."""
    return schedule.latency + (BUFFER_LATENCY if stall_free(schedule.initiation_interval) else 0)


def _kind(plan: Plan, i: int) -> str:
    """The op's kind (:data:`~ikseries.fit.ops.OPS`), except that an addition whose operands'
    bits cannot overlap (:func:`_carry_free`) is wiring here (an OR, no carry chain), and so
    is the addition of a table's index offset (:func:`_offset_add`: its operand, unchanged)."""
    return _kinds(plan)[i]


@per_plan
def _kinds(plan: Plan) -> tuple[str, ...]:
    """:func:`_kind` of every node, found once per plan (the scheduler asks every cycle)."""
    return tuple("wiring" if _carry_free(plan, i) or _offset_add(plan, i) is not None else OPS[n.op].kind
                 for i, n in enumerate(plan.nodes))


@per_plan
def _users(plan: Plan) -> tuple:
    """Per node, the nodes that read it."""
    users = [[] for _ in plan.nodes]
    for i, n in enumerate(plan.nodes):
        for a in n.args:
            users[a].append(i)
    return tuple(tuple(u) for u in users)


def _offset_add(plan: Plan, i: int) -> tuple[int, int] | None:
    """``(x, c)`` when node ``i`` is ``x + c``, ``c`` a constant, read (through binary point
    moves) only by cell numbers ``index(., s)`` that only address tables and by cell offsets
    ``mask(., s)``, with ``c`` a multiple of each ``2**s``: the offsets are those of ``x`` and
    each cell number is ``x``'s plus ``c >> s``, which the tables take in their layout
    (:func:`_index_rotation`), so the hardware reads ``x`` itself (no adder, no cycle). Not
    where ``x`` is a product: its bits, straight from the multiplier, would drive the tables'
    address logic (on the ECP5-25F such a core took nextpnr's router past 15 minutes)."""
    n = plan.nodes[i]
    if n.op != "add" or any(o.node == i for o in plan.outputs):
        return None
    consts = [k for k in (0, 1) if plan.nodes[n.args[k]].op == "const"]
    if len(consts) != 1:
        return None
    c, x = plan.nodes[n.args[consts[0]]].param, n.args[1 - consts[0]]
    if plan.nodes[under(plan.nodes, x, ("frac", "shr", "shl"))].op == "mul":   # its bits would drive the address logic
        return None
    users, todo = _users(plan), list(_users(plan)[i])
    if not todo:
        return None
    while todo:
        u = plan.nodes[j := todo.pop()]
        if u.op == "frac" and not any(o.node == j for o in plan.outputs):
            todo.extend(users[j])
        elif u.op not in ("index", "mask") or c % (1 << u.param) or (
                u.op == "index" and not all(plan.nodes[v].op == "lut" for v in users[j])):
            return None
    return x, c


def _index_rotation(plan: Plan, index: int) -> int:
    """How far the hardware's cell number ``index`` is below the plan's: ``c >> s`` when it
    reads an offset addition (:func:`_offset_add`) through binary point moves, else 0."""
    n = plan.nodes[index]
    if n.op != "index":
        return 0
    off = _offset_add(plan, under(plan.nodes, n.args[0], ("frac",)))
    return 0 if off is None else off[1] >> n.param


def _low_zeros(plan: Plan, i: int) -> int:
    """Low bits of node ``i``'s integer that its structure keeps zero (shifted in by a shl)."""
    n = plan.nodes[i]
    if n.op == "frac":        # the same integer
        return _low_zeros(plan, n.args[0])
    return n.param + _low_zeros(plan, n.args[0]) if n.op == "shl" else 0


def _carry_free(plan: Plan, i: int) -> bool:
    """Node ``i`` adds a non-negative value whose low ``k`` bits are zero to one in [0, 2**k)
    (a grid's cell address: a row number shifted left plus a column number): their bits do not
    overlap, so the sum is their OR."""
    n = plan.nodes[i]
    if n.op != "add":
        return False
    for a, b in (n.args, n.args[::-1]):
        k, na, nb = _low_zeros(plan, a), plan.nodes[a], plan.nodes[b]
        if k and na.lo >= 0 and nb.lo >= 0 and nb.hi < 1 << k:
            return True
    return False


def _wiring_expression(plan: Plan, i: int, ops):
    """The combinational value of wiring node ``i`` from its operands' values ``ops`` (a cell
    number behind an offset addition: its low bits, the tables' address)."""
    if _carry_free(plan, i):
        return ops[0] | ops[1]
    if (off := _offset_add(plan, i)) is not None:
        return ops[plan.nodes[i].args.index(off[0])]
    return node_expression(plan.nodes[i], ops)


def _input_clamp(plan: Plan, i: int) -> bool:
    """Node ``i`` clamps an input port: the input register takes the clamped value at once."""
    n = plan.nodes[i]
    return n.op == "clamp" and _kind(plan, n.args[0]) == "port"


def _clamp_tests(plan: Plan, i: int):
    """The limits clamp node ``i`` can reach (its operand's interval crosses them), each as
    ``(limit, test)`` with ``test(x)`` true beyond it, or None if some reachable limit needs a
    comparator: a limit of 0 below (the sign bit) or ``2**k - 1`` above a value that is not
    negative there (bits ``k`` and up) are single-LUT tests, so such a clamp takes one cycle."""
    n = plan.nodes[i]
    x, (lo, hi) = plan.nodes[n.args[0]], n.param
    tests = []
    if x.lo < lo:
        if lo != 0:
            return None
        tests.append((lo, lambda v: v[-1]))       # x.lo < 0: signed
    if x.hi > hi:
        k = (hi + 1).bit_length() - 1
        if hi < 0 or hi + 1 != 1 << k:
            return None
        w = x.width
        tests.append((hi, lambda v: v[k:w - 1 if x.signed else w].any() & ~(v[-1] if x.signed else 0)))
    return tests


def _clamp_latency(plan: Plan, i: int) -> int:
    """``CLAMP_LATENCY``, or one cycle if every limit the clamp reaches is a bit test."""
    return 1 if _clamp_tests(plan, i) is not None else CLAMP_LATENCY


@dataclass(frozen=True)
class ModuloSchedule:
    """When every plan node is computed for one target, and on which multiplier.

    ``ready[n]``: first cycle (counted from the cycle the target is accepted) in which node
    ``n`` can be read; ``start[n]``: the cycle a registered operation reads its operands
    (None for inputs, clamps of inputs, constants and wiring); ``unit[n]``: the multiplier of a
    multiplication. A multiplier serves at most one multiplication per phase
    ``start mod initiation_interval``, so targets can enter every ``initiation_interval``
    cycles.
    """
    initiation_interval: int
    units: int
    ready: tuple
    start: tuple
    unit: tuple
    latency: int
    swap: tuple = ()      # per node: the multiplier takes the operands in the other order
    operand_widths: tuple = ()  # per multiplier: signed widths (a, b) of its operands
    unit_latency: tuple = ()    # per multiplier: MUL_LATENCY, or WIDE_MUL_LATENCY if split in limbs
    registered_depth: int | None = None   # tables of at least this many words are registered

    def held_from(self, plan: Plan) -> list[int]:
        """Per node, the first cycle its own register holds it: ``ready``, except for a
        multiplication, whose product is read from the multiplier in cycle ``ready`` and
        captured at its end."""
        return [r + 1 if _kind(plan, i) == "product" else r for i, r in enumerate(self.ready)]

    def last_read(self, plan: Plan) -> list[int]:
        """Per node, the last cycle it is read: by a registered consumer (when that reads its
        operands), through a wiring consumer (as late as that is read) or as an output."""
        last = list(self.ready)
        for o in plan.outputs:
            last[o.node] = max(last[o.node], self.latency)
        readers = [[] for _ in plan.nodes]
        for i, n in enumerate(plan.nodes):
            for a in n.args:
                readers[a].append(i)
        for i in reversed(range(len(plan.nodes))):     # readers come after their operands
            for r in readers[i]:
                if _kind(plan, r) == "wiring":
                    last[i] = max(last[i], last[r])
                elif self.start[r] is not None:         # not an input clamp (reads the port)
                    last[i] = max(last[i], self.start[r])
        return last


def _fits(wa: int, wb: int, dsp) -> bool:
    """A wa x wb signed product fits one ``dsp`` block (either orientation; any if no dsp)."""
    return dsp is None or (wa <= dsp[0] and wb <= dsp[1]) or (wa <= dsp[1] and wb <= dsp[0])


def _own_latency(plan: Plan, i: int, registered_depth: int | None) -> int:
    """Cycles from reading the operands of node ``i``, not a multiplication, to its value."""
    n = plan.nodes[i]
    if _kind(plan, i) == "wiring" or _input_clamp(plan, i):
        return 0
    if _kind(plan, i) == "table":
        return REGISTERED_TABLE_LATENCY if table_registered(plan, i, registered_depth) else TABLE_LATENCY
    return _clamp_latency(plan, i) if n.op == "clamp" else 1


def _heights(plan: Plan, wide: set, registered_depth: int | None) -> list[int]:
    """Per node, cycles from reading its operands to the outputs: the scheduling priority
    (``wide``: the multiplications split in limbs)."""
    nodes = plan.nodes
    users = [[] for _ in nodes]
    for i, n in enumerate(nodes):
        for a in n.args:
            users[a].append(i)
    height = [0] * len(nodes)
    for i in reversed(range(len(nodes))):
        kind = _kind(plan, i)
        own = (WIDE_MUL_LATENCY if i in wide else MUL_LATENCY) if kind == "product" else \
            _own_latency(plan, i, registered_depth)
        height[i] = own + max((height[u] for u in users[i]), default=0)
    return height


class _SharedMultipliers:
    """The multipliers while a modulo schedule is built: ``n_narrow`` that fit one ``dsp``
    block, then ``n_wide`` split in limbs; the phases each one serves, its operand widths and
    the operand nodes each of its two ports selects."""

    def __init__(self, ii: int, n_narrow: int, n_wide: int, dsp):
        self.ii, self.n_narrow, self.dsp = ii, n_narrow, dsp
        self.units = n_narrow + n_wide
        self.latency = [WIDE_MUL_LATENCY if u >= n_narrow else MUL_LATENCY for u in range(self.units)]
        self.busy = [[False] * ii for _ in range(self.units)]
        self.widths = [(0, 0)] * self.units
        self.sources = [(set(), set()) for _ in range(self.units)]

    def place(self, nodes, i: int, wide: bool, cycle: int):
        """Take the free multiplier of node i's class (and operand order) that needs the fewest
        new operand sources (its multiplexers grow least), then whose widths grow least:
        ``(unit, swapped)``, or None if none is free at this phase."""
        wa, wb = (nodes[a].signed_width for a in nodes[i].args)
        na, nb = nodes[i].args
        pool = range(self.n_narrow, self.units) if wide else range(self.n_narrow)
        best = None
        for u in pool:
            if self.busy[u][cycle % self.ii]:
                continue
            ua, ub = self.widths[u]
            for sw, (x, y), (sx, sy) in ((False, (wa, wb), (na, nb)), (True, (wb, wa), (nb, na))):
                grown = (max(ua, x), max(ub, y))
                if u < self.n_narrow and not _fits(*grown, self.dsp):
                    continue
                new = (sx not in self.sources[u][0]) + (sy not in self.sources[u][1])
                key = (new, grown[0] * grown[1] - ua * ub, u, sw)
                if best is None or key < best[0]:
                    best = (key, u, sw, grown, sx, sy)
        if best is None:
            return None
        _, u, sw, grown, sx, sy = best
        self.widths[u] = grown
        self.sources[u][0].add(sx)
        self.sources[u][1].add(sy)
        self.busy[u][cycle % self.ii] = True
        return u, sw


def _settle(plan: Plan, ready: list, start: list, registered_depth: int | None):
    """Give every non-multiplication whose operands are scheduled its time (in place)."""
    for i, n in enumerate(plan.nodes):
        if ready[i] is not None or _kind(plan, i) == "product":
            continue
        if _kind(plan, i) == "constant":
            ready[i] = 0
        elif _kind(plan, i) == "port" or _input_clamp(plan, i):
            ready[i] = 1
        elif all(ready[a] is not None for a in n.args):
            t = max(ready[a] for a in n.args)
            if _kind(plan, i) == "wiring":
                ready[i] = t
            else:
                start[i], ready[i] = t, t + _own_latency(plan, i, registered_depth)


@per_plan
def modulo_schedule(plan: Plan, initiation_interval: int, dsp: tuple[int, int] | None = dsp_size("ecp5"),
                    registered_depth: int | None = None) -> ModuloSchedule:
    """List-schedule ``plan`` with its multiplications on shared multipliers, each free once
    per phase (cycle mod ``initiation_interval``).

    Multiplications are of two classes: those whose operands fit one ``dsp`` block (signed
    widths, either order; all of them when ``dsp`` is None) run on single-block multipliers
    in ``MUL_LATENCY`` cycles; wider ones on multipliers split into ``dsp``-sized limbs whose
    partial products are registered, then summed, in ``WIDE_MUL_LATENCY`` cycles. Each class
    gets the fewest multipliers that fit: ceil(its multiplications / initiation_interval).
    Every cycle the ready multiplications take the free multipliers of their class at that
    phase, the one with the longest path to an output first; of those, the multiplier (and the
    operand order) that adds the fewest new sources to its operand multiplexers (products that
    share an operand go to one multiplier), then whose widths grow least. Additions, clamps and
    table reads have their own hardware and run as soon as their operands are ready; a table read
    takes ``TABLE_LATENCY`` cycles, ``REGISTERED_TABLE_LATENCY`` if its table has at least
    ``registered_depth`` words (None: no table is registered).

    Computed once per plan object and options (:func:`~ikseries.hdl.planmemo.per_plan`): the
    architecture's timing, its multiplier count and the evaluator share one schedule.
    """
    ii = initiation_interval
    nodes = plan.nodes
    muls = [i for i in range(len(nodes)) if _kind(plan, i) == "product"]
    wide = {i for i in muls if not _fits(*(nodes[a].signed_width for a in nodes[i].args), dsp)}
    shared = _SharedMultipliers(ii, -(-(len(muls) - len(wide)) // ii), -(-len(wide) // ii), dsp)
    height = _heights(plan, wide, registered_depth)
    ready: list = [None] * len(nodes)
    start: list = [None] * len(nodes)
    unit: list = [None] * len(nodes)
    swap: list = [False] * len(nodes)
    pending = set(muls)
    _settle(plan, ready, start, registered_depth)
    cycle = 0
    while pending:
        cands = sorted((i for i in pending if all(ready[a] is not None and ready[a] <= cycle
                                                  for a in nodes[i].args)),
                       key=lambda i: (-height[i], i))
        for i in cands:
            placed = shared.place(nodes, i, i in wide, cycle)
            if placed is None:
                continue
            u, swap[i] = placed
            start[i], ready[i], unit[i] = cycle, cycle + shared.latency[u], u
            pending.discard(i)
        _settle(plan, ready, start, registered_depth)
        cycle += 1
        if cycle > 64 * (len(nodes) + ii):   # every multiplication fits some phase: cannot happen
            raise RuntimeError(f"modulo schedule did not converge: {len(pending)} multiplications unplaced")
    _settle(plan, ready, start, registered_depth)
    latency = max([1] + [ready[o.node] for o in plan.outputs])
    return ModuloSchedule(ii, shared.units, tuple(ready), tuple(start), tuple(unit), latency, tuple(swap),
                          tuple(shared.widths), tuple(shared.latency), registered_depth)


def _limbs(x, width: int, bits: int) -> list:
    """``x`` (signed, ``width`` bits) as limbs (value, shift): unsigned ``bits``-bit limbs from
    the bottom, the rest a signed top limb of at most ``bits + 1`` bits."""
    out, lo = [], 0
    while width - lo > bits + 1:
        out.append((x[lo:lo + bits], lo))
        lo += bits
    out.append((x[lo:width].as_signed(), lo))
    return out


class ModuloEvaluator(wiring.Component):
    """Evaluates every output of ``plan``, one target every ``initiation_interval`` cycles.

    Between the fully pipelined :class:`~ikseries.hdl.evaluator.PlanEvaluator` (one target
    per cycle, one multiplier per multiplication) and the
    :class:`~ikseries.hdl.folded.FoldedEvaluator` (everything on a few units, one target per
    evaluation): the dataflow keeps its own adders, clamps and table reads, while the
    multiplications share multipliers in a modulo schedule (:func:`modulo_schedule`). A phase
    counter selects each multiplier's operands; each multiplier has registered operands and a
    registered product (DSP-friendly). Consumers scheduled in the cycle after the product
    register is written read it directly; the node's own register captures it at the end of
    that cycle for later ones. Products wider
    than one DSP block run on multipliers split into DSP-sized limbs (lower limbs unsigned,
    ``dsp[0] - 1`` bits; the top limb signed), whose partial products are registered and then
    summed into a registered product. A value read more than ``initiation_interval`` cycles
    after it was computed is kept in a chain of registers that advance once per target.
    Every width comes from the plan's interval analysis, so the outputs equal
    :func:`ikseries.sim.golden.evaluate` bit for bit.

    Parameters
    ----------
    plan : Plan
    initiation_interval : int
        Cycles between accepted targets (>= 1).
    dsp : (int, int) or None
        Signed operand widths of the device's DSP multiplier (a family's
        :attr:`~ikseries.constraints.facts.Family.dsp`, default the ECP5's); None: every product
        in one piece.
    dsp_registers : None or str
        None (default): the operand and product registers are fabric flip-flops (Yosys maps
        the product to a DSP block without absorbing them, so every product path runs fabric
        -> DSP -> fabric). A family with a DSP primitive
        (:data:`ikseries.constraints.devices.PRIMITIVES`: ``"ice40"``, ``"ecp5"``; ``dsp`` must be that
        family's size): each block product is an instantiated primitive whose own
        input and output registers are the operand and product registers (clock enable = the
        pipeline enable, cleared by the domain's reset), same timing and values. The
        Amaranth simulator cannot run an ``Instance``: simulate the same core with None; the
        exported Verilog runs in Icarus and Verilator with the primitive's model
        (:attr:`~ikseries.constraints.facts.Primitive.model_path`; :func:`ikseries.sim.runner.run`
        adds it).
    registered_tables : None, bool or int
        An integer N >= 1: each read of a table of at least N words takes
        ``REGISTERED_TABLE_LATENCY`` cycles, the ROM's synchronous read then an output register,
        so a block RAM's slow clock-to-out ends at a register instead of running on through a
        multiplier's operand multiplexer. The luts that share an index are one ROM, their fields
        side by side (:func:`~ikseries.hdl.evaluator.lut_rom_init`). With a ``dsp_registers``
        family that has a block RAM primitive (:func:`~ikseries.hdl.tables.table_primitive`: the ECP5's DP16KD) the
        ROM is that primitive with its own output register (REGMODE "OUTREG"), else a
        ``Memory`` read port followed by a fabric register: same timing and values, the twin
        the Amaranth simulator runs. Shallower tables, and all of them with False, are one
        registered ROM read (``TABLE_LATENCY``; Yosys maps small ones to LUTs). True: every
        table (N = 1). None (default): N = the block RAM primitive's
        :attr:`~ikseries.constraints.facts.Primitive.min_depth` when ``dsp_registers`` names a
        family that has one, else False.

    Attributes
    ----------
    i : In(stream.Signature(input_layout(plan)))
    o : Out(stream.Signature(output_layout(plan)))

    Latency
    -------
    ``latency`` cycles from an input transfer to its output transfer while ``o.ready`` is
    high (:func:`modulo_latency`: the schedule's length, plus ``BUFFER_LATENCY`` for a core
    that never stalls, see below; a multiplication takes ``MUL_LATENCY`` cycles, one split in
    limbs ``WIDE_MUL_LATENCY``, a clamp ``CLAMP_LATENCY`` (one cycle if the limits it reaches
    are bit tests: 0 below, ``2**k - 1`` above), a table read ``TABLE_LATENCY``, or
    ``REGISTERED_TABLE_LATENCY`` if its table is registered (``registered_tables``), other
    operations one, an addition of bit fields that cannot overlap (a grid's cell address) none
    (an OR, wiring); the clamp of an input port none: the input register takes the clamped
    port value).

    Throughput
    ----------
    One input every ``initiation_interval`` cycles. At an interval of 1 (:func:`stall_free`)
    the pipeline never stalls: its outputs go through a FIFO of ``latency + 1`` words, and
    ``i.ready`` is low only while every word is taken or promised to a target in flight, so
    with ``o.ready`` high it stays high. At longer intervals ``i.ready`` is high one cycle in
    ``initiation_interval`` (when the phase counter is 0), and when ``o.valid`` is high and
    ``o.ready`` low, everything, the phase counter included, stalls.
    """

    def __init__(self, plan: Plan, initiation_interval: int, dsp: tuple[int, int] | None = dsp_size("ecp5"),
                 dsp_registers: str | None = None, registered_tables: bool | int | None = None):
        if not isinstance(plan, Plan):
            raise TypeError(f"plan must be a Plan, not {plan!r}")
        if isinstance(initiation_interval, bool) or not isinstance(initiation_interval, int) \
                or initiation_interval < 1:
            raise ValueError(f"initiation_interval must be an integer >= 1, not {initiation_interval!r}")
        check_dsp(dsp)
        self._primitive = check_dsp_registers(dsp_registers, dsp)
        self._table_primitive = table_primitive(dsp_registers)
        self._plan = plan
        self._dsp = dsp
        self._dsp_registers = dsp_registers
        self._schedule = modulo_schedule(plan, initiation_interval, dsp,
                                         self._registered_depth(registered_tables, dsp_registers))
        super().__init__({
            "i": In(stream.Signature(input_layout(plan))),
            "o": Out(stream.Signature(output_layout(plan))),
        })

    @property
    def plan(self) -> Plan:
        return self._plan

    @staticmethod
    def _registered_depth(registered_tables, dsp_registers) -> int | None:
        """The fewest words of a registered table (None: none is) for ``registered_tables``."""
        if registered_tables is None:
            return default_registered_depth(dsp_registers)
        if isinstance(registered_tables, bool):
            return 1 if registered_tables else None
        if not isinstance(registered_tables, int) or registered_tables < 1:
            raise ValueError(f"registered_tables must be None, True, False or an integer >= 1 (the fewest "
                             f"words of a registered table), not {registered_tables!r}")
        return registered_tables

    @property
    def registered_tables(self) -> int | None:
        """The fewest words of a registered table; None: no table is registered."""
        return self._schedule.registered_depth

    def _registered_groups(self) -> dict[int, list[int]]:
        """The lut groups (:func:`~ikseries.hdl.evaluator.lut_groups`) whose tables are registered."""
        return {index: luts for index, luts in lut_groups(self._plan).items()
                if table_registered(self._plan, luts[0], self.registered_tables)}

    @property
    def primitives(self) -> tuple:
        """The vendor primitives the core instantiates (:class:`~ikseries.constraints.facts.Primitive`)."""
        if self._dsp_registers is None:
            return ()
        table = (self._table_primitive,) if self._table_primitive and self._registered_groups() else ()
        return (self._primitive, *table)

    @property
    def schedule(self) -> ModuloSchedule:
        return self._schedule

    @property
    def latency(self) -> int:
        return modulo_latency(self._schedule)

    @property
    def initiation_interval(self) -> int:
        return self._schedule.initiation_interval

    @property
    def multipliers(self) -> int:
        return self._schedule.units

    def _product(self, m, a, b, en, name):
        """``a * b`` two enabled clock edges later: operand registers, then a product register
        (in the fabric; with ``dsp_registers`` the primitive's own input and output registers,
        cleared by the domain's reset like the fabric ones)."""
        wa, wb = len(a), len(b)
        p = Signal(signed(wa + wb + 1), name=f"{name}_p")   # + 1: unsigned limb x unsigned limb
        if self._dsp_registers is None:
            ar, br = Signal(a.shape(), name=f"{name}_a"), Signal(b.shape(), name=f"{name}_b")
            with m.If(en):
                m.d.sync += [ar.eq(a), br.eq(b), p.eq(ar * br)]
            return p
        m.submodules[f"{name}_dsp"] = self._primitive.instance(m, a, b, p, en)
        return p

    def elaborate(self, platform):
        m = Module()
        plan, sch = self._plan, self._schedule
        phase = Signal(range(sch.initiation_interval), name="phase")
        if stall_free(sch.initiation_interval):
            en, end = Const(1), self._output_buffer(m)
        else:
            en, end = Signal(name="en"), self.o
            m.d.comb += [en.eq(~self.o.valid | self.o.ready), self.i.ready.eq(en & (phase == 0))]
        with m.If(en):
            m.d.sync += phase.eq(Mux(phase == sch.initiation_interval - 1, 0, phase + 1))
        values = _NodeValues(m, plan, sch, en, phase)
        registered = self._registered_groups()
        live = plan.live()
        for i, n in enumerate(plan.nodes):
            if i not in live and _kind(plan, i) != "port":
                continue     # a sum only the certifier reads
            if _kind(plan, i) not in ("wiring", "constant", "product") and not (
                    _kind(plan, i) == "table" and n.args[0] in registered):
                self._operation(m, values, i)
        for index, luts in registered.items():
            self._registered_table(m, values, index, luts)
        products = {}     # multiplier -> its product register
        for u in range(sch.units):
            mine = [i for i in range(len(plan.nodes)) if sch.unit[i] == u]
            if mine:
                products[u] = self._multiplier(m, values, u, mine)
        for w, u in values.bypass:
            m.d.comb += w.eq(products[u])
        lat = sch.latency
        valid = Signal(lat, name="valid")    # valid[k]: a target accepted k + 1 cycles ago
        with m.If(en):
            m.d.sync += valid.eq(Cat(self.i.valid & self.i.ready, valid[:lat - 1]))
        m.d.comb += end.valid.eq(valid[lat - 1])
        for o in plan.outputs:
            m.d.comb += end.payload[o.name].eq(values.read(o.node, lat))
        return m

    def _output_buffer(self, m):
        """The outputs of a pipeline that never stalls, through an :class:`OutputBuffer` with a
        word for every target in flight: at one target a cycle a word is promised for the
        latency (the pipeline's cycles and the buffer's), then for the read's return to
        ``room``, so ``latency + 1`` words keep ``i.ready`` high while ``o.ready`` is. Returns
        the stream (valid and payload) the pipeline's last cycle drives."""
        depth = self.latency + 1
        m.submodules.buffer = buffer = OutputBuffer(output_layout(self._plan), depth)
        wiring.connect(m, wiring.flipped(self.o), buffer.o)
        m.d.comb += [self.i.ready.eq(buffer.room), buffer.promise.eq(self.i.valid & buffer.room)]
        return buffer.w

    def _operation(self, m, values: _NodeValues, i: int):
        """The register of node ``i``, neither a multiplication nor wiring nor a constant: an
        input register (the port, or clamped), a clamp (one stage if its reachable limits are
        bit tests, else two), or one registered operation at its start phase."""
        n = self._plan.nodes[i]
        reg = values.chains[i][0]      # not a product: read at least in its ready cycle
        if _kind(self._plan, i) == "port" or _input_clamp(self._plan, i):
            port = self.i.payload[(self._plan.nodes[n.args[0]] if n.args else n).param]
            with m.If(self.i.ready):
                m.d.sync += reg.eq(node_expression(n, [port]) if n.args else port)
            return
        s = self._schedule.start[i]
        ops = [values.read(a, s) for a in n.args]
        if n.op == "lut" and (k := _index_rotation(self._plan, n.args[0])):
            with m.If(values.at_phase(s)):     # the table laid out for the offset-free cell number
                m.d.sync += reg.eq(Array(rotated_table(self._plan, n.args[0], list(n.param), k))[ops[0]])
            return
        if n.op == "clamp" and (tests := _clamp_tests(self._plan, i)) is not None:
            v = ops[0]       # the limits it reaches are bit tests: one cycle
            for limit, test in reversed(tests):
                v = Mux(test(ops[0]), limit, v)
            with m.If(values.at_phase(s)):
                m.d.sync += reg.eq(v)
            return
        if n.op == "clamp":   # comparisons registered with the value, then the selection
            lo, hi = n.param
            x = Signal.like(ops[0], name=f"n{i}_clamp_x")
            below, above = Signal(name=f"n{i}_clamp_lt"), Signal(name=f"n{i}_clamp_gt")
            with m.If(values.at_phase(s)):
                m.d.sync += [x.eq(ops[0]), below.eq(ops[0] < lo), above.eq(ops[0] > hi)]
            with m.If(values.at_phase(s + 1)):
                m.d.sync += reg.eq(Mux(below, lo, Mux(above, hi, x)))
            return
        v = node_expression(n, ops)
        with m.If(values.at_phase(s)):
            m.d.sync += reg.eq(v)

    def _registered_table(self, m, values: _NodeValues, index: int, luts: list):
        """The ROM of the ``luts`` read at node ``index`` (:func:`~ikseries.hdl.tables.registered_rom`):
        read at their start phase, its output register written at the next; each lut's
        register is its field of that output register."""
        s = self._schedule.start[luts[0]]
        assert all(self._schedule.start[li] == s for li in luts)   # one operand, one start
        fields = registered_rom(m, self._plan, index, luts, values.read(index, s), values.at_phase(s),
                                values.at_phase(s + 1), self._table_primitive, _index_rotation(self._plan, index))
        for li, f in fields.items():
            if values.chains[li]:
                m.d.comb += values.chains[li][0].eq(f)

    def _multiplier(self, m, values: _NodeValues, u: int, mine: list):
        """Shared multiplier ``u`` for the multiplications ``mine``: operands selected by
        phase, registered; product registered; each multiplication's node register captures
        the product at its phase. The product register."""
        sch, nodes, ii = self._schedule, self._plan.nodes, self._schedule.initiation_interval
        wa, wb = sch.operand_widths[u]
        a, b = Signal(signed(wa), name=f"mul{u}_a_next"), Signal(signed(wb), name=f"mul{u}_b_next")
        with m.Switch(values.phase):
            for i in mine:
                s = sch.start[i]
                x, y = nodes[i].args[::-1] if sch.swap[i] else nodes[i].args
                with m.Case(s % ii):
                    m.d.comb += [a.eq(values.read(x, s)), b.eq(values.read(y, s))]
        if sch.unit_latency[u] == MUL_LATENCY:
            p = self._product(m, a, b, values.en, f"mul{u}")
        else:
            p = self._limb_product(m, a, b, values.en, f"mul{u}")
        for i in mine:
            if values.chains[i]:
                with m.If(values.at_phase(sch.ready[i])):
                    m.d.sync += values.chains[i][0].eq(p)
        return p

    def _limb_product(self, m, a, b, en, name):
        """``a * b`` in DSP-sized limbs: registered partial products, then their registered sum."""
        wa, wb = len(a), len(b)
        terms = [self._product(m, xa, xb, en, f"{name}_{j}{k}") << (sa + sb)
                 for j, (xa, sa) in enumerate(_limbs(a, wa, self._dsp[0] - 1))
                 for k, (xb, sb) in enumerate(_limbs(b, wb, self._dsp[1] - 1))]
        p = Signal(signed(wa + wb), name=f"{name}_p")
        total = terms[0]
        for t in terms[1:]:
            total = total + t
        with m.If(en):
            m.d.sync += p.eq(total)
        return p


class _NodeValues:
    """The values of the plan's nodes for the target being evaluated, by cycle of its schedule.

    Builds every registered node's chain of registers (``chains[i][0]`` written at the end of
    cycle ``held - 1``, ``chains[i][j]`` takes ``chains[i][j - 1]`` at the same phase; none for
    a product only read by bypass); :meth:`read` gives a node's value in a cycle: a constant,
    combinational wiring (one signal per node and cycle), the product register (``bypass``,
    wired to it by the evaluator) or the register of the chain that holds it then.
    """

    def __init__(self, m, plan: Plan, sch: ModuloSchedule, en, phase):
        self.m, self.plan, self.sch, self.en, self.phase = m, plan, sch, en, phase
        self.last = sch.last_read(plan)
        self.held = sch.held_from(plan)
        self.chains: dict = {}
        self.wires: dict = {}
        self.bypass: list = []       # (wire, multiplier): a product read from the product register
        ii = sch.initiation_interval
        live = plan.live()
        for i, n in enumerate(plan.nodes):
            if _kind(plan, i) in ("wiring", "constant") or (i not in live and _kind(plan, i) != "port"):
                continue
            depth = max(0, (self.last[i] - self.held[i]) // ii + 1)
            self.chains[i] = [Signal(node_shape(n), name=f"n{i}_{n.op}" + (f"_r{j}" if j else ""))
                              for j in range(depth)]
            with m.If(self.at_phase(self.held[i] - 1)):
                m.d.sync += [self.chains[i][j].eq(self.chains[i][j - 1]) for j in range(1, depth)]

    def at_phase(self, c):
        """Enabled, in the phase of cycle ``c``."""
        return self.en & (self.phase == c % self.sch.initiation_interval)

    def read(self, i, c):
        """Value of node ``i`` of the target being evaluated, during its cycle ``c``."""
        n, sch = self.plan.nodes[i], self.sch
        if _kind(self.plan, i) == "constant":
            return node_expression(n, [])
        if _kind(self.plan, i) == "wiring":
            if (i, c) in self.wires:
                return self.wires[i, c]
            v = _wiring_expression(self.plan, i, [self.read(a, c) for a in n.args])
            w = self.wires[i, c] = Signal(node_shape(n), name=f"n{i}_{n.op}_c{c}")
            self.m.d.comb += w.eq(v)
            return w
        if c < sch.ready[i] or c > self.last[i]:
            raise AssertionError(f"node {i} read at cycle {c} outside [{sch.ready[i]}, {self.last[i]}]")
        if c < self.held[i]:         # the product register, in the cycle after the product
            if (i, c) not in self.wires:
                self.wires[i, c] = Signal(node_shape(n), name=f"n{i}_mul_bypass")
                self.bypass.append((self.wires[i, c], sch.unit[i]))
            return self.wires[i, c]
        return self.chains[i][(c - self.held[i]) // sch.initiation_interval]
