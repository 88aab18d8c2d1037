"""The parts of a robot description, one per TOML table: workspace, calibration, fit options
and hardware options.

Each part is a frozen dataclass that parses and validates its own table (``parse``) and gives
its JSON-ready record (``record``); checks that need more than one part (the pulse format
against the tolerance, the refresh rate against the clock, reachability) are made by
:func:`ikseries.robot.parse_robot` once the parts are built.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .constraints.devices import FAMILIES, FIT_DEVICES, PRIMITIVES
from .kinematics import Calibration

__all__ = ["RobotError", "InputSpec", "Workspace", "CalibrationSpec", "FitOptions", "HardwareOptions",
           "field_number", "field_table", "refuse_extra", "HARDWARE_LABELS", "ARCHITECTURE_OPTIONS",
           "LOWERINGS", "PRODUCTS", "ARCHITECTURES", "DSP_CHOICES"]

#: fit.lowering values: "mixed" = per servo the Horner/Estrin mix of least pipeline depth (a few
#: more multiplications), "horner" = nested Horner (fewest multiplications, deepest)
LOWERINGS = ("mixed", "horner")
#: fit.products values: "exact" = every product at the width interval analysis gives it (a wide
#: one is split into DSP-sized limbs in hardware), "dsp" = operands narrowed so that every
#: product fits one DSP block of hardware.dsp (fewer DSP blocks and cycles, a bit more rounding)
PRODUCTS = ("exact", "dsp")
#: hardware.architecture values: "auto" picks the smallest that meets hardware.min_refresh_hz,
#: "fastest" the fastest whose Yosys cell counts fit hardware.fit_device (see ikseries.architecture).
#: Default: "pipelined" (one target per clock, verified by cocotb too) for one leg, "auto" for more.
ARCHITECTURES = ("auto", "pipelined", "folded", "modulo", "fastest")
#: hardware.dsp values: the FPGA family whose DSP multiplier size the folded evaluator uses
#: (see ikseries.constraints.devices.FAMILIES), or "none" for full-width products
DSP_CHOICES = (*FAMILIES, "none")

#: option -> how errors name it (TOML field names; the CLI passes its option names)
HARDWARE_LABELS = {"legs": "legs", "architecture": "hardware.architecture",
                   "multipliers": "hardware.multipliers", "interval": "hardware.interval", "dsp": "hardware.dsp",
                   "min_refresh_hz": "hardware.min_refresh_hz", "fit_device": "hardware.fit_device",
                   "dsp_primitives": "hardware.dsp_primitives"}

#: options that only one architecture takes: option -> (architecture, why the others don't)
ARCHITECTURE_OPTIONS = {"multipliers": ("folded", "auto picks 1 or 2 multipliers itself"),
                        "interval": ("modulo", "auto and fastest pick the interval themselves")}


class RobotError(ValueError):
    """An invalid robot description; the message names the field and the bad value."""


# -- TOML field helpers ------------------------------------------------------------------
def field_number(table, key, path, *, default=None, positive=False, integer=False):
    """``table[key]`` checked to be a finite number (``integer``: an int; ``positive``: > 0);
    ``default`` when it is absent, else a missing field is an error. ``path`` prefixes the
    field name in messages (``"hardware."``)."""
    if key not in table:
        if default is None:
            raise RobotError(f"{path}{key} is missing")
        return default
    v = table[key]
    kind = "an integer" if integer else "a number"
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
        raise RobotError(f"{path}{key} must be {kind}, not {v!r}")
    if not np.isfinite(v):
        raise RobotError(f"{path}{key} must be finite, not {v!r}")
    if positive and v <= 0:
        raise RobotError(f"{path}{key} must be > 0, not {v!r}")
    return v


def field_table(table, key, path, required=True) -> dict:
    """The sub-table ``table[key]`` ({} when absent and not ``required``)."""
    v = table.get(key, None)
    if v is None:
        if required:
            raise RobotError(f"{path}{key} is missing")
        return {}
    if not isinstance(v, dict):
        raise RobotError(f"{path}{key} must be a table, not {v!r}")
    return v


def refuse_extra(table, allowed, path) -> None:
    """Refuse the first (sorted) field of ``table`` that is not in ``allowed``."""
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise RobotError(f"unknown field {path}{extra[0]} (expected one of: {', '.join(sorted(allowed))})")


# -- workspace ---------------------------------------------------------------------------
@dataclass(frozen=True)
class InputSpec:
    """One target input: its range and the fractional bits of its fixed-point port."""
    name: str
    unit: str
    min: float
    max: float
    frac_bits: int

    @property
    def lo(self) -> int:
        return int(np.ceil(self.min * 2 ** self.frac_bits))

    @property
    def hi(self) -> int:
        return int(np.floor(self.max * 2 ** self.frac_bits))


@dataclass(frozen=True)
class Workspace:
    """The box of targets (``[workspace]``): one :class:`InputSpec` per geometry input, in order."""
    inputs: tuple[InputSpec, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(i.name for i in self.inputs)

    @property
    def lows(self) -> list[float]:
        return [i.min for i in self.inputs]

    @property
    def highs(self) -> list[float]:
        return [i.max for i in self.inputs]

    @classmethod
    def parse(cls, table: dict, geometry) -> "Workspace":
        """Validate the ``[workspace]`` table against ``geometry``'s inputs."""
        refuse_extra(table, geometry.inputs, "workspace.")
        inputs = []
        for name, unit in zip(geometry.inputs, geometry.input_units):
            t = field_table(table, name, "workspace.")
            p = f"workspace.{name}."
            refuse_extra(t, ["min", "max", "frac_bits"], p)
            lo, hi = field_number(t, "min", p), field_number(t, "max", p)
            if not lo < hi:
                raise RobotError(f"{p}max must be > {p}min ({lo!r}), not {hi!r}")
            fb = field_number(t, "frac_bits", p, integer=True)
            if not 0 <= fb <= 16:
                raise RobotError(f"{p}frac_bits must be in 0..16, not {fb!r}")
            check = getattr(geometry, "workspace_error", None)
            problem = check(name, lo, hi) if check is not None else None
            if problem:
                raise RobotError(problem)
            spec = InputSpec(name, unit, float(lo), float(hi), fb)
            if spec.lo > spec.hi:
                raise RobotError(f"{p}: no value with {fb} fractional bits lies in [{lo!r}, {hi!r}]")
            inputs.append(spec)
        return cls(tuple(inputs))

    def record(self) -> dict:
        return {"inputs": [dataclasses.asdict(i) for i in self.inputs]}

    @classmethod
    def from_record(cls, d: dict) -> "Workspace":
        return cls(tuple(InputSpec(**i) for i in d["inputs"]))


