"""Fixed-point formats of a fitted robot: the narrowest feature and accumulator precisions
whose certified rounding bound meets the quantization budget, and the coefficients
re-optimised on their integer grid."""
from __future__ import annotations

import dataclasses
import functools

import numpy as np

from .context import FormatError
from .lowering import trial_plan
from .minimax import subset_minimax
from .structure import ServoFit

__all__ = ["round_and_refit", "requantize", "choose_formats", "narrowest_formats", "narrowest_frac", "fitted_cost",
           "FEATURE_BITS", "MAX_FRAC"]

#: the most fractional bits an accumulator may have
MAX_FRAC = 24


def round_and_refit(sf: ServoFit, frac: int):
    """Coefficients on the grid 2**-frac, rounded one at a time (highest degree first) while
    the rest are refitted (minimax over the fit's active rows, :func:`~.minimax.subset_minimax`)
    to absorb each rounding; plain rounding instead if that is better over the pool (the refit
    is a heuristic for the maximum error). Piecewise: in every cell.
    Returns (poly, max error over the pool) or None without fit data."""
    if sf.refit is None:
        return None
    data, states, _ = sf.refit
    terms = sorted(sf.poly, key=lambda e: (-sum(e), e))
    grid = 2.0 ** frac
    coefs, worst = [], 0.0
    for orig, state, rows in zip(data.coef(sf.poly, terms), states, data.rows):
        a, b = rows.basis.rows(terms, state.active), rows.t[state.active]
        ref = np.searchsorted(state.active, state.reference)
        coef = orig.copy()
        fixed = np.zeros(len(terms), dtype=bool)
        for k in range(len(terms)):
            coef[k] = np.round(coef[k] * grid) / grid
            fixed[k] = True
            free = ~fixed
            if free.any():        # each refit starts among the previous one's reference
                coef[free], ref = subset_minimax(a[:, free], b - a[:, fixed] @ coef[fixed], ref)
        err = rows.error(terms, coef)
        naive = np.round(orig * grid) / grid
        naive_err = rows.error(terms, naive)
        if naive_err < err:          # the refit is a heuristic: never worse than plain rounding
            coef, err = naive, naive_err
        coefs.append(coef)
        worst = max(worst, err)
    return data.poly(terms, np.array(coefs)), worst


def _rounding_pu(ctx, sf: ServoFit, fv: int) -> float:
    """Certified rounding bound (pu) of ``sf`` alone in a plan with features of ``fv`` bits
    (infinite when an intermediate would overflow 63 bits)."""
    try:
        plan = trial_plan(ctx, sf, fv)
    except OverflowError:
        return np.inf
    return plan.rounding_bounds()[plan.outputs[0].preround] / ctx.ticks_per_pu


def requantize(ctx, fits: list[ServoFit], fv: int, progress) -> list[ServoFit]:
    """Re-optimise each servo's coefficients after quantization, then take the narrowest
    accumulator format whose certified rounding bound still meets the quantization budget
    and whose refitted polynomial still meets the approximation budget on the check set."""
    out = []
    for sf in fits:
        best = None
        for frac in range(sf.frac, max(-1, sf.frac - 4), -1):
            r = round_and_refit(sf, frac)
            if r is None or r[1] > sf.refit[2]:
                break
            trial = ServoFit(sf.name, sf.features, sf.degree, r[0], r[1], frac=frac)
            if _rounding_pu(ctx, trial, fv) > ctx.budget.quantization:
                break
            best = trial
        if best is not None:
            progress(f"  {sf.name}: coefficients re-optimised on the 2^-{best.frac} grid "
                     f"(was 2^-{sf.frac}), max fit error {best.fit_error_ticks:.4g} ticks")
            sf = dataclasses.replace(sf, poly=best.poly, fit_error_ticks=best.fit_error_ticks, frac=best.frac)
        out.append(sf)
    return out


