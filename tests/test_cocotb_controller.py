"""cocotb tests of the exported robot controller at its pins, on Icarus (and on Verilator with --long).

One build per simulator of ``RobotController(small_plan, 2 legs, period 820, 48 MHz, divisor 4)``
runs every test of :mod:`ikseries.sim.cocotb_controller.tests` (identity and status, move_leg,
move_legs, speed limit, timed move, failsafe, a 300-byte seeded fuzz); each checks every PWM
period's widths against the model, one answer per request, and its own property.
"""
from __future__ import annotations

import pytest

from test_cocotb import _skip_unless_available

from ikseries.sim.cocotb_controller.config import TESTS
from ikseries.sim.controller_runner import run_controller

# divisor 4; the period: the pass before the pulses (354 cycles for 2 legs of 3 servos) and the
# test box's pulses after their trims (449 cycles)
CLOCK, BAUD, PERIOD = 48_000_000, 12e6, 820


# Verilator's run (a 40 s C++ build) with --long; bench/controller_fuzz.py runs it at length
@pytest.mark.parametrize("simulator", ["icarus", pytest.param("verilator", marks=pytest.mark.long)])
def test_controller_cocotb(simulator, small_plan_file, tmp_path_factory):
    _skip_unless_available(simulator)
    res = run_controller(small_plan_file, 2, PERIOD, CLOCK, BAUD, simulator,
                         tmp_path_factory.mktemp(f"cocotb_controller_{simulator}"), verilator_opt="-O0")
    print(res.summary())
    assert set(res.tests) == set(TESTS), res.summary()
    assert res.ok, res.summary()


@pytest.mark.parametrize("seed", range(8))
def test_fuzz_traffic_counters_are_the_receiver_models_over_the_stream_sent(seed):
    # the counters the fuzz test expects in its final status answer: a fresh receiver model fed
    # exactly the bytes sent (the bad pieces before the resynchronising tail counted once)
    import random

    from ikseries.hdl import protocol as P
    from ikseries.host.protocol import request_parser
    from ikseries.sim.cocotb_controller.scene import HALF, REF
    from ikseries.sim.cocotb_controller.stream import fuzz_traffic

    shape = P.Shape(2, 3, 6)
    box = [(r - h, r + h) for r, h in zip(REF, HALF)]
    traffic = fuzz_traffic(random.Random(seed), shape, 3000, box, [(100, 400)] * shape.channels)
    parser = request_parser(shape)
    parser.feed(b"".join(traffic.segments))
    assert traffic.counters == {k: v for k, v in parser.counters.items() if k != "garbage"}
    assert traffic.nbytes == sum(map(len, traffic.segments))
