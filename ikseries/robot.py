"""Robot descriptions: the robot as its parts, TOML parsing, records and built-in presets.

A :class:`Robot` is its name, its number of legs, its geometry and one part per TOML table
(:mod:`ikseries.robot_parts`). Each part parses and validates its own table; the checks that
need several parts are made here once the parts are built. :meth:`Robot.fit_record` is the
part of the description that decides the fitted plan: the plan cache and ``--plan`` compare it.
"""
from __future__ import annotations

import dataclasses
import json
import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from .geometry import geometry_class, geometry_type
from .joints import CONVENTION_FIELDS, geometry_record
from .calibration import Calibration
from .kinematics import UnreachableError
from .chain.parse import CHAIN_TYPES, parse_chain
from .reach import ReachUnprovenError, check_no_wrap, prove_box_reachable
from .body import Body
from .channels import check_channels
from .fit.cost import COSTS
from .robot_parts import (ARCHITECTURES, DSP_CHOICES, HARDWARE_LABELS, LOWERINGS, PRODUCTS, CalibrationSpec,
                          FitOptions, HardwareOptions, InputSpec, RobotError, Workspace, field_number, field_table,
                          refuse_extra)

__all__ = ["RobotError", "InputSpec", "Workspace", "CalibrationSpec", "FitOptions", "HardwareOptions", "Robot",
           "load_robot", "load_preset", "preset_names", "parse_robot", "robot_record", "robot_from_record",
           "nested_record", "fit_record", "with_hardware", "with_fit", "check_architecture_options",
           "ARCHITECTURES", "DSP_CHOICES", "LOWERINGS", "PRODUCTS"]

#: robot names: they name the output files and, as ``<name>_core`` with '-' as '_', the
#: Verilog module, so ASCII only and a letter first
NAME_MAX = 64
NAME_PATTERN = re.compile(rf"[A-Za-z][A-Za-z0-9_-]{{0,{NAME_MAX - 1}}}")

#: share of fit.tolerance_pu the fit keeps for the plan's own rounding and its safety margin
#: (``ikseries.fit.fitter.Budget.split``: 10 % quantization, 15 % margin); the output's
#: rounding to whole PWM ticks must leave the rest a positive approximation budget
FIT_RESERVED_SHARE = 0.25


@dataclass(frozen=True)
class Robot:
    """A robot description: ``legs`` identical legs of one ``geometry`` sharing one fitted plan,
    and the parts read from the TOML tables of the same names; ``body`` (optional, ``[body]``,
    :mod:`ikseries.body`) places the legs on a body and gives their sides."""
    name: str
    description: str
    legs: int
    geometry: object  # an ikseries.geometry.Geometry of a registered class
    workspace: Workspace
    calibration: CalibrationSpec
    fit: FitOptions
    hardware: HardwareOptions
    body: Body | None = None

    @property
    def servos(self) -> tuple[str, ...]:
        return self.geometry.servos

    @property
    def ticks_per_pu(self) -> float:
        """PWM clock ticks per pulse unit."""
        return self.hardware.clock_hz * self.calibration.pulse_unit_us * 1e-6

    def pulse_limits_ticks(self) -> dict[str, tuple[int, int]]:
        """Per servo its pulse limits in whole PWM ticks (inside the µs limits): the output clamp."""
        return {s: self.limits_ticks(*self.calibration.limits_us(s)) for s in self.servos}

    def limits_ticks(self, lo_us: float, hi_us: float) -> tuple[int, int]:
        """Pulse limits in µs as whole PWM ticks inside them."""
        tpu = self.hardware.clock_hz * 1e-6
        return int(np.ceil(lo_us * tpu)), int(np.floor(hi_us * tpu))

    @property
    def joint_calibration(self) -> Calibration:
        """The joint angle -> pulse map of the geometry under the calibration."""
        return self.calibration.joint_map(self.geometry)

    def pulses_pu(self, *coords):
        """Exact pulse widths (pu, float64) per servo for input coordinate arrays."""
        return self.joint_calibration.pulses(self.geometry.ik(*coords))

    @property
    def fitted(self) -> "Robot":
        """The robot its plan is fitted for: with a body, ``fit.tolerance_pu`` less what its
        channel table adds to the plan's error and divided by the largest gain it applies
        (:func:`ikseries.channels.fit_tolerance_pu`), so that every channel, mirrored, scaled or
        not, stays within the tolerance; else the robot itself."""
        from .channels import fit_tolerance_pu

        tol = fit_tolerance_pu(self) if self.body is not None else self.fit.tolerance_pu
        if tol == self.fit.tolerance_pu:
            return self
        if tol <= 0:
            raise RobotError(f"fit.tolerance_pu must exceed the error the channel table adds (a mirrored leg's "
                             f"2 * centre, a scaled channel's gain, rounded to PWM ticks), not {self.fit.tolerance_pu!r}")
        return dataclasses.replace(self, fit=dataclasses.replace(self.fit, tolerance_pu=tol))

    def fit_record(self) -> dict:
        """The part of :func:`robot_record` that decides the fitted plan (:func:`fit_record`): of
        :attr:`fitted`, so a mirror's margin is part of it."""
        return fit_record(robot_record(self.fitted))


