"""PLL facts of the families boards use, and the exact search for a PLL's divider settings.

:func:`clock_plan` turns a board's oscillator and a requested core clock into a
:class:`ClockPlan` before anything is elaborated: the PLL primitive, its divider parameters and
the frequency they achieve, as an exact fraction. A clock the PLL cannot reach within
:data:`CLOCK_TOLERANCE_PPM` is refused in one line naming the nearest frequency it can reach.

Limits (all frequencies in MHz, closed ranges):

========  =============  ===========  ============  ==============  ================================
family    input          PFD          VCO           output          dividers
========  =============  ===========  ============  ==============  ================================
iCE40     10 .. 133      10 .. 133    533 .. 1066   16 .. 275       DIVR 0..15, DIVF 0..127, DIVQ 1..6
ECP5      8 .. 400       3.125 .. 400 400 .. 800    3.125 .. 400    CLKI 1..128, CLKFB 1..80, CLKOP/OS 1..128
========  =============  ===========  ============  ==============  ================================

iCE40: "sysCLOCK PLL" table of the iCE40 UltraPlus data sheet (FPGA-DS-02008) and the iCE40
sysCLOCK PLL Design and Usage Guide (TN1251), SIMPLE feedback: f_out = f_in (DIVF + 1) /
((DIVR + 1) 2^DIVQ); FILTER_RANGE from the PFD frequency as the guide's table (and icepll) set it.
ECP5: "sysCLOCK PLL Timing" of the ECP5 data sheet (FPGA-DS-02012) and TN1263, feedback from
CLKOP: f_CLKOP = f_in CLKFB_DIV / CLKI_DIV, f_VCO = f_CLKOP CLKOP_DIV; when no CLKOP frequency is
close enough, the core clock is the secondary output CLKOS = f_VCO / CLKOS_DIV (CLKOP then only
closes the loop), which reaches many more frequencies (``ecppll --highres``).

Tie-breaking follows the vendor tools' habits, so that the results are reproducible and agree
with ``icepll`` / ``ecppll``: iCE40 the smallest (DIVR, DIVF, DIVQ) among the closest; ECP5 the
VCO nearest 600 MHz, then the smallest dividers.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from .boards import Board, board as find_board

__all__ = ["CLOCK_TOLERANCE_PPM", "POWER_ON_HOLD_S", "ICE40_PLL", "ECP5_PLL", "PLL_FAMILIES", "ICE40_PLL_PADS",
           "ClockPlan", "ClockPlanError", "clock_plan", "search_pll"]

#: the largest accepted deviation of the achieved core clock from the requested one, in parts per
#: million (0.1 %: a UART's baud-rate divisor and the PWM period stay well within their own
#: tolerances, and the exact achieved frequency is reported for everything that counts ticks)
CLOCK_TOLERANCE_PPM = 1000

_MHZ = 1_000_000

#: seconds the core stays in reset after the PLL locks, by family: iCE40 block RAMs read as zeroes
#: for ~3 us after configuration (no erratum; icestorm issue 76), and Amaranth's own iCE40 reset
#: waits 5 times that
POWER_ON_HOLD_S = {"ice40": 15e-6, "ecp5": 0.0}


@dataclass(frozen=True)
class PllLimits:
    """Legal ranges of one family's PLL (Hz, closed intervals) and of its dividers."""
    family: str
    primitive: str
    f_in: tuple[int, int]
    f_pfd: tuple[Fraction, Fraction]
    f_vco: tuple[int, int]
    f_out: tuple[Fraction, Fraction]
    dividers: tuple[tuple[str, int, int], ...]

    def divider_range(self, name: str) -> range:
        lo, hi = next((lo, hi) for n, lo, hi in self.dividers if n == name)
        return range(lo, hi + 1)


def _mhz(x) -> Fraction:
    return Fraction(x) * _MHZ


ICE40_PLL = PllLimits(
    "ice40", "SB_PLL40", (10 * _MHZ, 133 * _MHZ), (_mhz(10), _mhz(133)), (533 * _MHZ, 1066 * _MHZ),
    (_mhz(16), _mhz(275)), (("DIVR", 0, 15), ("DIVF", 0, 127), ("DIVQ", 1, 6)))

