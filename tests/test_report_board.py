"""The board section's servo pulse line (ikseries/report.py) from a board record."""
from ikseries.report import _servo_pulses


def test_servo_pulse_line_names_the_lead_and_widest_pulse_in_cycles_and_us():
    b = {"clock": {"achieved_hz": 12e6}, "servo_pulses": {"lead_cycles": 1026, "max_width_cycles": 238974}}
    line = _servo_pulses(b)[0]
    assert "rises at once, 1,026 cycles (85.5 µs) after the period start" in line
    assert "at most 238,974 cycles (19914.5 µs) wide" in line
    assert _servo_pulses({"clock": {"achieved_hz": 12e6}}) == []      # records before the field