def _parse_name(data: dict) -> tuple[str, str]:
    name = data.get("name")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise RobotError(f"name must be an ASCII letter followed by at most {NAME_MAX - 1} ASCII letters, "
                         f"digits, '-' and '_' (it names the output files and the Verilog module), "
                         f"not {name!r}")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise RobotError(f"description must be a string, not {desc!r}")
    return name, desc


def _parse_geometry(geo: dict):
    """The geometry of the ``[geometry]`` table: its ``type`` and that class's fields, the
    numbers required and the optional joint conventions (:mod:`ikseries.joints`) as given,
    checked by the geometry's constructor."""
    try:
        cls = geometry_class(geo.get("type"))
    except ValueError as e:
        raise RobotError(str(e)) from None
    fields = [f.name for f in dataclasses.fields(cls)]
    refuse_extra(geo, ["type", *fields], "geometry.")
    signed = getattr(cls, "signed_fields", ())  # fields that may be <= 0 (e.g. an angle)
    kw = {f: float(field_number(geo, f, "geometry.", positive=f not in signed))
          for f in fields if f not in CONVENTION_FIELDS}
    kw.update({f: geo[f] for f in CONVENTION_FIELDS if f in fields and f in geo})
    try:
        return cls(**kw)
    except ValueError as e:
        raise RobotError(f"geometry.{e}") from None


def parse_robot(data: dict, source: str = "robot", base_dir=None) -> Robot:
    """Validate a parsed TOML table and build a :class:`Robot`; files it names (a chain's
    URDF) are relative to ``base_dir``."""
    if not isinstance(data, dict):
        raise RobotError(f"{source}: a robot description must be a table")
    refuse_extra(data, {"name", "description", "legs", "geometry", "workspace", "calibration", "fit", "hardware",
                        "body"}, "")
    name, desc = _parse_name(data)
    geo = field_table(data, "geometry", "")
    geometry = parse_chain(geo, base_dir) if geo.get("type") in CHAIN_TYPES else _parse_geometry(geo)
    workspace = Workspace.parse(field_table(data, "workspace", ""), geometry)
    calibration = CalibrationSpec.parse(field_table(data, "calibration", ""), geometry)
    fit = FitOptions.parse(field_table(data, "fit", "", required=False))
    body = None
    if "body" in data:
        body = Body.parse(field_table(data, "body", ""), data.get("legs"), geometry, workspace)
        _check_mirrored_tables(calibration, body)
    legs = data.get("legs", 1) if body is None else len(body.legs)
    _check_legs_count(legs)
    hardware = HardwareOptions.parse(field_table(data, "hardware", "", required=False), legs)
    robot = Robot(name, desc, legs, geometry, workspace, calibration, fit, hardware, body)
    _check_period(robot)
    _check_legs(robot)
    _check_ticks(robot)
    _check_pulses(robot)
    _check_refresh(robot)
    _check_reachable(robot)
    return robot


