"""The core clock and reset of a board top: oscillator -> PLL -> ``sync`` domain, reset until lock.

:class:`BoardClocking` builds what a :class:`~ikseries.constraints.pll.ClockPlan` describes: the
board's oscillator pin, the PLL primitive with the plan's parameters (none when the plan runs
the core at the oscillator frequency) and the ``sync`` clock domain, held in reset until the PLL
locks and for the family's :data:`~ikseries.constraints.pll.POWER_ON_HOLD_S` more, then
released through :class:`amaranth.lib.cdc.ResetSynchronizer`.
"""
from __future__ import annotations

import math

from amaranth.hdl import ClockDomain, ClockSignal, Const, Elaboratable, Instance, Module, Signal
from amaranth.lib import io
from amaranth.lib.cdc import ResetSynchronizer

from ..constraints.boards import Board
from ..constraints.pll import POWER_ON_HOLD_S, ClockPlan

__all__ = ["BoardClocking"]

# EHXPLLL settings ecppll writes besides the dividers (loop filter, unused dynamic phase inputs)
_ECP5_FIXED = dict(
    p_PLLRST_ENA="DISABLED", p_INTFB_WAKE="DISABLED", p_STDBY_ENABLE="DISABLED", p_DPHASE_SOURCE="DISABLED",
    p_OUTDIVIDER_MUXA="DIVA", p_OUTDIVIDER_MUXB="DIVB", p_OUTDIVIDER_MUXC="DIVC", p_OUTDIVIDER_MUXD="DIVD",
    p_CLKOP_ENABLE="ENABLED", p_CLKOP_FPHASE=0, p_FEEDBK_PATH="CLKOP",
    a_ICP_CURRENT="12", a_LPF_RESISTOR="8", a_MFG_ENABLE_FILTEROPAMP="1", a_MFG_GMCREF_SEL="2",
    i_RST=Const(0), i_STDBY=Const(0), i_PHASESEL0=Const(0), i_PHASESEL1=Const(0), i_PHASEDIR=Const(1),
    i_PHASESTEP=Const(1), i_PHASELOADREG=Const(1), i_PLLWAKESYNC=Const(0), i_ENCLKOP=Const(0))


def _mhz_text(hz) -> str:
    return f"{float(hz) / 1e6:.6g}"


