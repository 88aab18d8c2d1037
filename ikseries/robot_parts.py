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
from .fit.cost import COSTS
from .calibration import Calibration, LinearMap, ServoOverride, TableMap, first_failure
from .kinematics import format_point

__all__ = ["RobotError", "InputSpec", "Workspace", "CalibrationSpec", "FitOptions", "HardwareOptions",
           "field_number", "field_table", "refuse_extra", "HARDWARE_LABELS", "ARCHITECTURE_OPTIONS",
           "LOWERINGS", "PRODUCTS", "ARCHITECTURES", "DSP_CHOICES",
           "DEVICE_COST_ARCHITECTURES"]

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
#: the architectures that offer the device cost model (hardware.cost = "device", one of
#: ikseries.fit.cost.COSTS: the share of the DSP family's reference part the plan takes)
DEVICE_COST_ARCHITECTURES = ("modulo", "pipelined")

#: option -> how errors name it (TOML field names; the CLI passes its option names)
HARDWARE_LABELS = {"legs": "legs", "architecture": "hardware.architecture",
                   "multipliers": "hardware.multipliers", "interval": "hardware.interval", "dsp": "hardware.dsp",
                   "min_refresh_hz": "hardware.min_refresh_hz", "fit_device": "hardware.fit_device",
                   "dsp_primitives": "hardware.dsp_primitives", "cost": "hardware.cost"}

#: options that only one architecture takes: option -> (architecture, why the others don't)
ARCHITECTURE_OPTIONS = {"multipliers": ("folded", "auto picks 1 or 2 multipliers itself"),
                        "interval": ("modulo", "auto and fastest pick the interval themselves")}


