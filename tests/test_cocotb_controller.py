"""cocotb tests of the exported robot controller at its pins, on Icarus (and on Verilator with --long).

One build per simulator of ``RobotController(small_plan, 2 legs, period 640, 48 MHz, divisor 4)``
runs every test of :mod:`ikseries.sim.cocotb_controller.tests` (identity and status, move_leg,
move_legs, speed limit, timed move, failsafe, a 300-byte seeded fuzz); each checks every PWM
period's widths against the model, one answer per request, and its own property.
"""
from __future__ import annotations

import pytest

from test_cocotb import _skip_unless_available

from ikseries.sim.cocotb_controller.config import TESTS
from ikseries.sim.controller_runner import run_controller

CLOCK, BAUD, PERIOD = 48_000_000, 12e6, 640     # divisor 4; the shortest period for 2 legs of 3 servos


# Verilator's run (a 40 s C++ build) with --long; bench/controller_fuzz.py runs it at length
@pytest.mark.parametrize("simulator", ["icarus", pytest.param("verilator", marks=pytest.mark.long)])
def test_controller_cocotb(simulator, small_plan_file, tmp_path_factory):
    _skip_unless_available(simulator)
    res = run_controller(small_plan_file, 2, PERIOD, CLOCK, BAUD, simulator,
                         tmp_path_factory.mktemp(f"cocotb_controller_{simulator}"), verilator_opt="-O0")
    print(res.summary())
    assert set(res.tests) == set(TESTS), res.summary()
    assert res.ok, res.summary()