ECP5_PLL = PllLimits(
    "ecp5", "EHXPLLL", (8 * _MHZ, 400 * _MHZ), (_mhz("3.125"), _mhz(400)), (400 * _MHZ, 800 * _MHZ),
    (_mhz("3.125"), _mhz(400)),
    (("CLKI_DIV", 1, 128), ("CLKFB_DIV", 1, 80), ("CLKOP_DIV", 1, 128), ("CLKOS_DIV", 1, 128)))

#: family name -> its PLL limits
PLL_FAMILIES = {p.family: p for p in (ICE40_PLL, ECP5_PLL)}

#: (device, package) -> the pins that feed an iCE40 PLL directly (SB_PLL40_PAD); a clock on any
#: other pin reaches the PLL through a global buffer (SB_PLL40_CORE). The UP5K's only PLL sits
#: on pin 35's I/O pair in the SG48 package: nextpnr finds no place for an SB_PLL40_CORE while
#: pin 35 is in use as an input, and places SB_PLL40_PAD there.
ICE40_PLL_PADS = {("iCE40UP5K", "SG48"): ("35",)}

# TN1251 table 6: loop-filter setting by the PFD frequency (upper bounds, MHz, exclusive)
_ICE40_FILTER = ((17, 1), (26, 2), (44, 3), (66, 4), (101, 5))


class ClockPlanError(ValueError):
    """A core clock the board's PLL cannot make (the message names the nearest it can)."""


@dataclass(frozen=True)
class ClockPlan:
    """How a board's oscillator becomes the core clock, computed before anything is built.

    Parameters
    ----------
    board : str
        The board's registry name.
    family : str
        Its FPGA family.
    oscillator_hz : int
        The board's oscillator.
    requested_hz : int
        The core clock asked for.
    achieved_hz : Fraction
        The core clock the settings give, exactly.
    primitive : str or None
        The PLL primitive (``SB_PLL40_PAD``, ``SB_PLL40_CORE``, ``EHXPLLL``); None when the
        oscillator is the core clock.
    parameters : tuple of (str, int or str)
        The primitive's divider and mode parameters, in the order the vendor tools print them.
    vco_hz, pfd_hz : Fraction or None
        The PLL's VCO and phase-detector frequencies (None without a PLL).
    """
    board: str
    family: str
    oscillator_hz: int
    requested_hz: int
    achieved_hz: Fraction
    primitive: str | None
    parameters: tuple[tuple[str, object], ...]
    vco_hz: Fraction | None
    pfd_hz: Fraction | None

    def __post_init__(self):
        if self.family not in PLL_FAMILIES:
            raise ValueError(f"family must be one of {', '.join(PLL_FAMILIES)}, not {self.family!r}")
        for name in ("oscillator_hz", "requested_hz"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"{name} must be a positive integer (Hz), not {v!r}")
        if not isinstance(self.achieved_hz, Fraction) or self.achieved_hz <= 0:
            raise ValueError(f"achieved_hz must be a positive Fraction, not {self.achieved_hz!r}")
        if self.primitive is None and (self.parameters or self.achieved_hz != self.oscillator_hz):
            raise ValueError("a clock plan without a PLL must run at the oscillator frequency with no parameters")
        if abs(self.error_ppm) > CLOCK_TOLERANCE_PPM:
            raise ValueError(f"achieved_hz must be within {CLOCK_TOLERANCE_PPM} ppm of {self.requested_hz}, "
                             f"not {float(self.achieved_hz):.9g}")
        object.__setattr__(self, "parameters", tuple(self.parameters))

    @property
    def error_ppm(self) -> float:
        """(achieved - requested) / requested, in parts per million."""
        return float((self.achieved_hz - self.requested_hz) / self.requested_hz * 1_000_000)

    @property
    def exact(self) -> bool:
        return self.achieved_hz == self.requested_hz

    @property
    def params(self) -> dict:
        return dict(self.parameters)

    def describe(self) -> str:
        """One line: requested and achieved clock and how."""
        how = (f"the {self.oscillator_hz / 1e6:g} MHz oscillator directly" if self.primitive is None else
               f"{self.primitive} " + ", ".join(f"{k}={v}" for k, v in self.parameters if isinstance(v, int))
               + f" (VCO {float(self.vco_hz) / 1e6:.6g} MHz)")
        return (f"{self.board}: core clock {float(self.achieved_hz) / 1e6:.9g} MHz "
                f"(requested {self.requested_hz / 1e6:g} MHz, {self.error_ppm:+.1f} ppm) from {how}")

    def record(self) -> dict:
        """JSON form for manifests and reports."""
        return {"board": self.board, "oscillator_hz": self.oscillator_hz, "requested_hz": self.requested_hz,
                "achieved_hz": float(self.achieved_hz),
                "achieved_hz_exact": [self.achieved_hz.numerator, self.achieved_hz.denominator],
                "error_ppm": self.error_ppm, "primitive": self.primitive, "parameters": dict(self.parameters),
                "vco_hz": None if self.vco_hz is None else float(self.vco_hz),
                "pfd_hz": None if self.pfd_hz is None else float(self.pfd_hz)}


