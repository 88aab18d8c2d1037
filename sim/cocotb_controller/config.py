"""What a cocotb run of the controller bench is told (no cocotb import, so the runner can write it).

The runner (:func:`ikseries.sim.controller_runner.run_controller`) exports a
:class:`~ikseries.hdl.controller.RobotController`, writes a :class:`ControllerConfig` JSON with
what the bench cannot read off the pins (the plan, the shape, the divisor, the identity) and
names it in the same one environment variable as the leg bench,
:data:`~ikseries.sim.cocotb_leg.config.ENV_CONFIG`.
"""
from __future__ import annotations

import dataclasses

from ..cocotb_leg.config import ConfigFile

__all__ = ["TESTS", "ControllerConfig"]

#: the cocotb tests of :mod:`ikseries.sim.cocotb_controller.tests`
TESTS = ("test_identity_and_status", "test_move_leg", "test_move_legs", "test_speed_limit",
         "test_timed_move", "test_failsafe", "test_fuzz", "test_link_rate")


@dataclasses.dataclass(frozen=True)
class ControllerConfig(ConfigFile):
    """One run of the controller bench.

    Attributes
    ----------
    plan : str
        Path of the plan JSON the controller was built from (the golden model's input).
    legs, period, clock_hz, divisor : int
        The controller's legs, PWM period (cycles), identity clock and UART divisor.
    lead : int
        Cycles from a period start (the servo controller's pass) to the rise of the pulses
        (:attr:`ikseries.hdl.servo.ServoController.lead`).
    name : str
        Robot name of the identity answer.
    manifest : str
        The identity answer's manifest bytes, as hex.
    seed : int
        Seed of the fuzz stream.
    fuzz_bytes : int
        Bytes of mixed traffic the fuzz test sends.
    tests : tuple of str, or None
        The selected tests (None: all).
    """
    plan: str
    legs: int
    period: int
    clock_hz: int
    divisor: int
    name: str
    manifest: str
    lead: int
    seed: int = 1
    fuzz_bytes: int = 300
    tests: tuple[str, ...] | None = None

    RUNNER = "ikseries.sim.controller_runner.run_controller"

    def __post_init__(self):
        for what in ("legs", "period", "clock_hz", "divisor", "lead", "fuzz_bytes"):
            v = getattr(self, what)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{what} must be a positive integer, not {v!r}")
        if self.tests is not None and not set(self.tests) <= set(TESTS):
            raise ValueError(f"tests must be names from {', '.join(TESTS)}, not {self.tests!r}")

    @property
    def manifest_bytes(self) -> bytes:
        return bytes.fromhex(self.manifest)