# -- checks across parts -----------------------------------------------------------------
def _check_mirrored_tables(calibration, body) -> None:
    """A left leg's pulse is ``2 centre -`` the right leg's: the mirror of a linear map only."""
    left = [leg.name for leg in body.legs if leg.mirrored]
    tables = [s for s, o in calibration.servos.items() if o.table is not None]
    if left and tables:
        raise RobotError(f"calibration.servos.{tables[0]}.table cannot be mirrored onto the left legs "
                         f"({', '.join(left)}): a left leg's pulse is 2 * centre - the right leg's, the mirror "
                         "image of a linear map only; give that servo us_per_degree instead")


def _check_legs_count(legs, labels: dict | None = None) -> None:
    lab = {**HARDWARE_LABELS, **(labels or {})}
    if isinstance(legs, bool) or not isinstance(legs, int) or legs < 1:
        raise RobotError(f"{lab['legs']} must be an integer >= 1, not {legs!r}")


def _check_legs(robot: Robot, labels: dict | None = None) -> None:
    """Several legs share one folded evaluator: only the architectures that fold may take them."""
    lab = {**HARDWARE_LABELS, **(labels or {})}
    arch = robot.hardware.architecture
    if robot.legs > 1 and arch in ("pipelined", "modulo"):
        raise RobotError(f"{lab['architecture']} must be auto, folded or fastest for {lab['legs']} = {robot.legs} "
                         f"(the legs share one folded evaluator), not {arch!r}")


def _check_period(robot: Robot) -> None:
    period, pmax = robot.hardware.pwm_period_us, robot.calibration.pulse_max_us
    if period <= pmax:
        raise RobotError(f"hardware.pwm_period_us must be > calibration.pulse_max_us ({pmax:g}), not {period!r}")


def _check_ticks(robot: Robot) -> None:
    if robot.ticks_per_pu < 1:
        raise RobotError(f"hardware.clock_hz must give at least one PWM tick per pulse unit "
                         f"(>= {1 / (robot.calibration.pulse_unit_us * 1e-6):g} Hz), not {robot.hardware.clock_hz!r}")


def check_architecture_options(robot: Robot, given, labels: dict | None = None) -> None:
    """Refuse an architecture-specific option that was ``given`` (a set of option names) with
    another architecture (:meth:`HardwareOptions.check_given`)."""
    robot.hardware.check_given(given, labels)


def with_hardware(robot: Robot, labels: dict | None = None, **options) -> Robot:
    """``robot`` with ``legs`` or some :class:`HardwareOptions` fields (``architecture``,
    ``multipliers``, ``dsp``, ...) replaced, validated; ``labels`` maps an option to the name
    errors use for it."""
    legs = options.pop("legs", robot.legs)
    new = dataclasses.replace(robot, legs=legs, hardware=dataclasses.replace(robot.hardware, **options))
    _check_legs_count(new.legs, labels)
    if new.body is not None and new.legs != len(new.body.legs):
        lab = {**HARDWARE_LABELS, **(labels or {})}
        raise RobotError(f"{lab['legs']} must be {len(new.body.legs)} (the number of [[body.legs]]) for "
                         f"{robot.name}, not {new.legs!r}")
    new.hardware.validate(labels)
    _check_legs(new, labels)
    _check_refresh(new, labels)
    return new


def with_fit(robot: Robot, **options) -> Robot:
    """``robot`` with some :class:`FitOptions` fields (``tolerance_pu``, ``lowering``,
    ``products``) replaced, validated."""
    new = dataclasses.replace(robot, fit=dataclasses.replace(robot.fit, **options))
    new.fit.validate()
    _check_pulses(new)
    return new