# -- calibration -------------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrationSpec:
    """The servo calibration as described (``[calibration]``): the neutral pose, the pulse
    at it, the pulse per degree and direction of each servo (the pulse's sense against the
    servo angle of :mod:`ikseries.joints`), and the pulse limits. :meth:`joint_map` computes
    from it the servo angle -> pulse map of the geometry."""
    neutral_pose: dict
    pulse_unit_us: float
    neutral_pulse_pu: float
    pu_per_degree: float
    directions: tuple[int, ...]
    pulse_min_us: float = 500.0
    pulse_max_us: float = 2500.0

    @classmethod
    def parse(cls, table: dict, geometry) -> "CalibrationSpec":
        """Validate the ``[calibration]`` table for ``geometry``'s inputs and servos."""
        p = "calibration."
        refuse_extra(table, ["pulse_unit_us", "neutral_pulse_pu", "pu_per_degree", "neutral_pose", "directions",
                             "pulse_min_us", "pulse_max_us"], p)
        pose = field_table(table, "neutral_pose", p)
        refuse_extra(pose, geometry.inputs, "calibration.neutral_pose.")
        pose = {name: float(field_number(pose, name, "calibration.neutral_pose.")) for name in geometry.inputs}
        n = len(geometry.servos)
        dirs = table.get("directions", [1] * n)
        if (not isinstance(dirs, list) or len(dirs) != n
                or any(d not in (1, -1) or isinstance(d, bool) for d in dirs)):
            raise RobotError(f"calibration.directions must be a list of {n} values each +1 or -1, not {dirs!r}")
        pmin = float(field_number(table, "pulse_min_us", p, default=500.0, positive=True))
        pmax = float(field_number(table, "pulse_max_us", p, default=2500.0, positive=True))
        if not pmin < pmax:
            raise RobotError(f"calibration.pulse_max_us must be > pulse_min_us ({pmin!r}), not {pmax!r}")
        spec = cls(pose, float(field_number(table, "pulse_unit_us", p, positive=True)),
                   float(field_number(table, "neutral_pulse_pu", p, positive=True)),
                   float(field_number(table, "pu_per_degree", p, positive=True)), tuple(dirs), pmin, pmax)
        spec.check_neutral_pulse()
        return spec

    def check_neutral_pulse(self) -> None:
        """The neutral pulse must lie within the pulse limits."""
        neutral_us = self.neutral_pulse_pu * self.pulse_unit_us
        if not self.pulse_min_us <= neutral_us <= self.pulse_max_us:
            raise RobotError(f"calibration.neutral_pulse_pu must give a pulse within [pulse_min_us, pulse_max_us] = "
                             f"[{self.pulse_min_us:g}, {self.pulse_max_us:g}] us, i.e. within "
                             f"[{self.pulse_min_us / self.pulse_unit_us:g}, "
                             f"{self.pulse_max_us / self.pulse_unit_us:g}] pu at pulse_unit_us = "
                             f"{self.pulse_unit_us:g}, not {self.neutral_pulse_pu!r}")

    def joint_map(self, geometry) -> Calibration:
        """The servo angle -> pulse map of ``geometry``: its servo angles at the neutral pose."""
        neutral = tuple(float(a) for a in geometry.ik(*(self.neutral_pose[n] for n in geometry.inputs)))
        return Calibration(neutral, self.directions, self.neutral_pulse_pu, self.pu_per_degree)

    def record(self) -> dict:
        return {**dataclasses.asdict(self), "directions": list(self.directions)}

    @classmethod
    def from_record(cls, d: dict) -> "CalibrationSpec":
        return cls(**{**d, "directions": tuple(d["directions"])})


