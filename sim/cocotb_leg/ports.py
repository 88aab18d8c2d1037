"""The design's signals, found by the names and widths its manifest gives."""
from __future__ import annotations

from .config import Design, Field

__all__ = ["Ports"]


def _port(dut, name: str, width: int | None = None):
    sig = getattr(dut, name, None)
    assert sig is not None, f"the design has no port {name!r}, which its manifest names"
    if width is not None:
        assert len(sig) == width, f"port {name} is {len(sig)} bits wide, the manifest says {width}"
    return sig


class Ports:
    """Handles of every port the bench drives or watches.

    Ports: clk, rst (active-high, synchronous), i_valid/i_ready and the input fields,
    o_valid/o_ready and the output fields, the PWM outputs; the robot top adds i_leg/o_leg
    (when at least one bit wide) and period_start. Every field's width is checked against the
    manifest.

    Parameters
    ----------
    dut : cocotb handle
        The simulated top-level module.
    design : Design
        Its manifest.
    """

    def __init__(self, dut, design: Design):
        self.clk, self.rst = _port(dut, "clk", 1), _port(dut, "rst", 1)
        self.i_valid, self.i_ready = _port(dut, "i_valid", 1), _port(dut, "i_ready", 1)
        self.o_valid, self.o_ready = _port(dut, "o_valid", 1), _port(dut, "o_ready", 1)
        self.inputs = {f.name: _port(dut, f.port, f.width) for f in design.inputs}
        self.outputs = {f.name: _port(dut, f.port, f.width) for f in design.outputs}
        self.i_leg = self._leg(dut, design.leg_in)
        self.o_leg = self._leg(dut, design.leg_out)
        # leg top: {servo: pwm_<servo>}; robot top: {(leg, servo): pwm_l<leg>_<servo>}
        self.pwm = {k: _port(dut, p, 1) for k, p in design.pwm.items()}
        self.period_start = None if design.period_start is None else _port(dut, design.period_start, 1)

    @staticmethod
    def _leg(dut, f: Field | None):
        return None if f is None else _port(dut, f.port, f.width)
