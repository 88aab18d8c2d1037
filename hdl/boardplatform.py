"""An Amaranth build platform for a :class:`~ikseries.constraints.boards.Board`.

A board of amaranth-boards gets a fresh instance of its platform class; a board file gets a
generic subclass of Amaranth's iCE40 (``LatticeICE40Platform``) or ECP5
(``LatticeECP5Platform``) platform whose resources come from the file: ``clk`` (the oscillator,
its frequency as the pin's clock constraint), ``uart`` (``rx``, ``tx``) and ``led``, every pin
with the file's I/O standard. Servo pins are added by the top that uses them
(:class:`ikseries.hdl.top.BoardTop`), so one platform instance serves one build.
"""
from __future__ import annotations

import importlib

from amaranth.build import Attrs, Clock, Pins, PinsN, Resource, Subsignal

from ..constraints.boards import IO_ATTRIBUTE, Board

__all__ = ["board_platform"]


def _file_platform_class(board: Board):
    from amaranth.vendor import LatticeECP5Platform, LatticeICE40Platform
    attrs = {IO_ATTRIBUTE[board.family]: board.io_standard}
    clock_attrs = dict(attrs, GLOBAL=True) if board.family == "ice40" else attrs
    led = (PinsN if board.led_active_low else Pins)(board.led, dir="o")
    resources = [
        Resource("clk", 0, Pins(board.clock_pin, dir="i"), Clock(board.clock_hz), Attrs(**clock_attrs)),
        Resource("uart", 0, Subsignal("rx", Pins(board.uart_rx, dir="i")),
                 Subsignal("tx", Pins(board.uart_tx, dir="o")), Attrs(**attrs)),
        Resource("led", 0, led, Attrs(**attrs)),
    ]
    base = LatticeICE40Platform if board.family == "ice40" else LatticeECP5Platform
    ns = {"device": board.device, "package": board.package, "default_clk": "clk",
          "resources": resources, "connectors": [], "__doc__": f"Board file platform of {board.name}."}
    if board.family == "ecp5":
        ns["speed"] = board.speed
    return type(f"BoardFilePlatform_{board.name.replace('-', '_')}", (base,), ns)


def board_platform(board: Board):
    """A new platform instance for ``board`` (its amaranth-boards class or a board file's)."""
    if not isinstance(board, Board):
        raise TypeError(f"board must be a Board, not {board!r}")
    if board.platform:
        module, _, cls = board.platform.partition(":")
        return getattr(importlib.import_module(module), cls)()
    return _file_platform_class(board)()
