"""Option checks shared by the polynomial architectures."""
from __future__ import annotations

from ...constraints.devices import FAMILIES, multiplier_families, reference_part
from ...fit.cost import COSTS, DEFAULT_COST_MODEL, CostModel, DeviceCost

__all__ = ["dsp_size", "positive_int", "dsp_label", "primitive_families", "check_primitives", "check_cost",
           "offered_cost_model"]


def dsp_size(dsp: str | None) -> tuple[int, int] | None:
    """Signed operand widths of the DSP blocks of family ``dsp`` (None or "none": full-width
    products)."""
    if dsp in (None, "none"):
        return None
    if dsp not in FAMILIES:
        raise ValueError(f"dsp must be None, 'none' or one of {', '.join(FAMILIES)}, not {dsp!r}")
    return FAMILIES[dsp].dsp


def dsp_label(dsp: str | None) -> str:
    """``ice40 16x16 DSP`` or ``full-width``."""
    size = dsp_size(dsp)
    return "full-width" if size is None else "{} {}x{} DSP".format(dsp, *size)


def positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, not {value!r}")
    return value


def primitive_families() -> tuple[str, ...]:
    """Families whose DSP primitives a modulo core can instantiate (with their registers)."""
    return multiplier_families()


def check_primitives(primitives, dsp: str | None) -> bool:
    """``primitives`` if it is a bool and, when true, ``dsp`` a family with DSP primitives."""
    if not isinstance(primitives, bool):
        raise ValueError(f"primitives must be true or false, not {primitives!r}")
    if primitives and dsp not in primitive_families():
        raise ValueError(f"dsp must be one of {', '.join(primitive_families())} with primitives (the "
                         f"families whose DSP primitives are instantiated), not {dsp!r}")
    return primitives


def check_cost(cost, dsp: str | None) -> str:
    """``cost`` if it is one of :data:`ikseries.fit.cost.COSTS` (what a modulo-scheduled or
    pipelined core asks the fitter to minimise: "multipliers", :class:`~ikseries.fit.cost.MultiplierCount`,
    or "device", :class:`~ikseries.fit.cost.DeviceCost`), and "device" only with a DSP family ``dsp``."""
    if cost not in COSTS:
        raise ValueError(f"cost must be one of {', '.join(COSTS)}, not {cost!r}")
    if cost == "device" and dsp_size(dsp) is None:
        raise ValueError(f"dsp must be one of {', '.join(FAMILIES)} with cost 'device' (the family whose "
                         f"reference part prices the plan), not {dsp!r}")
    return cost


def offered_cost_model(cost: str, dsp: str | None, interval: int) -> CostModel:
    """The cost model of a core with option ``cost`` (:func:`check_cost`) on family ``dsp``,
    serving ``interval`` targets per multiplier: :class:`~ikseries.fit.cost.DeviceCost` of the
    family's reference part (:func:`ikseries.constraints.devices.reference_part`) for
    "device", else the default."""
    if cost == "device":
        return DeviceCost(reference_part(dsp).name, interval)
    return DEFAULT_COST_MODEL