# -- fit options -------------------------------------------------------------------------
@dataclass(frozen=True)
class FitOptions:
    """How the plan is fitted (``[fit]``)."""
    tolerance_pu: float = 0.5
    lowering: str = "mixed"     # one of LOWERINGS: how servo polynomials become plan operations
    products: str = "exact"     # one of PRODUCTS: product widths exact or fitted to hardware.dsp

    @classmethod
    def parse(cls, table: dict) -> "FitOptions":
        """Validate the ``[fit]`` table (every field optional)."""
        refuse_extra(table, [f.name for f in dataclasses.fields(cls)], "fit.")
        options = cls(**table)
        options.validate()
        return dataclasses.replace(options, tolerance_pu=float(options.tolerance_pu))

    def validate(self) -> None:
        tol = self.tolerance_pu
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0:
            raise RobotError(f"fit.tolerance_pu must be > 0 pu, not {tol!r}")
        if not np.isfinite(tol):
            raise RobotError(f"fit.tolerance_pu must be finite, not {tol!r}")
        if self.lowering not in LOWERINGS:
            raise RobotError(f"fit.lowering must be one of {', '.join(LOWERINGS)}, not {self.lowering!r}")
        if self.products not in PRODUCTS:
            raise RobotError(f"fit.products must be one of {', '.join(PRODUCTS)}, not {self.products!r}")

    def record(self) -> dict:
        return dataclasses.asdict(self)


