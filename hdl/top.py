"""The top of a bitstream: a board's clock and reset, UART, servo pins and status LED around a design."""
from __future__ import annotations

from amaranth.build import Attrs, Pins, Resource
from amaranth.hdl import Elaboratable, Module, Shape, Signal
from amaranth.lib import io, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..constraints.boards import IO_ATTRIBUTE, Board, BoardError
from ..constraints.pll import ClockPlan
from .clocking import BoardClocking

__all__ = ["SERVO_RESOURCE", "BoardTop", "design_channels", "servo_pin_map"]

#: name of the platform resources the top adds for the servo pins (number = channel)
SERVO_RESOURCE = "ikseries_servo"


def design_channels(design) -> int:
    """The number of servo channels of ``design``: the width of its ``pwm: Out(n)``, after
    checking that its signature also has ``rx: In(1)`` and ``tx: Out(1)``."""
    want = "a wiring.Component whose signature has rx: In(1), tx: Out(1) and pwm: Out(n)"
    if not isinstance(design, wiring.Component):
        raise TypeError(f"design must be {want}, not {design!r}")
    members = design.signature.members
    for name, flow in (("rx", In), ("tx", Out), ("pwm", Out)):
        if name not in members:
            raise TypeError(f"design must be {want}, not one without {name}")
        m = members[name]
        shape = Shape.cast(m.shape) if m.is_port else None
        if shape is None or m.flow != flow or shape.signed or (name != "pwm" and shape.width != 1):
            raise TypeError(f"design must be {want}, not one with {name}: {m!r}")
    return Shape.cast(members["pwm"].shape).width


def servo_pin_map(board: Board, channels: int, servo_pins=None) -> tuple[tuple[str, str, int], ...]:
    """(pin name, package pin, channel) for each of ``channels`` servo channels: the board's
    first pins in its default order, or ``servo_pins`` (names of the board's servo pins, one per
    channel in channel order)."""
    names = board.servo_pin_names
    if servo_pins is None:
        if channels > len(names):
            raise BoardError(f"the design has {channels} servo channels, more than the {len(names)} servo pins "
                             f"of {board.name}")
        chosen = names[:channels]
    else:
        if isinstance(servo_pins, str) or not all(isinstance(p, str) for p in servo_pins):
            raise BoardError(f"servo_pins must be a list of pin names, not {servo_pins!r}")
        chosen = tuple(servo_pins)
        if len(chosen) != channels:
            raise BoardError(f"servo_pins must name {channels} pins (one per pwm channel), not {len(chosen)}")
        seen = set()
        for p in chosen:
            board.package_pin(p)
            if p in seen:
                raise BoardError(f"servo_pins must name each pin once, not {p!r} twice")
            seen.add(p)
    return tuple((p, board.package_pin(p), k) for k, p in enumerate(chosen))


class BoardTop(Elaboratable):
    """A design on a board, for ``platform.build``.

    The design's ``rx`` and ``tx`` are connected to the board's UART pins and its ``pwm``
    channels to servo pins; the board's LED blinks at 1 Hz (on 0.5 s, off 0.5 s) from the core
    clock while the design runs and stays dark in reset, so a user sees the bitstream runs.

    Parameters
    ----------
    board : Board
    design : wiring.Component
        Signature with ``rx: In(1)`` (from the host), ``tx: Out(1)`` and ``pwm: Out(n)``; clocked
        by ``sync``. Its ``tx`` should reset to 1 (``Out(1, init=1)``), the line's idle level: the
        top shows it on the pin from the first cycle out of reset.
    clock_plan : ClockPlan
        How the board makes the core clock (:func:`ikseries.constraints.pll.clock_plan`).
    servo_pins : list of str, optional
        Names of the board's servo pins for channels 0 .. n-1; default: its first n in the
        board's default order.

    Attributes
    ----------
    pin_map : dict
        Servo pin name -> channel.
    pins : tuple of (str, str, int)
        (pin name, package pin, channel) of every servo channel.

    Latency
    -------
    ``rx`` reaches the design through a two-stage synchroniser (2 cycles); ``tx`` and every
    ``pwm`` bit are registered once more before the pins (1 cycle).

    Throughput
    ----------
    Every pin is sampled or driven every core clock cycle.

    Reset state: ``tx`` high (the UART line's idle level), every servo pin low, LED dark, until
    the core clock's reset is released (:class:`ikseries.hdl.clocking.BoardClocking`).
    """

    def __init__(self, board: Board, design, clock_plan: ClockPlan, servo_pins=None):
        if not isinstance(board, Board):
            raise TypeError(f"board must be a Board, not {board!r}")
        channels = design_channels(design)
        self.pins = servo_pin_map(board, channels, servo_pins)
        self.clocking = BoardClocking(board, clock_plan)
        self.board, self.design, self.clock_plan = board, design, clock_plan
        self.pin_map = {name: k for name, _, k in self.pins}

    def pin_record(self) -> list[dict]:
        """The servo pins as JSON rows (pin, package pin, channel)."""
        return [{"pin": n, "package_pin": p, "channel": k} for n, p, k in self.pins]

    def _heartbeat(self, m, led):
        half = max(1, round(self.clock_plan.achieved_hz / 2))
        count = Signal(range(half))
        lit = Signal()
        with m.If(count == half - 1):
            m.d.sync += [count.eq(0), lit.eq(~lit)]
        with m.Else():
            m.d.sync += count.eq(count + 1)
        m.d.comb += led.eq(lit)

    def elaborate(self, platform):
        board = self.board
        if (platform.device, platform.package) != (board.device, board.package):
            raise ValueError(f"platform must be for {board.device} {board.package} ({board.name}), "
                             f"not {platform.device} {platform.package}")
        m = Module()
        m.domains.sync = self.clocking.domain
        m.submodules.clocking = self.clocking
        m.submodules.design = design = self.design
        attrs = Attrs(**{IO_ATTRIBUTE[board.family]: board.io_standard})
        platform.add_resources([Resource(SERVO_RESOURCE, k, Pins(pin, dir="o"), attrs) for _, pin, k in self.pins])
        uart = platform.request(*board.resource("uart"), dir="-")
        m.submodules.rx_buffer = rx = io.Buffer("i", uart.rx)
        m.submodules.rx_sync = FFSynchronizer(rx.i, design.rx, init=1)
        tx = Signal(init=1)
        m.d.sync += tx.eq(design.tx)
        m.d.comb += self._output(m, "tx", uart.tx).eq(tx)
        pwm = Signal.like(design.pwm)
        m.d.sync += pwm.eq(design.pwm)
        for _, _, k in self.pins:
            m.d.comb += self._output(m, f"servo{k}", platform.request(SERVO_RESOURCE, k, dir="-")).eq(pwm[k])
        self._heartbeat(m, self._output(m, "led", platform.request(*board.resource("led"), dir="-")))
        return m

    @staticmethod
    def _output(m, name, port):
        """The ``o`` of a plain output buffer on ``port`` (the registers are in the fabric, with
        the domain's reset value)."""
        m.submodules[f"{name}_buffer"] = buf = io.Buffer("o", port)
        return buf.o
