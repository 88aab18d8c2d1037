"""Robot descriptions: TOML format, validation and built-in presets."""
from __future__ import annotations

import dataclasses
import json
import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from .constraints.devices import FAMILIES, FIT_DEVICES, PRIMITIVES
from .geometry import geometry_class, geometry_type
from .kinematics import Calibration, UnreachableError
from .reach import ReachUnprovenError, prove_box_reachable

__all__ = ["RobotError", "InputSpec", "Robot", "load_robot", "load_preset", "preset_names", "parse_robot",
           "robot_record", "robot_from_record", "fit_record", "with_hardware", "ARCHITECTURES", "DSP_CHOICES", "PRODUCTS"]

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


class RobotError(ValueError):
    """An invalid robot description; the message names the field and the bad value."""


@dataclass(frozen=True)
class InputSpec:
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
class Robot:
    name: str
    description: str
    geometry: object  # an ikseries.geometry.Geometry of a registered class
    inputs: tuple[InputSpec, ...]
    neutral_pose: dict
    pulse_unit_us: float
    neutral_pulse_pu: float
    pu_per_degree: float
    directions: tuple[int, ...]
    pulse_min_us: float
    pulse_max_us: float
    tolerance_pu: float
    clock_hz: int
    pwm_period_us: float
    # hardware architecture (defaults keep records written before these fields loadable)
    legs: int = 1                   # identical legs sharing one fitted plan
    architecture: str = "pipelined"  # one of ARCHITECTURES
    multipliers: int = 1            # multiplier units of a folded evaluator
    dsp: str = "ice40"              # one of DSP_CHOICES
    min_refresh_hz: float = 1000.0  # every leg's servos re-evaluated at least this often
    fit_device: str | None = None   # one of FIT_DEVICES: the device "fastest" must fit
    lowering: str = "mixed"         # one of LOWERINGS: how servo polynomials become plan operations
    interval: int = 8               # initiation interval of a modulo-scheduled evaluator
    products: str = "exact"         # one of PRODUCTS: product widths exact or fitted to hardware.dsp
    dsp_primitives: bool = False    # modulo cores: products on instantiated DSP primitives with their registers

    @property
    def servos(self) -> tuple[str, ...]:
        return self.geometry.servos

    @property
    def ticks_per_pu(self) -> float:
        """PWM clock ticks per pulse unit."""
        return self.clock_hz * self.pulse_unit_us * 1e-6

    @property
    def pwm_period_ticks(self) -> int:
        return int(round(self.pwm_period_us * 1e-6 * self.clock_hz))

    def pulse_limits_ticks(self) -> tuple[int, int]:
        tpu = self.clock_hz * 1e-6
        return int(np.ceil(self.pulse_min_us * tpu)), int(np.floor(self.pulse_max_us * tpu))

    @property
    def calibration(self) -> Calibration:
        pose = [self.neutral_pose[i.name] for i in self.inputs]
        neutral = tuple(float(a) for a in self.geometry.ik(*pose))
        return Calibration(neutral, self.directions, self.neutral_pulse_pu, self.pu_per_degree)

    def pulses_pu(self, *coords):
        """Exact pulse widths (pu, float64) per servo for input coordinate arrays."""
        return self.calibration.pulses(self.geometry.ik(*coords))


# -- parsing helpers -------------------------------------------------------------------
def _number(table, key, path, *, default=None, positive=False, integer=False):
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


def _table(table, key, path, required=True):
    v = table.get(key, None)
    if v is None:
        if required:
            raise RobotError(f"{path}{key} is missing")
        return {}
    if not isinstance(v, dict):
        raise RobotError(f"{path}{key} must be a table, not {v!r}")
    return v


def _no_extra(table, allowed, path):
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise RobotError(f"unknown field {path}{extra[0]} (expected one of: {', '.join(sorted(allowed))})")


