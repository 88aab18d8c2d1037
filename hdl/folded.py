"""Folded evaluator: the whole plan on a few shared units, driven by a microcode ROM."""
from __future__ import annotations

import functools
import operator

from amaranth.hdl import Cat, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..fit.plan import Plan
from .evaluator import input_layout, output_layout
from .limbmul import LimbMultiplier, check_dsp_registers
from .planmemo import per_plan
from .schedule import ALU_OPS, Program, compile_program

__all__ = ["FoldedEvaluator", "folded_program", "microcode_layout"]


def _bits(n: int) -> int:
    return max(1, (n - 1).bit_length())


@per_plan
def folded_program(plan: Plan, multipliers: int = 1, dsp: tuple[int, int] | None = None) -> Program:
    """:func:`~ikseries.hdl.schedule.compile_program` of ``plan``, computed once per plan object
    and options (the architecture's timing and the evaluator share one program; nothing
    changes a program once compiled)."""
    return compile_program(plan, multipliers, dsp)


def microcode_layout(prog: Program) -> data.StructLayout:
    """Fields of one microcode word (everything the machine does in one cycle).

    ``rx``/``ry``: value-memory read addresses; ``go``: one bit per multiplier, latch the
    read register (data read two words before); ``tab`` (only when the plan has ``lut``
    nodes): table number of the ROM lookup of the index in the read register; ``alu``: ALU
    selection (operation) of the operands read three words before; ``src``: write-back
    source, registered (0 ALU, 1..k multipliers, k+1.. input registers, then the table ROM
    if any); ``view``: index of the shift ``(x >> a) << b`` applied to the source registered
    the word before; ``we``/``wa``: write that shifted value at address ``wa`` (one word
    later); ``cap``: one bit per output, capture it (one word later). The exact offsets are
    in :mod:`ikseries.hdl.schedule` (Timing).
    """
    k = prog.multipliers
    fields = {
        "rx": unsigned(_bits(prog.depth)), "ry": unsigned(_bits(prog.depth)),
        "alu": unsigned(_bits(len(ALU_OPS))), "go": unsigned(k),
        "we": unsigned(1), "wa": unsigned(_bits(prog.depth)),
        "src": unsigned(_bits(1 + k + len(prog.plan.inputs) + bool(prog.tables))),
        "view": unsigned(_bits(len(prog.views))),
        "cap": unsigned(len(prog.plan.outputs)),
    }
    if prog.tables:
        fields["tab"] = unsigned(_bits(len(prog.tables)))
    return data.StructLayout(fields)