#: pulses are within their limits up to this slack (µs): a pulse on a limit is not refused for a
#: rounding error
PULSE_SLACK_US = 1e-9


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
    servo angle of :mod:`ikseries.joints`), and the pulse limits, the defaults of every servo;
    ``servos`` maps a servo to its own calibration (``[calibration.servos.<servo>]``,
    :class:`ikseries.calibration.ServoOverride`). :meth:`joint_map` computes from it the servo
    angle -> pulse map of the geometry."""
    neutral_pose: dict
    pulse_unit_us: float
    neutral_pulse_pu: float
    pu_per_degree: float
    directions: tuple[int, ...]
    pulse_min_us: float = 500.0
    pulse_max_us: float = 2500.0
    servos: dict = dataclasses.field(default_factory=dict)   # servo -> ServoOverride

    @classmethod
    def parse(cls, table: dict, geometry) -> "CalibrationSpec":
        """Validate the ``[calibration]`` table for ``geometry``'s inputs and servos."""
        p = "calibration."
        refuse_extra(table, ["pulse_unit_us", "neutral_pulse_pu", "pu_per_degree", "neutral_pose", "directions",
                             "pulse_min_us", "pulse_max_us", "servos"], p)
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
                   float(field_number(table, "pu_per_degree", p, positive=True)), tuple(dirs), pmin, pmax,
                   _parse_servos(field_table(table, "servos", p, required=False), geometry))
        spec.check_neutral_pulse()
        spec.check_servos(geometry.servos)
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

    def check_servos(self, servos) -> None:
        """Per servo override: its pulse limits in order, and a gain or table not also flipped
        by ``directions`` (the gain's sign is the direction; a table gives the pulses)."""
        for k, name in enumerate(servos):
            o = self.servos.get(name)
            if o is None:
                continue
            lo, hi = self.limits_us(name)
            if not lo < hi and o.pulse_max_us is not None:
                raise RobotError(f"calibration.servos.{name}.pulse_max_us must be > the pulse_min_us of {name} "
                                 f"({lo!r}), not {hi!r}")
            if not lo < hi:
                raise RobotError(f"calibration.servos.{name}.pulse_min_us must be < the pulse_max_us of {name} "
                                 f"({hi!r}), not {lo!r}")
            own = "us_per_degree" if o.us_per_degree is not None else "table" if o.table is not None else None
            if own is not None and self.directions[k] != 1:
                why = "its sign is the direction" if own == "us_per_degree" else "it gives the pulses"
                raise RobotError(f"calibration.directions[{k}] must be 1 when calibration.servos.{name}.{own} "
                                 f"is given ({why}), not {self.directions[k]!r}")

    def limits_us(self, servo: str) -> tuple[float, float]:
        """Pulse limits (µs) of ``servo``: its own, else the defaults."""
        o = self.servos.get(servo)
        lo = o.pulse_min_us if o is not None and o.pulse_min_us is not None else self.pulse_min_us
        hi = o.pulse_max_us if o is not None and o.pulse_max_us is not None else self.pulse_max_us
        return lo, hi

    def limit_field(self, servo: str, which: str) -> str:
        """The TOML field that sets ``servo``'s ``which`` ("pulse_min_us" / "pulse_max_us") limit."""
        o = self.servos.get(servo)
        return f"calibration.servos.{servo}.{which}" if o is not None and getattr(o, which) is not None \
            else f"calibration.{which}"

    def neutral_angles(self, geometry) -> tuple[float, ...]:
        """The servo angles of ``geometry`` at the neutral pose."""
        return tuple(float(a) for a in geometry.ik(*(self.neutral_pose[n] for n in geometry.inputs)))

    def joint_map(self, geometry) -> Calibration:
        """The servo angle -> pulse map of ``geometry``: its servo angles at the neutral pose."""
        neutral = self.neutral_angles(geometry)
        if not self.servos:
            return Calibration.linear(neutral, self.directions, self.neutral_pulse_pu, self.pu_per_degree)
        return Calibration(tuple(self._servo_map(k, name, neutral[k]) for k, name in enumerate(geometry.servos)))

    def _servo_map(self, k: int, name: str, neutral: float):
        u, o = self.pulse_unit_us, self.servos.get(name)
        if o is None:
            return LinearMap(neutral, self.neutral_pulse_pu, self.directions[k] * self.pu_per_degree)
        trim = (o.trim_us or 0.0) / u
        if o.table is not None:
            return TableMap(tuple((a, us / u) for a, us in o.table), trim)
        gain = o.us_per_degree / u if o.us_per_degree is not None else self.directions[k] * self.pu_per_degree
        if o.zero_pulse_us is not None:
            return LinearMap(0.0, o.zero_pulse_us / u, gain, trim)
        return LinearMap(neutral, o.neutral_pulse_us / u, gain, trim)

    def check_neutral(self, geometry) -> None:
        """Each overridden servo's pulse at the neutral pose (trim included) lies within its
        pulse limits, and a table servo's neutral angle within its table."""
        cal = self.joint_map(geometry)
        for k, (name, a) in enumerate(zip(geometry.servos, self.neutral_angles(geometry))):
            o, m = self.servos.get(name), cal.servos[k]
            if o is None:
                continue
            path = f"calibration.servos.{name}"
            if isinstance(m, TableMap) and not m.angle_range[0] <= a <= m.angle_range[1]:
                raise RobotError(f"{path}.table covers servo angles [{m.angle_range[0]:g}, {m.angle_range[1]:g}] deg, "
                                 f"not the neutral pose's {a:.6g} deg")
            us, (lo, hi) = float(m.pulse(a)) * self.pulse_unit_us, self.limits_us(name)
            if not lo <= us <= hi:
                trimmed = o.trim_us and lo <= us - o.trim_us <= hi    # the trim alone drives it out
                what = (f"{path}.trim_us = {o.trim_us:g} drives the pulse at the neutral pose to {us:.6g} us"
                        if trimmed else f"{path} gives a pulse of {us:.6g} us at the neutral pose")
                raise RobotError(f"{what}, outside its pulse limits [{lo:g}, {hi:g}] us")

    def check_box(self, geometry, names, coords, angles) -> None:
        """At the targets ``coords`` (arrays, input ``names``) with servo ``angles``: every
        servo's pulse within its limits and every table servo's angle within its table; the
        first target (C order) that fails is named with the servo."""
        cal, labels = self.joint_map(geometry), getattr(geometry, "servo_names", geometry.servos)
        masks, reasons = [], []
        for k, (name, label, a) in enumerate(zip(geometry.servos, labels, angles)):
            m, a = cal.servos[k], np.ravel(a)
            if isinstance(m, TableMap):
                lo, hi = m.angle_range
                masks.append(~((a >= lo) & (a <= hi)))
                reasons.append(lambda i, a=a, s=f"{name} ({label})", lo=lo, hi=hi, f=f"calibration.servos.{name}.table":
                               f"needs servo {s} at {a[i]:.6g} deg, outside its table [{lo:g}, {hi:g}] deg ({f})")
            us = np.ravel(m.pulse(a)) * self.pulse_unit_us
            (lo, hi), s = self.limits_us(name), f"{name} ({label})"
            for mask, which in ((us < lo - PULSE_SLACK_US, "pulse_min_us"), (us > hi + PULSE_SLACK_US, "pulse_max_us")):
                masks.append(mask)
                reasons.append(lambda i, us=us, s=s, lo=lo, hi=hi, f=self.limit_field(name, which):
                               f"drives servo {s} to {us[i]:.6g} us, past its pulse limits [{lo:g}, {hi:g}] us ({f})")
        bad = first_failure(masks)
        if bad is not None:
            i, j = bad
            point = format_point(names, [np.ravel(c)[i] for c in coords])
            raise RobotError(f"calibration: target {point} {reasons[j](i)}")

    def servo_records(self, geometry) -> list[dict]:
        """Each servo's calibration as used (µs, deg): for the manifest and the report."""
        cal, u = self.joint_map(geometry), self.pulse_unit_us
        out = []
        for k, (name, a) in enumerate(zip(geometry.servos, self.neutral_angles(geometry))):
            m = cal.servos[k]
            lo, hi = self.limits_us(name)
            rec = {"servo": name, "map": "table" if isinstance(m, TableMap) else "linear",
                   "neutral_angle_deg": a, "neutral_pulse_us": float(m.pulse(a)) * u}
            if isinstance(m, TableMap):
                rec["table"] = [[d, p * u] for d, p in m.points]
            else:
                rec.update(zero_pulse_us=float(m.pulse(0.0)) * u, us_per_degree=m.pu_per_degree * u)
            rec.update(trim_us=m.trim_pu * u, pulse_min_us=lo, pulse_max_us=hi)
            out.append(rec)
        return out

    def record(self) -> dict:
        d = {**dataclasses.asdict(self), "directions": list(self.directions)}
        del d["servos"]
        if self.servos:   # left out without overrides: the record (and plan-cache key) they predate
            d["servos"] = {name: o.record() for name, o in self.servos.items()}
        return d

    @classmethod
    def from_record(cls, d: dict) -> "CalibrationSpec":
        servos = {name: _override(t, name) for name, t in d.get("servos", {}).items()}
        return cls(**{**d, "directions": tuple(d["directions"]), "servos": servos})


