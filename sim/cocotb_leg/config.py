"""What a cocotb run of the bench is told: the run configuration file and the design's manifest.

The runner (:func:`ikseries.sim.runner.run`) writes a small JSON run configuration
(:class:`RunConfig`: manifest path, plan path, seed, random targets, test selection) and names it
in one environment variable, :data:`ENV_CONFIG`. Everything about the design (ports, widths,
latency, initiation interval, legs, PWM period, stream rule) comes from its ``manifest.json``
(:func:`ikseries.hdl.export.manifest`), read into a :class:`Design`. This module does not import
cocotb, so the runner can write what the bench reads.
"""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from .rules import RULES

__all__ = ["ENV_CONFIG", "CLOCK_NS", "TESTS", "ConfigFile", "RunConfig", "Field", "Design"]

#: environment variable holding the path of the run configuration JSON
ENV_CONFIG = "IKSERIES_BENCH_CONFIG"

#: clock period of the bench in ns (100 MHz)
CLOCK_NS = 10

#: the cocotb tests of :mod:`ikseries.sim.cocotb_leg.tests`
TESTS = ("test_back_to_back", "test_backpressure", "test_pwm")


def _positive_int(what: str, v) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ValueError(f"{what} must be a positive integer, not {v!r}")
    return v


class ConfigFile:
    """A frozen dataclass run configuration as the JSON file the runner writes and the bench
    reads (``tests``: a tuple, or None); subclasses name their runner in ``RUNNER``."""

    RUNNER = "ikseries.sim.runner.run"

    def write(self, path) -> Path:
        """Write the configuration as JSON to ``path``; returns the path."""
        path = Path(path)
        rec = dataclasses.asdict(self)
        rec["tests"] = None if self.tests is None else list(self.tests)
        path.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
        return path

    @classmethod
    def read(cls, path):
        """The configuration in the JSON file ``path``."""
        rec = json.loads(Path(path).read_text())
        tests = rec.pop("tests", None)
        return cls(**rec, tests=None if tests is None else tuple(tests))

    @classmethod
    def from_environment(cls):
        """The configuration named by :data:`ENV_CONFIG` (set by the runner)."""
        path = os.environ.get(ENV_CONFIG)
        if not path:
            raise RuntimeError(f"{ENV_CONFIG} is not set: start the bench with {cls.RUNNER}")
        return cls.read(path)


@dataclasses.dataclass(frozen=True)
class RunConfig(ConfigFile):
    """One run of the bench.

    Attributes
    ----------
    manifest : str
        Path of the design's ``manifest.json``.
    plan : str
        Path of the plan JSON the design was generated from (the golden model's input).
    seed : int
        Seed of the random targets and handshakes.
    n_random : int
        Random targets of the back-to-back test (the backpressure test runs half as many).
    tests : tuple of str, or None
        The selected tests (None: all); the runner passes the same selection to cocotb, and
        each test checks that it is one of them.
    """
    manifest: str
    plan: str
    seed: int = 1
    n_random: int = 3000
    tests: tuple[str, ...] | None = None

    def __post_init__(self):
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, not {self.seed!r}")
        _positive_int("n_random", self.n_random)
        if self.tests is not None and (not self.tests or not all(isinstance(t, str) and t for t in self.tests)):
            raise ValueError(f"tests must be None or test names, not {self.tests!r}")


@dataclasses.dataclass(frozen=True)
class Field:
    """One stream field of the manifest: its name, Verilog port and width in bits."""
    name: str
    port: str
    width: int


def _get(man: dict, *keys):
    v = man
    for k in keys:
        if not isinstance(v, dict) or k not in v:
            raise ValueError(f"manifest has no {'.'.join(keys)}")
        v = v[k]
    return v