class FoldedEvaluator(wiring.Component):
    """Evaluates every output of ``plan`` on ``multipliers`` shared multipliers and one ALU.

    The plan is lowered, list-scheduled and register-allocated at construction
    (:func:`folded_program`); one evaluation then runs through a
    horizontal microcode ROM, one word per cycle. Constants are pre-loaded into the value
    memory (``Memory`` with ``init``: block RAM), which also holds the intermediates (two
    read ports, one write port). The ``lut`` tables are one more ROM (``Memory`` with
    ``init``), one entry per (table, index value), addressed by the table number from the
    microcode above the low bits of the index read from the value memory; its synchronous
    read is written back like an ALU result (see :mod:`ikseries.hdl.schedule`); ``mask`` is an
    ALU ``and``, ``index`` a shift view. Every stored value is the exact integer of a plan node
    (shifts applied on the write port, floor for ``shr``), so the outputs equal
    :func:`ikseries.sim.golden.evaluate` for every input, bit for bit. The datapath is as
    wide as the plan needs (``program.store_width``, ``program.acc_width``), whatever plan
    is given.

    Parameters
    ----------
    plan : Plan
    multipliers : int
        Number of multiplier units (one DSP block each when ``dsp`` is given).
    dsp : (int, int) or None
        Signed operand widths of the DSP multiplier (a family's
        :attr:`~ikseries.constraints.facts.Family.dsp`). Wider products are
        computed limb by limb (:class:`LimbMultiplier`). None: full-width multipliers.
    dsp_registers : None or str
        A family with a DSP primitive: each unit's limb product on that primitive with its own
        registers (``dsp`` must be its size; see :class:`LimbMultiplier`), same timing and
        values; the Amaranth simulator cannot run it (simulate the core with None, the exported
        Verilog with the primitive's model). None (default): fabric registers.
    held_input : bool
        The sender holds ``i.payload`` from the input transfer until ``o.valid`` (its own
        register, as the :class:`~ikseries.hdl.dispatch.Dispatcher`'s target), so the evaluator
        reads the port itself instead of an input register of its own (16 flip-flops a
        coordinate less, each a logic cell of its own on iCE40: a register fed by a register).
        Default False: the payload is registered at the transfer.
    rotate_outputs : bool
        Adds ``rotate``: each strobe moves the output registers one place towards the first
        output (the first takes the last's), for a reader that takes the widths one at a time
        from the first (no multiplexer: the move packs into the registers' own logic cells).
        The reader strobes it exactly once per output per evaluation (or never), so the
        registers are in order again when the next evaluation captures into them. Default False.

    Attributes
    ----------
    i : In(stream.Signature(input_layout(plan)))
    o : Out(stream.Signature(output_layout(plan)))
    rotate : In(1)
        With ``rotate_outputs``: a strobe while ``o.valid`` (the machine is idle: no capture meets it).
    program : Program
        The schedule and microcode.

    The long paths are registered for clock speed: the microcode ROM's word (the ROM reads
    two words ahead, its address from a counter of its own; word 0 is a constant loaded while
    idle; a copy of the running flag gates the datapath, so the handshake's flag drives only
    the sequencer), the memory's read data before
    the ALU, multipliers and table ROM, the ALU between its sum/comparison and its selection,
    and the write-back between the source selection and the view shift, and again before the
    memory write port and the output registers. The compiler's timing model
    (:mod:`ikseries.hdl.schedule`, Timing) accounts for every stage: an operation's result is
    written ``ALU_LATENCY`` (4), ``LUT_LATENCY`` (3) or ``program.mul_latency`` cycles after
    its issue and can be read ``WRITE_DELAY + 1`` (3) cycles after that.

    Latency
    -------
    ``latency`` = ``program.steps + 1`` cycles from an input transfer to ``o.valid``
    (``program.steps``: last write + ``WRITE_DELAY`` + 1, the length of the schedule,
    every pipeline stage included).

    Throughput
    ----------
    One evaluation at a time: ``i.ready`` is high only when the machine is idle and its
    output register is free (empty, or transferred in the same cycle), so inputs are
    accepted every ``initiation_interval`` = ``latency`` cycles while ``o.ready`` is high.
    A held output (``o.ready`` low) blocks the next input, never an evaluation in flight.
    """

    def __init__(self, plan: Plan, multipliers: int = 1, dsp: tuple[int, int] | None = None,
                 dsp_registers: str | None = None, held_input: bool = False, rotate_outputs: bool = False):
        self._prog = folded_program(plan, multipliers, dsp)
        check_dsp_registers(dsp_registers, self._prog.dsp)
        self._plan, self._dsp_registers = plan, dsp_registers
        self._held_input, self._rotate = bool(held_input), bool(rotate_outputs)
        super().__init__({
            "i": In(stream.Signature(input_layout(plan))),
            "o": Out(stream.Signature(output_layout(plan))),
            **({"rotate": In(1)} if self._rotate else {}),
        })

    @property
    def plan(self) -> Plan:
        return self._plan

    @property
    def program(self) -> Program:
        return self._prog

    @property
    def multipliers(self) -> int:
        return self._prog.multipliers

    @property
    def dsp(self):
        return self._prog.dsp

    @property
    def dsp_registers(self) -> str | None:
        return self._dsp_registers

    @property
    def latency(self) -> int:
        return self._prog.steps + 1

    @property
    def initiation_interval(self) -> int:
        return self._prog.steps + 1

    def elaborate(self, platform):
        m = Module()
        layout = microcode_layout(self._prog)
        code, rx, ry, wr = self._memories(m, layout)
        # microcode register after the ROM's read: the ROM reads two words ahead, word 0
        # comes from a constant (the machine is idle, or in its last step, before step 0)
        w = Signal(layout, init=self._prog.words[0])
        running, busy, in_reg, hot = self._sequencer(m, layout, code, w)
        x, y = self._read_register(m, w, rx, ry)
        alu = self._alu(m, w, x, y)
        muls = self._multipliers(m, w, busy, x, y)
        lut = self._tables(m, w, x)
        wb_data, wb_cap = self._write_back(m, w, hot, busy, in_reg, alu, muls, lut, wr)
        self._outputs(m, wb_data, wb_cap)
        return m

    def _memories(self, m, layout):
        """The microcode ROM and the value memory; the ROM's read port, the memory's two read
        ports and its write port."""
        prog = self._prog
        m.submodules.microcode = rom = Memory(shape=layout, depth=prog.steps, init=prog.words)
        m.submodules.values = mem = Memory(shape=signed(prog.store_width), depth=prog.depth,
                                           init=prog.memory_init())
        code = rom.read_port()
        rx, ry = mem.read_port(), mem.read_port()
        wr = mem.write_port()
        return code, rx, ry, wr

    def _sequencer(self, m, layout, code, w):
        """Handshake, step counter and microcode fetch; the running flag, its copy for the
        datapath and the input register."""
        prog, plan = self._prog, self._plan
        steps = prog.steps
        running = Signal()
        # a second running flag for the datapath's gates (the microcode register, multiplier
        # starts, write enables, the input register's load): running's own loads are then the
        # sequencer's, not a net of some hundred loads in front of pc and the handshake; its
        # own feedback keeps Yosys from merging the two
        busy = Signal(name="busy")
        pc = Signal(range(steps))
        last = pc == steps - 1
        in_reg = Signal(input_layout(plan))
        accept = Signal()
        # the ROM address of the next cycle's read from a counter of its own (an adder and a
        # comparison of pc in front of the block RAM's address were the core's longest path):
        # pc + 2 while that is in the program, else 0 (2 after an input transfer, which
        # itself reads word 1; fetch counts up to steps - 1, then rests at 0)
        fetch = Signal(range(steps), name="fetch")
        m.d.comb += [self.i.ready.eq(~running & (~self.o.valid | self.o.ready)),
                     accept.eq(self.i.valid & self.i.ready),
                     code.addr.eq(Mux(accept, 1 % steps, fetch))]
        with m.If(accept):
            m.d.sync += fetch.eq(2 if 2 < steps else 0)
        with m.Elif((fetch != 0) & (fetch != steps - 1)):
            m.d.sync += fetch.eq(fetch + 1)
        with m.Else():
            m.d.sync += fetch.eq(0)
        # the write-back's source one-hot, registered with the word: an and-or selection is a
        # LUT level shorter than a multiplexer on the encoded field
        n_src = 1 + prog.multipliers + len(plan.inputs) + bool(prog.tables)
        hot = Signal(n_src, name="src_hot", init=1 << prog.words[0]["src"])
        with m.If(busy & ~last):
            m.d.sync += [w.eq(code.data), hot.eq(Cat(*(code.data.src == v for v in range(n_src))))]
        with m.Else():
            m.d.sync += [w.eq(layout.const(prog.words[0])), hot.eq(1 << prog.words[0]["src"])]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        if self._held_input:    # the sender's own register holds the target: no copy
            m.d.comb += in_reg.eq(self.i.payload)
        else:
            with m.If(~busy):   # idle: the input register follows the port (latched at accept)
                m.d.sync += in_reg.eq(self.i.payload)
        with m.If(accept):
            m.d.sync += [running.eq(1), busy.eq(1), pc.eq(0)]
        with m.Elif(running):
            m.d.sync += pc.eq(pc + 1)
            with m.If(last):
                m.d.sync += [running.eq(0), busy.eq(0), pc.eq(0), self.o.valid.eq(1)]
        return running, busy, in_reg, hot

    def _read_register(self, m, w, rx, ry):
        """The read register: the units see the data read two cycles before (memory, register)."""
        m.d.comb += [rx.addr.eq(w.rx), ry.addr.eq(w.ry)]
        x, y = Signal.like(rx.data), Signal.like(ry.data)
        m.d.sync += [x.eq(rx.data), y.eq(ry.data)]
        return x, y

    def _alu(self, m, w, x, y):
        """The ALU, two stages: sum and comparison of the read register, then the selection
        (operation from the word after the one that saw the operands)."""
        prog = self._prog
        sx, sy = Signal.like(x), Signal.like(y)
        s_sum, s_lt = Signal(signed(prog.store_width + 1)), Signal()
        m.d.sync += [sx.eq(x), sy.eq(y), s_sum.eq(x + y), s_lt.eq(x < y)]
        alu = Signal(signed(prog.store_width + 1))
        with m.Switch(w.alu):
            with m.Case(ALU_OPS.index("add")):
                m.d.sync += alu.eq(s_sum)
            with m.Case(ALU_OPS.index("max")):
                m.d.sync += alu.eq(Mux(s_lt, sy, sx))
            with m.Case(ALU_OPS.index("min")):
                m.d.sync += alu.eq(Mux(s_lt, sx, sy))
            with m.Case(ALU_OPS.index("and")):
                m.d.sync += alu.eq(sx & sy)
            with m.Default():
                m.d.sync += alu.eq(sx)
        return alu

    def _multipliers(self, m, w, running, x, y):
        """The multiplier units, started by the ``go`` bits on the read register."""
        prog = self._prog
        wa, wb = prog.mul_widths
        muls = []
        for u in range(prog.multipliers):
            mu = LimbMultiplier(wa, wb, prog.dsp, prog.acc_width, self._dsp_registers)
            m.submodules[f"mul{u}"] = mu
            m.d.comb += [mu.i.valid.eq(running & w.go[u]),
                         mu.i.payload.a.eq(x), mu.i.payload.b.eq(y)]
            muls.append(mu)
        return muls

    def _tables(self, m, w, x):
        """The coefficient table ROM's read port (None without tables): the ROM registers the
        address (index from the read register)."""
        prog = self._prog
        if not prog.tables:
            return None
        m.submodules.tables = tab = Memory(shape=signed(prog.lut_width), depth=len(prog.lut_init()),
                                           init=prog.lut_init())
        lut = tab.read_port()
        m.d.comb += lut.addr.eq(Cat(x[:prog.lut_index_bits], w.tab))
        return lut

    def _write_back(self, m, w, hot, running, in_reg, alu, muls, lut, wr):
        """Write-back, two registered stages: the source (field src of the word at w, one-hot in
        ``hot``), then the view shift with the memory write and output capture fields of the
        word at w + 1; the memory write happens at w + 2. The written value and the capture bits."""
        prog, plan = self._prog, self._plan
        sources = [alu, *(mu.o.payload for mu in muls), *(in_reg[inp.name] for inp in plan.inputs)]
        if prog.tables:
            sources.append(lut.data)
        wbv = Signal(signed(prog.wb_width))
        terms = []
        for v, src in enumerate(sources):
            t = Signal(signed(prog.wb_width), name=f"wb_src{v}")
            m.d.comb += t.eq(Mux(hot[v], src, 0))
            terms.append(t)
        m.d.sync += wbv.eq(functools.reduce(operator.or_, terms))
        value = Signal(signed(prog.store_width))
        with m.Switch(w.view):
            for v, (a, b) in enumerate(prog.views):
                with m.Case(v):
                    m.d.comb += value.eq((wbv >> a) << b)
        wb_en, wb_addr = Signal(), Signal.like(w.wa)
        wb_data, wb_cap = Signal.like(value), Signal.like(w.cap)
        m.d.sync += [wb_en.eq(running & w.we), wb_addr.eq(w.wa), wb_data.eq(value),
                     wb_cap.eq(Mux(running, w.cap, 0))]
        m.d.comb += [wr.en.eq(wb_en), wr.addr.eq(wb_addr), wr.data.eq(wb_data)]
        return wb_data, wb_cap

    def _outputs(self, m, wb_data, wb_cap):
        """The output registers (constant outputs wired), each captured from the write-back."""
        prog, plan = self._prog, self._plan
        if self._rotate:
            self._rotating_outputs(m, wb_data, wb_cap)
            return
        outs = Signal(output_layout(plan))
        for j, o in enumerate(plan.outputs):
            vid = prog.outputs[o.name]
            if vid in prog.const_value:
                m.d.comb += self.o.payload[o.name].eq(prog.const_value[vid])
            else:
                with m.If(wb_cap[j]):
                    m.d.sync += outs[o.name].eq(wb_data)
                m.d.comb += self.o.payload[o.name].eq(outs[o.name])

    def _rotating_outputs(self, m, wb_data, wb_cap):
        """The output registers of ``rotate_outputs``: a constant output is a register too (its
        value from reset, never captured), so that it moves round with the others."""
        prog, plan = self._prog, self._plan
        consts = [prog.const_value.get(prog.outputs[o.name]) for o in plan.outputs]
        regs = [Signal.like(self.o.payload[o.name], name=f"out_{o.name}", init=c or 0)
                for o, c in zip(plan.outputs, consts)]
        for j, (o, reg, const) in enumerate(zip(plan.outputs, regs, consts)):
            m.d.comb += self.o.payload[o.name].eq(reg)
            with m.If(self.rotate):
                m.d.sync += reg.eq(regs[(j + 1) % len(regs)])
            if const is None:
                with m.If(wb_cap[j]):
                    m.d.sync += reg.eq(wb_data)
