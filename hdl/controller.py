"""The robot controller a board top wraps: host link, command dispatcher, IK core, servo
controller, on three kinds of pins (``rx``, ``tx``, ``pwm``)."""
from __future__ import annotations

from amaranth.hdl import Module, Shape
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..fit.plan import Plan
from . import protocol as P
from .dispatch import Dispatcher
from .evaluator import node_shape
from .link import Link
from .servo import ServoController
from .shared import RobotCore
from .uart import uart_divisor

__all__ = ["RobotController", "pulse_bits"]

_S16 = (-(1 << 15), (1 << 15) - 1)
#: a pulse on the wire is a u24
_WIRE_PULSE_BITS = 24


def pulse_bits(plan: Plan, period: int) -> int:
    """Bits of a pulse width, limit, speed, acceleration and home pulse in the servo controller:
    enough for every width the plan yields and for every pulse shorter than the period."""
    widths = [Shape.cast(node_shape(plan.nodes[o.node])) for o in plan.outputs]
    return max([s.width - s.signed for s in widths] + [(period - 1).bit_length()])


def _check(plan, legs, period, clock_hz, name, manifest):
    if not isinstance(plan, Plan):
        raise TypeError(f"plan must be an ikseries Plan, not {plan!r}")
    for inp in plan.inputs:
        if not (_S16[0] <= inp.lo and inp.hi <= _S16[1]):
            raise ValueError(f"plan input {inp.name} must have its range [{inp.lo}, {inp.hi}] within s16 "
                             f"[{_S16[0]}, {_S16[1]}] (a target coordinate is an s16 on the wire)")
    if not isinstance(legs, int) or isinstance(legs, bool) or not 1 <= legs <= 8:
        raise ValueError(f"legs must be an integer in [1, 8], not {legs!r}")
    if not isinstance(period, int) or isinstance(period, bool) or not 2 <= period < 1 << 24:
        raise ValueError(f"period must be an integer in [2, {(1 << 24) - 1}] cycles (a u24 on the wire), not {period!r}")
    if isinstance(clock_hz, bool) or not isinstance(clock_hz, (int, float)) or not 0 < clock_hz < 1 << 32 \
            or clock_hz != int(clock_hz):
        raise ValueError(f"clock_hz must be a whole number of Hz in [1, {(1 << 32) - 1}] (a u32 on the wire), "
                         f"not {clock_hz!r}")
    if not isinstance(name, str) or len(name.encode()) > 32:
        raise ValueError(f"name must be a string of at most 32 UTF-8 bytes, not {name!r}")
    if not isinstance(manifest, (bytes, bytearray)) or len(manifest) != 8:
        raise ValueError(f"manifest must be 8 bytes (the start of the manifest's SHA-256), not {manifest!r}")