def parse_robot(data: dict, source: str = "robot") -> Robot:
    """Validate a parsed TOML table and build a :class:`Robot`."""
    if not isinstance(data, dict):
        raise RobotError(f"{source}: a robot description must be a table")
    _no_extra(data, {"name", "description", "legs", "geometry", "workspace", "calibration", "fit", "hardware"}, "")
    name = data.get("name")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise RobotError(f"name must be an ASCII letter followed by at most {NAME_MAX - 1} ASCII letters, "
                         f"digits, '-' and '_' (it names the output files and the Verilog module), "
                         f"not {name!r}")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise RobotError(f"description must be a string, not {desc!r}")

    geo = _table(data, "geometry", "")
    gtype = geo.get("type")
    try:
        cls = geometry_class(gtype)
    except ValueError as e:
        raise RobotError(str(e)) from None
    fields = [f for f in cls.__dataclass_fields__]
    _no_extra(geo, ["type", *fields], "geometry.")
    signed = getattr(cls, "signed_fields", ())  # fields that may be <= 0 (e.g. an angle)
    kw = {f: float(_number(geo, f, "geometry.", positive=f not in signed)) for f in fields}
    try:
        geometry = cls(**kw)
    except ValueError as e:
        raise RobotError(f"geometry.{e}") from None

    ws = _table(data, "workspace", "")
    _no_extra(ws, geometry.inputs, "workspace.")
    inputs = []
    for name_i, unit in zip(geometry.inputs, geometry.input_units):
        t = _table(ws, name_i, "workspace.")
        p = f"workspace.{name_i}."
        _no_extra(t, ["min", "max", "frac_bits"], p)
        lo, hi = _number(t, "min", p), _number(t, "max", p)
        if not lo < hi:
            raise RobotError(f"{p}max must be > {p}min ({lo!r}), not {hi!r}")
        fb = _number(t, "frac_bits", p, integer=True)
        if not 0 <= fb <= 16:
            raise RobotError(f"{p}frac_bits must be in 0..16, not {fb!r}")
        check = getattr(geometry, "workspace_error", None)
        problem = check(name_i, lo, hi) if check is not None else None
        if problem:
            raise RobotError(problem)
        spec = InputSpec(name_i, unit, float(lo), float(hi), fb)
        if spec.lo > spec.hi:
            raise RobotError(f"{p}: no value with {fb} fractional bits lies in [{lo!r}, {hi!r}]")
        inputs.append(spec)

    cal = _table(data, "calibration", "")
    p = "calibration."
    _no_extra(cal, ["pulse_unit_us", "neutral_pulse_pu", "pu_per_degree", "neutral_pose", "directions",
                    "pulse_min_us", "pulse_max_us"], p)
    pose = _table(cal, "neutral_pose", p)
    _no_extra(pose, geometry.inputs, "calibration.neutral_pose.")
    pose = {i.name: float(_number(pose, i.name, "calibration.neutral_pose.")) for i in inputs}
    dirs = cal.get("directions", [1] * len(geometry.servos))
    if (not isinstance(dirs, list) or len(dirs) != len(geometry.servos)
            or any(d not in (1, -1) or isinstance(d, bool) for d in dirs)):
        raise RobotError(f"calibration.directions must be a list of {len(geometry.servos)} values "
                         f"each +1 or -1, not {dirs!r}")
    pmin = float(_number(cal, "pulse_min_us", p, default=500.0, positive=True))
    pmax = float(_number(cal, "pulse_max_us", p, default=2500.0, positive=True))
    if not pmin < pmax:
        raise RobotError(f"calibration.pulse_max_us must be > pulse_min_us ({pmin!r}), not {pmax!r}")

    fit = _table(data, "fit", "", required=False)
    _no_extra(fit, ["tolerance_pu", "lowering", "products"], "fit.")
    tol = fit.get("tolerance_pu", 0.5)
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0:
        raise RobotError(f"fit.tolerance_pu must be > 0 pu, not {tol!r}")
    if not np.isfinite(tol):
        raise RobotError(f"fit.tolerance_pu must be finite, not {tol!r}")
    lowering = fit.get("lowering", "mixed")
    if lowering not in LOWERINGS:
        raise RobotError(f"fit.lowering must be one of {', '.join(LOWERINGS)}, not {lowering!r}")
    products = fit.get("products", "exact")
    if products not in PRODUCTS:
        raise RobotError(f"fit.products must be one of {', '.join(PRODUCTS)}, not {products!r}")

    hw = _table(data, "hardware", "", required=False)
    _no_extra(hw, ["clock_hz", "pwm_period_us", "architecture", "multipliers", "interval", "dsp", "min_refresh_hz",
                   "fit_device", "dsp_primitives"], "hardware.")
    clk = _number(hw, "clock_hz", "hardware.", default=48_000_000, positive=True, integer=True)
    period = float(_number(hw, "pwm_period_us", "hardware.", default=20000.0, positive=True))
    if period <= pmax:
        raise RobotError(f"hardware.pwm_period_us must be > calibration.pulse_max_us ({pmax:g}), not {period!r}")

    robot = Robot(name, desc, geometry, tuple(inputs), pose,
                  float(_number(cal, "pulse_unit_us", p, positive=True)),
                  float(_number(cal, "neutral_pulse_pu", p, positive=True)),
                  float(_number(cal, "pu_per_degree", p, positive=True)),
                  tuple(dirs), pmin, pmax, float(tol), int(clk), period,
                  legs=data.get("legs", 1),
                  architecture=hw.get("architecture", "auto" if data.get("legs", 1) != 1 else "pipelined"),
                  multipliers=hw.get("multipliers", 1), dsp=hw.get("dsp", _default_dsp(hw.get("fit_device"))),
                  min_refresh_hz=hw.get("min_refresh_hz", 1000.0), fit_device=hw.get("fit_device"),
                  lowering=lowering, interval=hw.get("interval", 8), products=products,
                  dsp_primitives=hw.get("dsp_primitives", False))
    _check_hardware(robot)
    check_architecture_options(robot, set(hw))
    robot = dataclasses.replace(robot, min_refresh_hz=float(robot.min_refresh_hz))
    if robot.ticks_per_pu < 1:
        raise RobotError(f"hardware.clock_hz must give at least one PWM tick per pulse unit "
                         f"(>= {1 / (robot.pulse_unit_us * 1e-6):g} Hz), not {clk!r}")
    _check_pulses(robot)
    _check_refresh(robot)
    _check_reachable(robot)
    return robot