# -- hardware options --------------------------------------------------------------------
@dataclass(frozen=True)
class HardwareOptions:
    """The clock, PWM period and evaluator architecture (``[hardware]``); the defaults are
    those of records written before the architecture fields existed."""
    clock_hz: int
    pwm_period_us: float
    architecture: str = "pipelined"  # one of ARCHITECTURES
    multipliers: int = 1            # multiplier units of a folded evaluator
    interval: int = 8               # initiation interval of a modulo-scheduled evaluator
    dsp: str = "ice40"              # one of DSP_CHOICES
    min_refresh_hz: float = 1000.0  # every leg's servos re-evaluated at least this often
    fit_device: str | None = None   # one of FIT_DEVICES: the device "fastest" must fit
    dsp_primitives: bool = False    # modulo cores: products on instantiated DSP primitives with their registers

    @property
    def pwm_period_ticks(self) -> int:
        return int(round(self.pwm_period_us * 1e-6 * self.clock_hz))

    @classmethod
    def parse(cls, table: dict, legs: int) -> "HardwareOptions":
        """Validate the ``[hardware]`` table (every field optional) of a robot of ``legs`` legs."""
        refuse_extra(table, [f.name for f in dataclasses.fields(cls)], "hardware.")
        clk = field_number(table, "clock_hz", "hardware.", default=48_000_000, positive=True, integer=True)
        period = float(field_number(table, "pwm_period_us", "hardware.", default=20000.0, positive=True))
        fit_device = table.get("fit_device")
        defaults = {"architecture": "auto" if legs != 1 else "pipelined",
                    "dsp": FIT_DEVICES.get(fit_device, "ice40") if isinstance(fit_device, str) else "ice40"}
        options = cls(**{**defaults, **table, "clock_hz": int(clk), "pwm_period_us": period})
        options.validate()
        options.check_given(set(table))
        return dataclasses.replace(options, min_refresh_hz=float(options.min_refresh_hz))

    def validate(self, labels: dict | None = None) -> None:
        """Check the architecture options; errors name the field via ``labels``."""
        lab = {**HARDWARE_LABELS, **(labels or {})}
        for key in ("multipliers", "interval"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise RobotError(f"{lab[key]} must be an integer >= 1, not {v!r}")
        for key, choices in (("architecture", ARCHITECTURES), ("dsp", DSP_CHOICES)):
            v = getattr(self, key)
            if v not in choices:
                raise RobotError(f"{lab[key]} must be one of {', '.join(choices)}, not {v!r}")
        r = self.min_refresh_hz
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not np.isfinite(r) or r <= 0:
            raise RobotError(f"{lab['min_refresh_hz']} must be a number > 0, not {r!r}")
        self._validate_dsp_primitives(lab)
        self._validate_fit_device(lab)

    def _validate_dsp_primitives(self, lab: dict) -> None:
        prim = self.dsp_primitives
        if not isinstance(prim, bool):
            raise RobotError(f"{lab['dsp_primitives']} must be true or false, not {prim!r}")
        prim_families = {p.family: p for p in PRIMITIVES.values()}
        if prim and self.dsp not in prim_families:
            raise RobotError(f"{lab['dsp']} must be {', '.join(prim_families)} when {lab['dsp_primitives']} is "
                             f"true (the only DSP primitive instantiated is the "
                             + ", ".join(f"{FAMILIES[f].label} {p.name}" for f, p in prim_families.items())
                             + f"), not {self.dsp!r}")

    def _validate_fit_device(self, lab: dict) -> None:
        dev = self.fit_device
        if dev is not None and dev not in FIT_DEVICES:
            raise RobotError(f"{lab['fit_device']} must be one of {', '.join(FIT_DEVICES)}, not {dev!r}")
        if dev is not None and self.architecture != "fastest":
            raise RobotError(f"{lab['architecture']} must be fastest when {lab['fit_device']} is given "
                             f"(the device the fastest configuration must fit), not {self.architecture!r}")
        if dev is None and self.architecture == "fastest":
            raise RobotError(f"{lab['fit_device']} must be one of {', '.join(FIT_DEVICES)} when "
                             f"{lab['architecture']} is fastest (the device to fit), not None")

    def check_given(self, given, labels: dict | None = None) -> None:
        """Refuse an option of :data:`ARCHITECTURE_OPTIONS` that was ``given`` (a set of option
        names) with another architecture; errors name the fields via ``labels``."""
        lab = {**HARDWARE_LABELS, **(labels or {})}
        for key, (arch, why) in ARCHITECTURE_OPTIONS.items():
            if key in given and self.architecture != arch:
                raise RobotError(f"{lab['architecture']} must be {arch} when {lab[key]} is given ({why}), "
                                 f"not {self.architecture!r}")

    def record(self) -> dict:
        return dataclasses.asdict(self)
