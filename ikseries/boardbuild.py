"""``ikseries build --board``: the robot controller on a board, its Verilog and its bitstream.

Before the fit, :func:`board_spec` checks everything the board decides, each in one line: the
board (a registry name or a board file), the core clock its PLL can make (:func:`clock_plan`;
the fit then uses the clock the PLL achieves, since a pulse in ticks depends on it), the UART
divisor for the baud rate, and one servo pin per channel. After the core step,
:func:`board_build` builds the :class:`~ikseries.hdl.controller.RobotController` (host link,
dispatcher, one shared IK core, servo controller), exports its Verilog (the design ``ikseries
serve`` simulates) and runs the bitstream flow (:func:`ikseries.bitstream.build_bitstream`) into
the build's ``bitstream/`` directory.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from fractions import Fraction

from amaranth.back import verilog

from .bitstream import BitstreamError, BitstreamResult, build_bitstream
from .channels import channel_table
from .constraints.boards import Board, BoardError, board
from .constraints.pll import ClockPlan, ClockPlanError, clock_plan
from .hdl.controller import RobotController
from .hdl.top import servo_pin_map
from .hdl.uart import uart_divisor
from .pnr import DoesNotFitError
from .robot import with_hardware

__all__ = ["DEFAULT_BAUD", "BoardSpec", "BoardBuild", "BoardBuildError", "board_spec", "board_build",
           "BITSTREAM_DIR", "controller_module"]

#: the host link's default rate (bits per second)
DEFAULT_BAUD = 1_000_000
#: the build directory's entry holding the bitstream and nextpnr's report
BITSTREAM_DIR = "bitstream"


class BoardBuildError(ValueError):
    """A board, clock, baud rate or pin choice the build cannot use; or a failed bitstream."""


def controller_module(module: str) -> str:
    """Verilog module name of the robot controller of core module ``module``."""
    return f"{module}_controller"


@dataclass(frozen=True)
class BoardSpec:
    """The board part of a build, validated before the fit."""
    board: Board
    clock: ClockPlan
    baud: int
    divisor: int
    servo_pins: tuple[str, ...] | None
    pins: tuple[tuple[str, str, int], ...]      # (servo pin, package pin, channel)

    @property
    def clock_hz(self) -> int:
        """The core clock the fit and the hardware use: the PLL's, rounded to a whole Hz."""
        return round(self.clock.achieved_hz)

    def channels(self, robot) -> list[dict]:
        """Per channel: its pin, package pin, leg (index and name) and servo (channel
        ``l * servos + j`` is servo ``j`` of leg ``l``)."""
        n = len(robot.servos)
        names = robot.body.names if robot.body is not None else None
        return [{"channel": k, "pin": pin, "package_pin": pad, "leg": k // n, "servo": robot.servos[k % n],
                 **({"leg_name": names[k // n]} if names is not None else {})}
                for pin, pad, k in self.pins]

    def record(self, robot) -> dict:
        return {"board": self.board.name, "clock": self.clock.record(), "baud": self.baud,
                "uart_divisor": self.divisor, "channels": self.channels(robot)}


def board_spec(robot, name, servo_pins=None, baud=DEFAULT_BAUD) -> BoardSpec:
    """The validated board part of a build of ``robot`` (raises :class:`BoardBuildError`)."""
    try:
        b = board(name)
        plan = clock_plan(b, robot.hardware.clock_hz)
    except (BoardError, ClockPlanError) as e:
        raise BoardBuildError(str(e)) from None
    if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
        raise BoardBuildError(f"baud must be a positive integer (bits per second), not {baud!r}")
    try:
        divisor = uart_divisor(round(plan.achieved_hz), baud)
        pins = servo_pin_map(b, robot.legs * len(robot.servos), servo_pins)
    except (ValueError, BoardError) as e:
        raise BoardBuildError(str(e)) from None
    return BoardSpec(b, plan, baud, divisor, None if servo_pins is None else tuple(servo_pins), tuple(pins))


def robot_on_board(robot, spec: BoardSpec):
    """``robot`` with the clock its board's PLL achieves (the same robot when exact)."""
    if Fraction(spec.clock_hz) == Fraction(robot.hardware.clock_hz):
        return robot
    return with_hardware(robot, clock_hz=spec.clock_hz)


@dataclass(frozen=True)
class BoardBuild:
    """The controller's Verilog, its IK core and its bitstream."""
    spec: BoardSpec
    module: str
    verilog: str
    bitstream: BitstreamResult
    #: the controller's IK core: {"architecture", "legs", "latency_cycles"}
    core: dict
    #: the servo pins' timing: {"lead_cycles": pulses rise this long after a period start,
    #: "max_width_cycles": the widest pulse shown}
    pulses: dict


def board_build(robot, plan, spec: BoardSpec, module: str, manifest_text: str, outdir, progress) -> BoardBuild:
    """Build the robot controller of ``plan`` (identity: the robot's name and the first 8 bytes
    of the SHA-256 of ``manifest_text``), export its Verilog as ``controller_module(module)`` and
    build its bitstream into ``outdir / BITSTREAM_DIR``."""
    digest = hashlib.sha256(manifest_text.encode()).digest()[:8]
    try:
        ctl = RobotController(plan, robot.legs, robot.hardware.pwm_period_ticks, spec.clock_hz, spec.baud,
                              name=robot.name, manifest=digest, channels=channel_table(robot))
    except ValueError as e:
        raise BoardBuildError(f"robot controller: {e}") from None
    core = {"architecture": "shared", "legs": robot.legs, "latency_cycles": ctl.core.latency}
    progress(f"exporting the robot controller ({ctl.shape.channels} channels, host link at {spec.baud:,} baud; IK core: "
             f"the folded evaluator shared by the legs, {ctl.core.latency} cycles a leg, since requests arrive at "
             "the line rate)")
    name = controller_module(module)
    text = verilog.convert(ctl, name=name, emit_src=False)
    progress(f"building the {spec.board.name} bitstream: {spec.clock.describe()}")
    try:
        bits = build_bitstream(spec.board, ctl, spec.clock, spec.servo_pins, outdir / BITSTREAM_DIR, name=module)
    except (BitstreamError, DoesNotFitError) as e:
        raise BoardBuildError(str(e)) from None
    progress(f"bitstream {bits.path.name}: Fmax {bits.fmax_mhz:g} MHz against {spec.clock_hz / 1e6:g} MHz"
             f" (nextpnr seed {bits.seed})")
    pulses = {"lead_cycles": ctl.servo.lead, "max_width_cycles": ctl.servo.max_width}
    return BoardBuild(spec, name, text, bits, core, pulses)