#: robot names: they name the output files and, as ``<name>_core`` with '-' as '_', the
#: Verilog module, so ASCII only and a letter first
NAME_MAX = 64
NAME_PATTERN = re.compile(rf"[A-Za-z][A-Za-z0-9_-]{{0,{NAME_MAX - 1}}}")

#: option -> how errors name it (TOML field names; the CLI passes its option names)
HARDWARE_LABELS = {"legs": "legs", "architecture": "hardware.architecture",
                   "multipliers": "hardware.multipliers", "interval": "hardware.interval", "dsp": "hardware.dsp",
                   "min_refresh_hz": "hardware.min_refresh_hz", "fit_device": "hardware.fit_device",
                   "dsp_primitives": "hardware.dsp_primitives"}


def _default_dsp(fit_device) -> str:
    """hardware.dsp when not given: the family of hardware.fit_device (its DSP size), else ice40."""
    return FIT_DEVICES.get(fit_device, "ice40") if isinstance(fit_device, str) else "ice40"


def _check_hardware(robot: Robot, labels: dict | None = None) -> None:
    """Validate the architecture options of ``robot``; errors name the field via ``labels``."""
    lab = {**HARDWARE_LABELS, **(labels or {})}

    def pos_int(key):
        v = getattr(robot, key)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise RobotError(f"{lab[key]} must be an integer >= 1, not {v!r}")
    pos_int("legs")
    pos_int("multipliers")
    pos_int("interval")
    for key, choices in (("architecture", ARCHITECTURES), ("dsp", DSP_CHOICES)):
        v = getattr(robot, key)
        if v not in choices:
            raise RobotError(f"{lab[key]} must be one of {', '.join(choices)}, not {v!r}")
    r = robot.min_refresh_hz
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not np.isfinite(r) or r <= 0:
        raise RobotError(f"{lab['min_refresh_hz']} must be a number > 0, not {r!r}")
    if robot.legs > 1 and robot.architecture in ("pipelined", "modulo"):
        raise RobotError(f"{lab['architecture']} must be auto, folded or fastest for {lab['legs']} = {robot.legs} "
                         f"(the legs share one folded evaluator), not {robot.architecture!r}")
    prim = robot.dsp_primitives
    if not isinstance(prim, bool):
        raise RobotError(f"{lab['dsp_primitives']} must be true or false, not {prim!r}")
    prim_families = {p.family: p for p in PRIMITIVES.values()}
    if prim and robot.dsp not in prim_families:
        raise RobotError(f"{lab['dsp']} must be {', '.join(prim_families)} when {lab['dsp_primitives']} is true "
                         f"(the only DSP primitive instantiated is the "
                         + ", ".join(f"{FAMILIES[f].label} {p.name}" for f, p in prim_families.items())
                         + f"), not {robot.dsp!r}")
    dev = robot.fit_device
    if dev is not None and dev not in FIT_DEVICES:
        raise RobotError(f"{lab['fit_device']} must be one of {', '.join(FIT_DEVICES)}, not {dev!r}")
    if dev is not None and robot.architecture != "fastest":
        raise RobotError(f"{lab['architecture']} must be fastest when {lab['fit_device']} is given "
                         f"(the device the fastest configuration must fit), not {robot.architecture!r}")
    if dev is None and robot.architecture == "fastest":
        raise RobotError(f"{lab['fit_device']} must be one of {', '.join(FIT_DEVICES)} when "
                         f"{lab['architecture']} is fastest (the device to fit), not None")