def _check_reachable(robot: Robot) -> None:
    """The neutral pose and every target of the workspace box must be reachable, and the
    calibration must keep every servo within its pulse limits (and a table servo within its
    table) there: a grid over the box (corners included) is checked first, then the whole box
    is proven reachable by interval analysis (:func:`ikseries.reach.prove_box_reachable`), or
    by the geometry's own ``check_box`` where it has one (a chain's numeric IK is no formula to
    run on intervals), then the calibration on the grid (between its points the certifier
    counts any pulse past the limits in its clamp term)."""
    ws, cal = robot.workspace, robot.calibration
    try:
        robot.geometry.ik(*(cal.neutral_pose[n] for n in ws.names))
    except UnreachableError as e:
        raise RobotError(f"calibration.neutral_pose: {e}") from None
    cal.check_neutral(robot.geometry)
    axes = [np.linspace(lo, hi, 9) for lo, hi in zip(ws.lows, ws.highs)]
    grid = [g.ravel() for g in np.meshgrid(*axes, indexing="ij")]
    shape = tuple(len(a) for a in axes)
    try:
        angles = robot.geometry.ik(*grid)
        check = getattr(robot.geometry, "check_box", None)
        try:
            if check is not None:
                check(ws.lows, ws.highs)
            else:
                prove_box_reachable(robot.geometry, ws.lows, ws.highs)
        except ReachUnprovenError:      # a wrap is one reason the proof fails: name it if it is that
            check_no_wrap(robot.geometry, ws.names, shape, grid, angles)
            raise
        check_no_wrap(robot.geometry, ws.names, shape, grid, angles)
    except (UnreachableError, ReachUnprovenError) as e:
        raise RobotError(f"workspace: {e}") from None
    cal.check_box(robot.geometry, ws.names, grid, angles)
    if robot.body is not None:
        neutral = [np.array([cal.neutral_pose[n]]) for n in ws.names]
        check_channels(robot, ws.names, [np.concatenate([p, g]) for p, g in zip(neutral, grid)])


def _check_pulses(robot: Robot) -> None:
    """One PWM tick must be fine enough that rounding to it leaves the fit an approximation
    budget of fit.tolerance_pu."""
    tol, tpp = robot.fit.tolerance_pu, robot.ticks_per_pu
    rounding = 0.5 / tpp     # pu: half a tick
    if rounding >= (1.0 - FIT_RESERVED_SHARE) * tol:
        need = 0.5 / ((1.0 - FIT_RESERVED_SHARE) * tol)   # ticks per pu
        raise RobotError(f"fit.tolerance_pu must be > {rounding / (1.0 - FIT_RESERVED_SHARE):.6g} pu with "
                         f"{tpp:g} PWM ticks per pulse unit (rounding to whole ticks costs "
                         f"{rounding:.6g} pu; or raise hardware.clock_hz or calibration.pulse_unit_us to "
                         f"give more than {need:.6g} ticks per pu), not {tol!r}")


def _check_refresh(robot: Robot, labels: dict | None = None) -> None:
    """hardware.min_refresh_hz must be reachable: no architecture takes more than one target
    per clock cycle, and the legs share it, so no leg is refreshed more than clock_hz / legs
    times a second."""
    lab = {**HARDWARE_LABELS, **(labels or {})}
    hw = robot.hardware
    best = hw.clock_hz / robot.legs
    if hw.min_refresh_hz > best:
        raise RobotError(f"{lab['min_refresh_hz']} must be at most {best:.6g} Hz (one target per clock "
                         f"cycle at hardware.clock_hz = {hw.clock_hz} shared by {lab['legs']} = "
                         f"{robot.legs}), not {hw.min_refresh_hz!r}")


# -- records -----------------------------------------------------------------------------
#: the record tables of the parts, and the classes whose fields a flat record spreads at its top level
RECORD_PARTS = {"calibration": CalibrationSpec, "fit": FitOptions, "hardware": HardwareOptions}


def robot_record(robot: Robot) -> dict:
    """JSON-ready record of every parameter of ``robot`` (stored in the fit artifact): the
    name, description and legs, then one table per part, like the TOML."""
    geometry = {"type": geometry_type(robot.geometry), **geometry_record(robot.geometry)}
    d = {"name": robot.name, "description": robot.description, "legs": robot.legs, "geometry": geometry,
         "workspace": robot.workspace.record(), "calibration": robot.calibration.record(),
         "fit": robot.fit.record(), "hardware": robot.hardware.record()}
    if robot.body is not None:      # absent without [body]: older records stay byte-identical
        d["body"] = robot.body.record()
    return json.loads(json.dumps(d))