def _within(x, bounds) -> bool:
    return bounds[0] <= x <= bounds[1]


def _ice40_candidates(f_in: int, target: int):
    """(error, tie-break key, achieved, parameters, vco, pfd) of every legal SIMPLE-feedback
    setting."""
    lim = ICE40_PLL
    for divr in lim.divider_range("DIVR"):
        pfd = Fraction(f_in, divr + 1)
        if not _within(pfd, lim.f_pfd):
            continue
        for divf in lim.divider_range("DIVF"):
            vco = pfd * (divf + 1)
            if not _within(vco, lim.f_vco):
                continue
            for divq in lim.divider_range("DIVQ"):
                out = vco / 2 ** divq
                if _within(out, lim.f_out):
                    yield abs(out - target), (divr, divf, divq), out, \
                        (("DIVR", divr), ("DIVF", divf), ("DIVQ", divq)), vco, pfd


def _ecp5_candidates(f_in: int, target: int):
    """The same for the ECP5: the legal CLKOP settings (feedback output = core clock) and, for
    each, the legal CLKOS_DIV nearest the target (the error grows monotonically away from it).
    Errors are screened in integers (numerator, denominator) and only settings at least as close
    as the closest so far are yielded: the minimum is the same, without a Fraction per setting."""
    lim = ECP5_PLL
    (plo, phi), (olo, ohi), (vlo, vhi) = lim.f_pfd, lim.f_out, lim.f_vco
    best = [None, 1]                  # closest error so far, as numerator / denominator

    def close(num: int, den: int) -> bool:
        if best[0] is None or num * best[1] <= best[0] * den:
            best[:] = [num, den]
            return True
        return False
    for ref in lim.divider_range("CLKI_DIV"):
        if not plo * ref <= f_in <= phi * ref:
            continue
        pfd = Fraction(f_in, ref)
        for fb in lim.divider_range("CLKFB_DIV"):
            op_ref = f_in * fb                 # f_CLKOP * ref
            if not olo * ref <= op_ref <= ohi * ref:
                continue
            for opd in lim.divider_range("CLKOP_DIV"):
                vco_ref = op_ref * opd         # f_VCO * ref
                if vco_ref > vhi * ref:
                    break
                if vco_ref < vlo * ref:
                    continue
                vco, common = Fraction(vco_ref, ref), (("CLKI_DIV", ref), ("CLKFB_DIV", fb), ("CLKOP_DIV", opd))
                if close(abs(op_ref - target * ref), ref):
                    yield abs(pfd * fb - target), (0, abs(vco - 600 * _MHZ), ref, fb, opd, 0), pfd * fb, \
                        common, vco, pfd
                legal = lim.divider_range("CLKOS_DIV")
                lo = max(legal.start, -(-vco_ref // (ohi * ref)))
                hi = min(legal.stop - 1, vco_ref // (olo * ref))
                ideal = vco_ref // (target * ref)
                for osd in {min(max(ideal, lo), hi), min(max(ideal + 1, lo), hi)} if lo <= hi else ():
                    if close(abs(vco_ref - target * ref * osd), ref * osd):
                        out = vco / osd
                        yield abs(out - target), (1, abs(vco - 600 * _MHZ), ref, fb, opd, osd), out, \
                            common + (("CLKOS_DIV", osd),), vco, pfd


def search_pll(family: str, f_in: int, target: int):
    """The setting of ``family``'s PLL nearest ``target`` Hz from ``f_in`` Hz: ``(achieved,
    parameters, vco, pfd)`` or None when no setting is legal (input outside the PLL's range)."""
    lim = PLL_FAMILIES[family]
    if not _within(f_in, lim.f_in):
        return None
    candidates = _ice40_candidates if family == "ice40" else _ecp5_candidates
    best = min(candidates(f_in, target), key=lambda c: (c[0], c[1]), default=None)
    return None if best is None else best[2:]


def _ice40_parameters(div: tuple, pfd: Fraction) -> tuple:
    filt = next((r for bound, r in _ICE40_FILTER if pfd < bound * _MHZ), 6)
    return (("FEEDBACK_PATH", "SIMPLE"), *div, ("FILTER_RANGE", filt))


def _ecp5_parameters(div: tuple) -> tuple:
    d = dict(div)
    # coarse phases as ecppll writes them; the phase to the oscillator is not used
    out = [("CLKI_DIV", d["CLKI_DIV"]), ("CLKFB_DIV", d["CLKFB_DIV"]), ("CLKOP_DIV", d["CLKOP_DIV"]),
           ("CLKOP_CPHASE", d["CLKOP_DIV"] // 2)]
    if "CLKOS_DIV" in d:
        out += [("CLKOS_DIV", d["CLKOS_DIV"]), ("CLKOS_CPHASE", 0), ("OUTPUT", "CLKOS")]
    else:
        out += [("OUTPUT", "CLKOP")]
    return tuple(out)


def clock_plan(board, clock_hz: int) -> ClockPlan:
    """The :class:`ClockPlan` making ``clock_hz`` on ``board`` (a
    :class:`~ikseries.constraints.boards.Board`, a registry name or a board file's path).

    Raises :class:`ClockPlanError` (one line) when the PLL cannot reach ``clock_hz`` within
    :data:`CLOCK_TOLERANCE_PPM`, ``ValueError`` for a ``clock_hz`` that is not a positive integer.
    """
    board = board if isinstance(board, Board) else find_board(board)
    if isinstance(clock_hz, bool) or not isinstance(clock_hz, int) or clock_hz <= 0:
        raise ValueError(f"clock_hz must be a positive integer (Hz), not {clock_hz!r}")
    osc = board.clock_hz
    if clock_hz == osc:
        return ClockPlan(board.name, board.family, osc, clock_hz, Fraction(osc), None, (), None, None)
    lim = PLL_FAMILIES[board.family]
    found = search_pll(board.family, osc, clock_hz)
    if found is None:
        raise ClockPlanError(f"clock_hz {clock_hz} cannot be made on {board.name}: its {osc / 1e6:g} MHz "
                             f"oscillator is outside the {lim.primitive} input range "
                             f"{lim.f_in[0] / 1e6:g}..{lim.f_in[1] / 1e6:g} MHz")
    achieved, div, vco, pfd = found
    err = (achieved - clock_hz) / clock_hz * 1_000_000
    if abs(err) > CLOCK_TOLERANCE_PPM:
        raise ClockPlanError(
            f"clock_hz {clock_hz} cannot be made on {board.name} within {CLOCK_TOLERANCE_PPM} ppm: the nearest "
            f"its {lim.primitive} reaches from the {osc / 1e6:g} MHz oscillator is "
            f"{float(achieved) / 1e6:.9g} MHz ({float(err):+.0f} ppm)")
    if board.family == "ice40":
        pad = board.clock_pin in ICE40_PLL_PADS.get((board.device, board.package), ())
        primitive, params = ("SB_PLL40_PAD" if pad else "SB_PLL40_CORE"), _ice40_parameters(div, pfd)
    else:
        primitive, params = "EHXPLLL", _ecp5_parameters(div)
    return ClockPlan(board.name, board.family, osc, clock_hz, achieved, primitive, params, vco, pfd)