#: options that only one architecture takes: option -> (architecture, why the others don't)
ARCHITECTURE_OPTIONS = {"multipliers": ("folded", "auto picks 1 or 2 multipliers itself"),
                        "interval": ("modulo", "auto and fastest pick the interval themselves")}


def check_architecture_options(robot: Robot, given, labels: dict | None = None) -> None:
    """Refuse an option of :data:`ARCHITECTURE_OPTIONS` that was ``given`` (a set of option
    names) with another architecture; errors name the fields via ``labels``."""
    lab = {**HARDWARE_LABELS, **(labels or {})}
    for key, (arch, why) in ARCHITECTURE_OPTIONS.items():
        if key in given and robot.architecture != arch:
            raise RobotError(f"{lab['architecture']} must be {arch} when {lab[key]} is given ({why}), "
                             f"not {robot.architecture!r}")


def with_hardware(robot: Robot, labels: dict | None = None, **options) -> Robot:
    """``robot`` with some architecture options replaced (``architecture``, ``multipliers``,
    ``dsp``, ...), validated; ``labels`` maps an option to the name errors use for it."""
    new = dataclasses.replace(robot, **options)
    _check_hardware(new, labels)
    _check_refresh(new, labels)
    return new


def _check_reachable(robot: Robot) -> None:
    """The neutral pose and every target of the workspace box must be reachable: a grid over
    the box (corners included) is checked first, then the whole box is proven by interval
    analysis (:func:`ikseries.reach.prove_box_reachable`)."""
    try:
        robot.geometry.ik(*(robot.neutral_pose[i.name] for i in robot.inputs))
    except UnreachableError as e:
        raise RobotError(f"calibration.neutral_pose: {e}") from None
    axes = [np.linspace(i.min, i.max, 9) for i in robot.inputs]
    grid = [g.ravel() for g in np.meshgrid(*axes, indexing="ij")]
    try:
        robot.geometry.ik(*grid)
        prove_box_reachable(robot.geometry, [i.min for i in robot.inputs], [i.max for i in robot.inputs])
    except (UnreachableError, ReachUnprovenError) as e:
        raise RobotError(f"workspace: {e}") from None


#: share of fit.tolerance_pu the fit keeps for the plan's own rounding and its safety margin
#: (``ikseries.fit.fitter.Budget.split``: 10 % quantization, 15 % margin); the output's
#: rounding to whole PWM ticks must leave the rest a positive approximation budget
FIT_RESERVED_SHARE = 0.25