def nested_record(d: dict) -> dict:
    """``d`` in the layout of :func:`robot_record`. Records written before the parts existed
    are flat (every field at the top level, the workspace as ``inputs``); their fields are
    moved into the table of the part that has them."""
    if not isinstance(d, dict) or "inputs" not in d:
        return d
    out = {k: d[k] for k in ("name", "description", "legs", "geometry") if k in d}
    out["workspace"] = {"inputs": d["inputs"]}
    for part, cls in RECORD_PARTS.items():
        out[part] = {f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d}
    known = {*out, "inputs", *(k for t in RECORD_PARTS for k in out[t])}
    unknown = sorted(set(d) - known)
    if unknown:
        raise RobotError(f"not a robot record: unknown field {unknown[0]!r}")
    return out


def fit_record(record: dict) -> dict:
    """The part of a robot record (either layout, :func:`nested_record`) that decides the
    fitted plan: the geometry, the workspace, the calibration, the fit options and the one
    hardware option the fit reads, the clock (it sets the PWM ticks per pulse unit), the DSP
    family too when ``fit.products = "dsp"`` sizes the products by it, and the record of the
    cost model the fit minimises (:func:`ikseries.architecture.recorded_cost_model`) when
    ``hardware.cost`` chooses another than the default. Flat, and without ``products`` when it
    is "exact" nor a cost model by default, so that records written before the parts (and
    before fit.products and hardware.cost) give the same record and the same plan-cache key."""
    r = nested_record(record)
    if not isinstance(r, dict):
        return {}
    hardware = r.get("hardware", {})
    fit = dict(r.get("fit", {}))
    key = {"geometry": r.get("geometry"), **r.get("workspace", {}), **r.get("calibration", {})}
    if "clock_hz" in hardware:
        key["clock_hz"] = hardware["clock_hz"]
    if fit.get("products", "exact") == "exact":
        fit.pop("products", None)
    elif "dsp" in hardware:
        key["dsp"] = hardware["dsp"]   # the DSP family sizes the products
    if hardware.get("cost", COSTS[0]) != COSTS[0]:     # the structures chosen are the model's
        from .architecture import recorded_cost_model
        key["cost_model"] = recorded_cost_model(hardware, r.get("legs", 1)).record()
    return {**key, **fit}


def robot_from_record(d: dict) -> Robot:
    """Inverse of :func:`robot_record`, for records of either layout (the record is
    re-validated; fields a record predates get their defaults)."""
    try:
        r = nested_record(d)
        geo = dict(r["geometry"])
        cls = geometry_class(geo.pop("type"))
        robot = Robot(r["name"], r["description"], r.get("legs", 1), cls(**geo),
                      Workspace.from_record(r["workspace"]), CalibrationSpec.from_record(r["calibration"]),
                      FitOptions(**r["fit"]), HardwareOptions(**r["hardware"]),
                      Body.from_record(r["body"]) if "body" in r else None)
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, RobotError):
            raise
        raise RobotError(f"not a robot record: {e}") from None
    _check_legs_count(robot.legs)
    if robot.body is not None and robot.legs != len(robot.body.legs):
        raise RobotError(f"not a robot record: legs {robot.legs!r} but {len(robot.body.legs)} body legs")
    robot.hardware.validate()
    _check_legs(robot)
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
    return parse_robot(data, str(path), path.parent)


def preset_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("ikseries.presets").iterdir() if p.name.endswith(".toml"))


def preset_text(name: str) -> str:
    if name not in preset_names():
        raise RobotError(f"preset must be one of {preset_names()}, not {name!r}")
    return resources.files("ikseries.presets").joinpath(f"{name}.toml").read_text()


def load_preset(name: str) -> Robot:
    return parse_robot(tomllib.loads(preset_text(name)), f"preset {name}")