class BoardClocking(Elaboratable):
    """Oscillator, PLL and reset of the ``sync`` domain on ``board`` as ``plan`` says.

    Parameters
    ----------
    board : Board
    plan : ClockPlan
        Made for ``board`` (:func:`ikseries.constraints.pll.clock_plan`).

    The top defines :attr:`domain` (Amaranth 0.6 wants a domain defined where its users can see
    it); this module drives its clock and reset.

    Attributes
    ----------
    domain : ClockDomain
        The ``sync`` domain.
    clk : Signal
        The core clock (``sync``'s clock). nextpnr derives its constraint from the oscillator
        pin's and the PLL's parameters (a constraint on the signal itself would name a net the
        synthesised design may not keep).
    locked : Signal
        The PLL's lock output (constant 1 without a PLL).
    hold_cycles : int
        Core clock cycles the reset is held after lock besides the synchroniser's.

    Latency
    -------
    ``sync`` leaves reset ``hold_cycles`` + 2 (the synchroniser's stages) core clock cycles after
    the PLL locks; a loss of lock resets it at once (asynchronously).

    Throughput
    ----------
    Not a data path: one clock, one reset.
    """

    def __init__(self, board: Board, plan: ClockPlan):
        if not isinstance(board, Board):
            raise TypeError(f"board must be a Board, not {board!r}")
        if not isinstance(plan, ClockPlan):
            raise TypeError(f"plan must be a ClockPlan, not {plan!r}")
        if (plan.board, plan.family, plan.oscillator_hz) != (board.name, board.family, board.clock_hz):
            raise ValueError(f"plan must be a clock plan for board {board.name}, not for {plan.board}")
        self.board, self.plan = board, plan
        self.domain = ClockDomain("sync")
        self.clk = self.domain.clk
        self.locked = Signal()
        self.hold_cycles = math.ceil(POWER_ON_HOLD_S[board.family] * plan.achieved_hz)

    @staticmethod
    def _input(m, platform, name: str, number: int):
        """The oscillator through the platform's input buffer (a global one where the pin's
        attributes ask for it)."""
        m.submodules.osc_buffer = buf = io.Buffer("i", platform.request(name, number, dir="-"))
        return buf.i

    def _pll(self, m, platform, name: str, number: int):
        p, plan = self.plan.params, self.plan
        if plan.primitive == "SB_PLL40_PAD":
            pad = platform.request(name, number, dir="-")
            m.submodules.pll = Instance(
                "SB_PLL40_PAD", p_FEEDBACK_PATH="SIMPLE", p_DIVR=p["DIVR"], p_DIVF=p["DIVF"], p_DIVQ=p["DIVQ"],
                p_FILTER_RANGE=p["FILTER_RANGE"], io_PACKAGEPIN=pad.io, i_RESETB=Const(1), i_BYPASS=Const(0),
                o_PLLOUTGLOBAL=self.clk, o_LOCK=self.locked)
        elif plan.primitive == "SB_PLL40_CORE":
            ref = self._input(m, platform, name, number)
            m.submodules.pll = Instance(
                "SB_PLL40_CORE", p_FEEDBACK_PATH="SIMPLE", p_DIVR=p["DIVR"], p_DIVF=p["DIVF"], p_DIVQ=p["DIVQ"],
                p_FILTER_RANGE=p["FILTER_RANGE"], i_REFERENCECLK=ref, i_RESETB=Const(1), i_BYPASS=Const(0),
                o_PLLOUTGLOBAL=self.clk, o_LOCK=self.locked)
        else:
            ref, feedback = self._input(m, platform, name, number), Signal(name="pll_feedback")
            secondary = p["OUTPUT"] == "CLKOS"
            out = dict(o_CLKOP=feedback, o_CLKOS=self.clk, p_CLKOS_ENABLE="ENABLED", p_CLKOS_DIV=p["CLKOS_DIV"],
                       p_CLKOS_CPHASE=p["CLKOS_CPHASE"], p_CLKOS_FPHASE=0,
                       a_FREQUENCY_PIN_CLKOS=_mhz_text(plan.achieved_hz)) if secondary else \
                dict(o_CLKOP=feedback, a_FREQUENCY_PIN_CLKOP=_mhz_text(plan.achieved_hz))
            if not secondary:
                m.d.comb += self.clk.eq(feedback)
            m.submodules.pll = Instance(
                "EHXPLLL", **_ECP5_FIXED, p_CLKI_DIV=p["CLKI_DIV"], p_CLKFB_DIV=p["CLKFB_DIV"],
                p_CLKOP_DIV=p["CLKOP_DIV"], p_CLKOP_CPHASE=p["CLKOP_CPHASE"],
                a_FREQUENCY_PIN_CLKI=_mhz_text(plan.oscillator_hz), i_CLKI=ref, i_CLKFB=feedback,
                o_LOCK=self.locked, **out)

    def elaborate(self, platform):
        m = Module()
        name, number = self.board.resource("clock")
        if self.plan.primitive is None:
            m.d.comb += [self.clk.eq(self._input(m, platform, name, number)), self.locked.eq(1)]
        else:
            self._pll(m, platform, name, number)
        # the hold counter runs on the core clock without a reset of its own: bitstream zero,
        # restarted whenever the PLL loses lock
        m.domains.hold = ClockDomain("hold", reset_less=True, local=True)
        m.d.comb += ClockSignal("hold").eq(self.clk)
        done = Signal()
        if self.hold_cycles:
            count = Signal(range(self.hold_cycles + 1))
            with m.If(~self.locked):
                m.d.hold += count.eq(0)
            with m.Elif(count != self.hold_cycles):
                m.d.hold += count.eq(count + 1)
            m.d.comb += done.eq(self.locked & (count == self.hold_cycles))
        else:
            m.d.comb += done.eq(self.locked)
        m.submodules.reset_sync = ResetSynchronizer(~done, domain="sync")
        return m