def narrowest_frac(bound, quant: float, top: int = MAX_FRAC) -> int | None:
    """Fewest accumulator fractional bits in ``[0, top]`` whose ``bound(frac)`` is within
    ``quant``, or None. The bound falls as ``frac`` grows until the intermediates need more
    than 63 bits (``bound`` is then infinite, and stays so for every wider ``frac``): the
    widest finite ``frac`` is found first, then the narrowest one that meets ``quant``."""
    bound = functools.cache(bound)
    lo, hi = 0, top
    if np.isfinite(bound(top)):
        lo = top
    elif not np.isfinite(bound(0)):
        return None
    while lo < hi:           # the widest frac without overflow
        mid = (lo + hi + 1) // 2
        if np.isfinite(bound(mid)):
            lo = mid
        else:
            hi = mid - 1
    if bound(lo) > quant:
        return None
    lo, hi = 0, lo
    while lo < hi:           # the bound falls as frac grows: bisect
        mid = (lo + hi) // 2
        if bound(mid) <= quant:
            hi = mid
        else:
            lo = mid + 1
    return lo


#: the feature precisions tried, narrowest first
FEATURE_BITS = range(8, 40)


def narrowest_formats(ctx, fits: list[ServoFit], fvs=FEATURE_BITS) -> tuple[int, list[int]] | None:
    """``(fv, fracs)``: the narrowest feature precision of ``fvs`` at which every servo of
    ``fits`` has an accumulator precision meeting the certified quantization budget, and those
    precisions (:func:`narrowest_frac`); None if none has."""
    quant = ctx.budget.quantization
    for fv in fvs:
        fracs = []
        for sf in fits:
            frac = narrowest_frac(lambda f: _rounding_pu(ctx, dataclasses.replace(sf, frac=f), fv), quant)
            if frac is None:
                break
            fracs.append(frac)
        if len(fracs) == len(fits):
            return fv, fracs
    return None


def choose_formats(ctx, fits: list[ServoFit], progress) -> tuple[int, list[ServoFit]]:
    """Narrowest feature precision ``fv`` and per-servo accumulator precision meeting the
    certified quantization budget: returns ``fv`` and the fits with their ``frac`` set."""
    formats = narrowest_formats(ctx, fits)
    if formats is None:
        raise FormatError(f"no fixed-point format keeps the certified rounding error within "
                          f"{ctx.budget.quantization:g} pu in 63-bit intermediates")
    fv, fracs = formats
    fits = [dataclasses.replace(sf, frac=fr) for sf, fr in zip(fits, fracs)]
    progress(f"  formats: features {fv} fractional bits, accumulators "
             + ", ".join(f"{sf.name} {sf.frac}" for sf in fits))
    return fv, fits


def fitted_cost(ctx, sf: ServoFit) -> float:
    """Cost (``ctx.cost_model``) of ``sf`` with its own fitted coefficients: its plan alone
    (:func:`~.lowering.trial_plan`) in the narrowest formats that keep its certified rounding
    within the quantization budget (:func:`narrowest_formats` of ``sf`` alone; the fit chooses
    them over every servo, so they may end a bit wider), so the coefficient tables and
    operands are as wide as the fitted values make them, not the search's stand-ins
    (:func:`~.lowering.structure_cost`). Infinite if no format fits.

    The search prices many fits of one servo, whose formats are alike: the feature precision
    found for the servo last (``ctx.format_hints``) is tried first, and taken if one bit fewer
    fails (the rounding bound falls as the precision grows); else every one, narrowest first.
    Each servo's hint is its own, dropped when its search starts
    (:func:`~.search.fit_servo`), so the price does not depend on the other servos' searches
    nor on an earlier attempt's (nor on ``jobs``)."""
    hint = ctx.format_hints.get(sf.name)
    if hint is not None and (hint == FEATURE_BITS.start or narrowest_formats(ctx, [sf], (hint - 1,)) is None):
        formats = narrowest_formats(ctx, [sf], range(hint, FEATURE_BITS.stop))
    else:
        formats = narrowest_formats(ctx, [sf])
    if formats is None:
        return float("inf")
    fv, (frac,) = formats
    ctx.format_hints[sf.name] = fv
    plan = trial_plan(ctx, dataclasses.replace(sf, frac=frac), fv)
    return ctx.cost_model.cost(plan, sf.name)