def _override(t, name: str) -> ServoOverride:
    try:
        return ServoOverride.parse(t, f"calibration.servos.{name}")
    except ValueError as e:
        raise RobotError(str(e)) from None


def _parse_servos(table: dict, geometry) -> dict:
    """``[calibration.servos]``: one table per servo named as the geometry names them, in
    the geometry's servo order."""
    refuse_extra(table, geometry.servos, "calibration.servos.")
    return {name: _override(field_table(table, name, "calibration.servos."), name)
            for name in geometry.servos if name in table}


# -- fit options -------------------------------------------------------------------------
#: coefficient-table entries per servo polynomial: the default (small tables: cells along one
#: input or a grid over two), and the most a description may allow (cells of computed
#: features too, e.g. rho2 x z, where at least FEATURE_GRID_ENTRIES are allowed; fit/features.py)
TABLE_ENTRIES, MAX_TABLE_ENTRIES = 16, 4096


@dataclass(frozen=True)
class FitOptions:
    """How the plan is fitted (``[fit]``)."""
    tolerance_pu: float = 0.5
    lowering: str = "mixed"     # one of LOWERINGS: how servo polynomials become plan operations
    products: str = "exact"     # one of PRODUCTS: product widths exact or fitted to hardware.dsp
    table_entries: int = TABLE_ENTRIES   # most coefficient-table entries per servo polynomial

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
        n = self.table_entries
        if isinstance(n, bool) or not isinstance(n, int) or not TABLE_ENTRIES <= n <= MAX_TABLE_ENTRIES:
            raise RobotError(f"fit.table_entries must be an integer from {TABLE_ENTRIES} to {MAX_TABLE_ENTRIES}, "
                             f"not {n!r}")

    def record(self) -> dict:
        """The fields as given; ``table_entries`` only where it is not the default (so records
        written before it give the same record and plan-cache key)."""
        rec = dataclasses.asdict(self)
        if rec["table_entries"] == TABLE_ENTRIES:
            del rec["table_entries"]
        return rec


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
    dsp_primitives: bool = False    # modulo, folded, shared cores: products on DSP primitives with their registers
    cost: str = COSTS[0]            # one of ikseries.fit.cost.COSTS: what the fitter minimises

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
        self._validate_cost(lab)

    def _validate_cost(self, lab: dict) -> None:
        if self.cost not in COSTS:
            raise RobotError(f"{lab['cost']} must be one of {', '.join(COSTS)}, not {self.cost!r}")
        if self.cost == COSTS[0]:         # the default
            return
        if self.architecture not in DEVICE_COST_ARCHITECTURES:
            raise RobotError(f"{lab['architecture']} must be {' or '.join(DEVICE_COST_ARCHITECTURES)} when "
                             f"{lab['cost']} is {self.cost!r} (the cores that price a plan on the device), "
                             f"not {self.architecture!r}")
        if self.dsp not in FAMILIES:
            raise RobotError(f"{lab['dsp']} must be one of {', '.join(FAMILIES)} when {lab['cost']} is "
                             f"{self.cost!r} (the family whose reference part prices the plan), not {self.dsp!r}")

    def _validate_dsp_primitives(self, lab: dict) -> None:
        prim = self.dsp_primitives
        if not isinstance(prim, bool):
            raise RobotError(f"{lab['dsp_primitives']} must be true or false, not {prim!r}")
        prim_families = {p.family: p for p in PRIMITIVES.values() if p.role == "multiplier"}
        if prim and self.dsp not in prim_families:
            raise RobotError(f"{lab['dsp']} must be {' or '.join(prim_families)} when {lab['dsp_primitives']} is "
                             f"true (the DSP primitives instantiated: "
                             + ", ".join(f"{FAMILIES[f].label} {p.name}" for f, p in prim_families.items())
                             + f"), not {self.dsp!r}")
        if prim and self.architecture == "pipelined":
            # its products are Yosys's: asked for primitives, it would silently drop them
            raise RobotError(f"{lab['architecture']} must be auto, modulo, folded or fastest when "
                             f"{lab['dsp_primitives']} is true (the pipelined core instantiates no primitives; "
                             f"modulo at interval 1 takes a target per cycle on registered ones), not 'pipelined'")

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
        """The fields; ``cost`` only where it is not the default (records written before it stay
        the same)."""
        rec = dataclasses.asdict(self)
        if rec["cost"] == COSTS[0]:
            del rec["cost"]
        return rec
