"""The ``Architecture`` interface: one way of turning an evaluation plan into a core.

An architecture is an immutable object holding its options, validated when it is made. It
answers, from the plan alone and before any hardware is elaborated:

- :meth:`Architecture.timing`: a :class:`Timing` (latency, initiation interval, the stream rule
  that says how the core's handshake behaves, and the legs that share it);
- :meth:`Architecture.multiplier_units`: the multiplier units it instantiates;
- :meth:`Architecture.cost_model`: what a plan costs it, the model the fitter minimises
  (:mod:`ikseries.fit.cost`);
- :meth:`Architecture.describe` / :meth:`Architecture.record`: what it is, for reports.

and builds on request:

- :meth:`Architecture.evaluator`: the stream component alone (``i`` targets, ``o`` widths);
- :meth:`Architecture.build`: the core a build exports, for a :class:`BuildTarget` (PWM
  period, clock).

Implementations register under the entry-point group ``ikseries.architectures`` (see
``pyproject.toml``); :func:`architecture_class` looks one up by name. Adding an architecture
is one module with a subclass of :class:`Architecture` plus one line in ``pyproject.toml``.

Stream rules (:data:`STREAM_RULES`), what a bench must expect of a core:

``pipelined``
    One target per cycle; the whole pipeline stalls while ``o_valid`` is high and ``o_ready``
    low (``i_ready = o_ready | ~o_valid``). Latency counts cycles of that enable.
``modulo``
    The same global stall; a phase counter advances with the enable and a target enters only
    at phase 0, one every ``initiation_interval`` enabled cycles.
``folded``
    One evaluation in flight: ``i_ready`` is low from an input transfer until its output
    transfers; latency counts clock cycles.
``buffered``
    One target per cycle, the pipeline never stalls: its outputs wait in a FIFO of
    ``latency + 1`` words, and ``i_ready`` is high exactly while fewer targets than that are
    in flight (input transferred, output not yet); latency counts clock cycles.
"""
from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import ClassVar

from ...fit.cost import DEFAULT_COST_MODEL, CostModel
from ...plugins import load_registered, registered

__all__ = ["STREAM_RULES", "ENTRY_POINT_GROUP", "Timing", "BuildTarget", "Architecture", "architecture_names",
           "architecture_class"]

STREAM_RULES = ("pipelined", "modulo", "folded", "buffered")
ENTRY_POINT_GROUP = "ikseries.architectures"


@dataclass(frozen=True)
class Timing:
    """Latency and throughput of a core, known before it is built.

    Attributes
    ----------
    latency : int
        Cycles from an input transfer to the transfer of its outputs while ``o_ready`` is high.
    initiation_interval : int
        Cycles between input transfers while ``o_ready`` stays high.
    stream_rule : str
        One of :data:`STREAM_RULES`.
    legs : int
        Legs whose targets share the core (each leg gets one target in ``legs``).
    """
    latency: int
    initiation_interval: int
    stream_rule: str
    legs: int = 1

    def __post_init__(self):
        if self.stream_rule not in STREAM_RULES:
            raise ValueError(f"stream_rule must be one of {', '.join(STREAM_RULES)}, not {self.stream_rule!r}")

    def targets_per_second(self, clock_hz: float) -> float:
        return clock_hz / self.initiation_interval

    def refresh_hz(self, clock_hz: float) -> float:
        """Times per second every leg can get new widths (targets offered round-robin)."""
        return clock_hz / (self.legs * self.initiation_interval)

    @property
    def latency_counts(self) -> str:
        """What a latency cycle is: "enable" (cycles of the pipeline enable ``~o_valid | o_ready``,
        global-stall cores) or "clock" (clock cycles)."""
        return "clock" if self.stream_rule == "folded" else "enable"


@dataclass(frozen=True)
class BuildTarget:
    """What a build's core drives: the PWM period (clock cycles) at ``clock_hz``."""
    period: int
    clock_hz: float


class Architecture(abc.ABC):
    """One way of evaluating a plan in hardware (see the module docstring)."""

    #: registered name (the entry point's name)
    name: ClassVar[str]
    #: options every architecture answers (None: not an option of this one)
    multipliers: int | None = None   # multiplier units asked for (folded, shared)
    interval: int | None = None      # initiation interval asked for (modulo, iterative CORDIC)
    dsp: str | None = None           # DSP family sizing the products
    legs: int = 1                    # legs sharing the core

    @abc.abstractmethod
    def timing(self, plan) -> Timing:
        """Latency, initiation interval and stream rule of this architecture for ``plan``."""

    @abc.abstractmethod
    def evaluator(self, plan):
        """The stream evaluator alone (``i``, ``o``, ``latency``, ``initiation_interval``)."""

    @abc.abstractmethod
    def build(self, plan, target: BuildTarget):
        """The core a build exports: the evaluator and its PWM generators."""

    @abc.abstractmethod
    def multiplier_units(self, plan) -> int | None:
        """Multiplier units instantiated (None: constant multiplies only)."""

    def cost_model(self) -> CostModel:
        """What a servo's evaluation costs this architecture (:mod:`ikseries.fit.cost`), for the
        fitter to minimise: by default one unit per multiplication."""
        return DEFAULT_COST_MODEL

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports, e.g. ``folded, 2 multipliers (ice40 16x16 DSP)``."""

    def record(self) -> dict:
        """JSON-ready options of this architecture."""
        return {"architecture": self.name, "multipliers": self.multipliers, "dsp": self.dsp, "legs": self.legs,
                "interval": self.interval, "description": self.describe()}

    def __eq__(self, other):
        return type(self) is type(other) and self.record() == other.record()

    def __hash__(self):
        return hash((type(self), tuple(sorted(self.record().items()))))


def architecture_names() -> list[str]:
    """Names of the registered architectures, sorted."""
    return list(registered(ENTRY_POINT_GROUP))


def architecture_class(name: str) -> type[Architecture]:
    """The registered :class:`Architecture` subclass called ``name``."""
    return load_registered(ENTRY_POINT_GROUP, name, "architecture")