class RobotController(wiring.Component):
    """Everything between the host's serial line and the servo pins of one robot.

    The :class:`~ikseries.hdl.link.Link` takes request frames off ``rx``; the
    :class:`~ikseries.hdl.dispatch.Dispatcher` executes each (``docs/protocol.md``) and
    answers on ``tx``; leg targets go through one :class:`~ikseries.hdl.shared.RobotCore`
    (a folded evaluator shared by the legs, also for one leg: requests arrive one at a time
    at the line rate, far slower than any evaluator, so a faster one would only cost
    area); the :class:`~ikseries.hdl.servo.ServoController` drives ``pwm``. The core's own
    PWM bank drives nothing and synthesis removes it.

    Parameters
    ----------
    plan : Plan
        One leg's plan (pulse widths in ticks of ``clock_hz``); its inputs, in order, are a
        target's coordinates; their ranges must fit s16.
    legs : int
        Legs sharing the plan (1 .. 8); leg ``l`` servo ``j`` is channel ``l * servos + j``.
    period : int
        PWM period in clock cycles (``hardware.pwm_period_us`` at ``clock_hz``); at least what
        :class:`~ikseries.hdl.servo.ServoController` needs.
    clock_hz : int
        The clock frequency (the identity answer's ``clock_hz``; sets the UART divisor).
    baud : float
        Line rate; ``clock_hz / baud`` must be a divisor :func:`~ikseries.hdl.uart.uart_divisor`
        accepts.
    name : str
        Robot name of the identity answer (at most 32 UTF-8 bytes).
    manifest : bytes
        The identity answer's 8 manifest-hash bytes.
    multipliers, dsp, channels
        The core's folded evaluator and its channel table (as :class:`~ikseries.hdl.shared.RobotCore`):
        a left leg's mirror and each channel's direction, centre, trim and limits, applied
        before the servo controller's own run-time trim and limits.
    time_bits, home_at_reset
        As :class:`~ikseries.hdl.servo.ServoController`.

    Attributes
    ----------
    rx : In(1)
        Serial input from the host (idle high); asynchronous: synchronised inside.
    tx : Out(1)
        Serial output to the host, registered, high from reset.
    pwm : Out(legs * servos)
        Servo signals, registered, low for a relaxed channel (every channel from reset,
        unless ``home_at_reset``).

    Latency
    -------
    A request is executed from ``link.latency`` cycles after the start edge of its last
    byte, as :class:`~ikseries.hdl.dispatch.Dispatcher` documents; its effect shows at the pins
    in the period after its commit, on the pulses that rise ``servo.lead`` cycles after that
    period's start (:class:`~ikseries.hdl.servo.ServoController`).

    Throughput
    ----------
    The line rate: a request is executed in less time than the next one takes to arrive
    (the dispatcher's bound, measured in ``tests/test_controller.py``); at 1 Mbaud a hexapod's
    42-byte ``move_legs`` is 420 µs on the wire, 2380 full updates a second.
    """

    def __init__(self, plan: Plan, legs: int, period: int, clock_hz: int, baud: float, *,
                 name: str = "", manifest: bytes = bytes(8), multipliers: int = 1, dsp=None,
                 time_bits: int = 16, home_at_reset: list[int] | None = None, channels=None):
        _check(plan, legs, period, clock_hz, name, manifest)
        self._divisor = uart_divisor(clock_hz, baud)
        # the dispatcher's target register holds a leg's target until its widths are taken,
        # which it takes one at a time from the first servo's
        self._core = RobotCore(plan, legs, period, clock_hz, multipliers=multipliers, dsp=dsp, channels=channels,
                               held_input=True, rotate_outputs=True)
        self._w = pulse_bits(plan, period)
        if self._w > _WIRE_PULSE_BITS:
            raise ValueError(f"pulse widths must fit {_WIRE_PULSE_BITS} bits (a u24 on the wire), not {self._w}")
        channels = legs * len(self._core.servos)
        self._shape = P.Shape(legs, len(plan.inputs), channels)
        self._link = Link(self._shape, self._divisor)
        # the dispatcher NACKs every field out of range before it writes: no second check
        self._servo = ServoController(channels, self._w, period, time_bits=time_bits, home_at_reset=home_at_reset,
                                      trusted_writes=True)
        identity = {"version": P.PROTOCOL_VERSION, "clock_hz": int(clock_hz), "pwm_period": period,
                    "legs": legs, "coords": len(plan.inputs), "channels": channels,
                    "manifest": bytes(manifest), "name": name}
        self._dispatcher = Dispatcher(plan, legs, self._core, self._servo, self._link, self._w, identity)
        super().__init__({"rx": In(1, init=1), "tx": Out(1, init=1), "pwm": Out(channels)})

    @property
    def shape(self) -> P.Shape:
        return self._shape

    @property
    def divisor(self) -> int:
        return self._divisor

    @property
    def width_bits(self) -> int:
        return self._w

    @property
    def core(self) -> RobotCore:
        return self._core

    @property
    def servo(self) -> ServoController:
        return self._servo

    @property
    def link(self) -> Link:
        return self._link

    @property
    def dispatcher(self) -> Dispatcher:
        return self._dispatcher

    def elaborate(self, platform):
        m = Module()
        link, core, servo, d = self._link, self._core, self._servo, self._dispatcher
        m.submodules.link, m.submodules.core = link, core
        m.submodules.servo, m.submodules.dispatcher = servo, d
        for name in ("request", "answer", "answer_data"):
            wiring.connect(m, getattr(link, name), getattr(d, name))
        wiring.connect(m, d.ik_i, core.i)
        wiring.connect(m, core.o, d.ik_o)
        m.d.comb += core.rotate.eq(d.ik_rotate)
        for name in ("write", "target", "read"):
            wiring.connect(m, getattr(d, name), getattr(servo, name))
        wiring.connect(m, servo.status, d.status)
        m.d.comb += [link.rx.eq(self.rx), self.tx.eq(link.tx), self.pwm.eq(servo.pwm),
                     link.rd_addr.eq(d.rd_addr), d.rd_data.eq(link.rd_data),
                     link.counter_addr.eq(d.counter_addr), d.counter_data.eq(link.counter_data), link.clamped.eq(d.clamped),
                     link.answer_index.eq(d.answer_index), d.answer_done.eq(link.answer_done),
                     servo.commit.eq(d.commit), servo.keepalive.eq(d.keepalive), servo.status_shift.eq(d.status_shift),
                     d.busy.eq(servo.busy), d.period_start.eq(servo.period_start), d.phase.eq(servo.phase),
                     link.period.eq(servo.period_start)]
        return m