def _check_pulses(robot: Robot) -> None:
    """Fit-free checks of the pulse format: the neutral pulse within the pulse limits, and one
    PWM tick fine enough that rounding to it leaves the fit an approximation budget."""
    neutral_us = robot.neutral_pulse_pu * robot.pulse_unit_us
    if not robot.pulse_min_us <= neutral_us <= robot.pulse_max_us:
        raise RobotError(f"calibration.neutral_pulse_pu must give a pulse within [pulse_min_us, pulse_max_us] = "
                         f"[{robot.pulse_min_us:g}, {robot.pulse_max_us:g}] us, i.e. within "
                         f"[{robot.pulse_min_us / robot.pulse_unit_us:g}, {robot.pulse_max_us / robot.pulse_unit_us:g}] "
                         f"pu at pulse_unit_us = {robot.pulse_unit_us:g}, not {robot.neutral_pulse_pu!r}")
    rounding = 0.5 / robot.ticks_per_pu     # pu: half a tick
    if rounding >= (1.0 - FIT_RESERVED_SHARE) * robot.tolerance_pu:
        need = 0.5 / ((1.0 - FIT_RESERVED_SHARE) * robot.tolerance_pu)   # ticks per pu
        raise RobotError(f"fit.tolerance_pu must be > {rounding / (1.0 - FIT_RESERVED_SHARE):.6g} pu with "
                         f"{robot.ticks_per_pu:g} PWM ticks per pulse unit (rounding to whole ticks costs "
                         f"{rounding:.6g} pu; or raise hardware.clock_hz or calibration.pulse_unit_us to "
                         f"give more than {need:.6g} ticks per pu), not {robot.tolerance_pu!r}")


def _check_refresh(robot: Robot, labels: dict | None = None) -> None:
    """hardware.min_refresh_hz must be reachable: no architecture takes more than one target
    per clock cycle, and the legs share it, so no leg is refreshed more than clock_hz / legs
    times a second."""
    lab = {**HARDWARE_LABELS, **(labels or {})}
    best = robot.clock_hz / robot.legs
    if robot.min_refresh_hz > best:
        raise RobotError(f"{lab['min_refresh_hz']} must be at most {best:.6g} Hz (one target per clock "
                         f"cycle at hardware.clock_hz = {robot.clock_hz} shared by {lab['legs']} = "
                         f"{robot.legs}), not {robot.min_refresh_hz!r}")


def robot_record(robot: Robot) -> dict:
    """JSON-ready record of every parameter of ``robot`` (stored in the fit artifact)."""
    d = dataclasses.asdict(robot)
    d["geometry"] = {"type": geometry_type(robot.geometry), **dataclasses.asdict(robot.geometry)}
    d["inputs"] = [dataclasses.asdict(i) for i in robot.inputs]
    return json.loads(json.dumps(d))


#: Robot fields that do not change the fitted plan (hardware architecture, naming, PWM period)
NON_FIT_FIELDS = ("name", "description", "legs", "architecture", "multipliers", "interval", "dsp", "min_refresh_hz",
                  "fit_device", "pwm_period_us", "dsp_primitives")


def fit_record(record: dict) -> dict:
    """The part of a :func:`robot_record` that decides the fitted plan (``dsp`` too when
    ``fit.products = "dsp"`` sizes the products by it)."""
    skip = set(NON_FIT_FIELDS)
    if record.get("products", "exact") == "exact":
        skip.add("products")    # so records written before fit.products existed still match
    else:
        skip.discard("dsp")     # the DSP family sizes the products
    return {k: v for k, v in record.items() if k not in skip}


def robot_from_record(d: dict) -> Robot:
    """Inverse of :func:`robot_record` (the record is re-validated)."""
    try:
        geo = dict(d["geometry"])
        cls = geometry_class(geo.pop("type"))
        fields = {k: v for k, v in d.items() if k not in ("geometry", "inputs")}
        fields["directions"] = tuple(fields["directions"])
        robot = Robot(geometry=cls(**geo), inputs=tuple(InputSpec(**i) for i in d["inputs"]), **fields)
    except (KeyError, TypeError, ValueError) as e:
        raise RobotError(f"not a robot record: {e}") from None
    _check_hardware(robot)   # records written before the architecture fields get their defaults
    _check_reachable(robot)
    return robot


def load_robot(path) -> Robot:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise RobotError(f"cannot read robot description {str(path)!r}: {e.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise RobotError(f"robot description {str(path)!r} must be UTF-8 text (TOML), not bytes like "
                         f"{raw[e.start:e.start + 4]!r} at byte {e.start}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise RobotError(f"{path}: invalid TOML: {e}") from None
    return parse_robot(data, str(path))


def preset_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("ikseries.presets").iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    if name not in preset_names():
        raise RobotError(f"preset must be one of {preset_names()}, not {name!r}")
    return resources.files("ikseries.presets").joinpath(f"{name}.toml").read_text()


def load_preset(name: str) -> Robot:
    return parse_robot(tomllib.loads(preset_text(name)), f"preset {name}")