@dataclasses.dataclass(frozen=True)
class Design:
    """What the bench needs of a design's manifest.

    Attributes
    ----------
    module : str
        Verilog module name.
    inputs, outputs : tuple of Field
        Target and width fields (without the leg field).
    leg_in, leg_out : Field or None
        The robot top's ``i_leg`` / ``o_leg`` (None on a leg top, or where zero bits wide).
    legs : int
        Legs served by the core (1 for a leg top).
    latency : int
        Input transfer edge -> output transfer edge, cycles.
    initiation_interval : int
        Cycles between input transfers.
    period : int
        PWM period in clock cycles.
    stream_rule : str
        A key of :data:`ikseries.sim.cocotb_leg.rules.RULES`.
    pwm : dict
        Leg top: {servo: port}; robot top: {(leg, servo): port}.
    period_start : str or None
        The robot top's period-start port.
    channel_table : dict or None
        The robot top's channel table record (:class:`ikseries.fit.channels.ChannelTable`:
        left legs' mirror, per-channel constants); None: its widths are the plan's.
    """
    module: str
    inputs: tuple[Field, ...]
    outputs: tuple[Field, ...]
    leg_in: Field | None
    leg_out: Field | None
    legs: int
    latency: int
    initiation_interval: int
    period: int
    stream_rule: str
    pwm: dict
    period_start: str | None
    channel_table: dict | None = None

    @property
    def robot(self) -> bool:
        """A robot top (legs sharing one evaluator, ``pwm_l<leg>_<servo>`` ports)?"""
        return self.period_start is not None

    @property
    def servos(self) -> list[str]:
        return [f.name for f in self.outputs]

    @classmethod
    def from_manifest(cls, man: dict) -> "Design":
        """Read a manifest (:func:`ikseries.hdl.export.manifest`); a missing or bad entry is one
        ``ValueError`` line naming it."""
        def fields(side):
            return [Field(f["name"], f["port"], f["width"]) for f in _get(man, side, "fields")]
        ins, outs = fields("inputs"), fields("outputs")
        leg_in = next((f for f in ins if f.name == "leg"), None)
        leg_out = next((f for f in outs if f.name == "leg"), None)
        rule = _get(man, "stream_rule")
        if rule not in RULES:
            raise ValueError(f"manifest stream_rule must be one of {', '.join(RULES)}, not {rule!r}")
        pwm_entries = _get(man, "pwm")
        periods = {p["period_cycles"] for p in pwm_entries}
        if len(periods) != 1:
            raise ValueError(f"manifest pwm entries must share one period_cycles, not {sorted(periods)}")
        ps = man.get("period_start")
        pwm = {((p["leg"], p["servo"]) if ps is not None else p["servo"]): p["port"] for p in pwm_entries}
        return cls(module=_get(man, "module"),
                   inputs=tuple(f for f in ins if f is not leg_in),
                   outputs=tuple(f for f in outs if f is not leg_out),
                   leg_in=leg_in if leg_in is not None and leg_in.width > 0 else None,
                   leg_out=leg_out if leg_out is not None and leg_out.width > 0 else None,
                   legs=_positive_int("manifest legs", _get(man, "legs")),
                   latency=_positive_int("manifest latency_cycles", _get(man, "latency_cycles")),
                   initiation_interval=_positive_int("manifest initiation_interval", _get(man, "initiation_interval")),
                   period=_positive_int("manifest pwm period_cycles", periods.pop()),
                   stream_rule=rule, pwm=pwm, period_start=None if ps is None else ps["port"],
                   channel_table=man.get("channel_table"))

    @classmethod
    def read(cls, path) -> "Design":
        """The design of the manifest file ``path``."""
        return cls.from_manifest(json.loads(Path(path).read_text()))

    def check_plan(self, plan) -> None:
        """Fail (one line) unless ``plan`` has this design's input and output fields, in order."""
        want = ([f.name for f in self.inputs], self.servos)
        have = ([i.name for i in plan.inputs], [o.name for o in plan.outputs])
        if want != have:
            raise ValueError(f"manifest fields (inputs {want[0]}, outputs {want[1]}) do not match the plan's "
                             f"(inputs {have[0]}, outputs {have[1]})")
