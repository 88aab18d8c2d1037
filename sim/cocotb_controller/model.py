"""The controller as the host sees it: request messages applied to the servo controller's
per-period model (:class:`ikseries.sim.servo_model.ServoModel`), leg targets through the
golden model of the plan (:mod:`ikseries.sim.golden`), as :class:`~ikseries.hdl.dispatch.Dispatcher`
documents them."""
from __future__ import annotations

import numpy as np

from ikseries.hdl.controller import pulse_bits
from ikseries.hdl.servo_fields import ChannelField as F
from ikseries.host.protocol import Message
from ikseries.sim import golden
from ikseries.sim.servo_model import ServoModel

__all__ = ["golden_widths", "ControllerModel"]


def golden_widths(plan, target, table=None, leg: int = 0) -> list[int]:
    """The golden model's pulse per servo (plan output order) for a target of port integers,
    saturated to the input ranges as the controller's dispatcher does; with the core's channel
    ``table``, the widths of ``leg``'s channels."""
    ints = {i.name: np.array([min(max(v, i.lo), i.hi)]) for i, v in zip(plan.inputs, target)}
    out = golden.robot_outputs(plan, table, np.array([leg]), ints)
    return [int(out[o.name][0]) for o in plan.outputs]


#: single-channel parameter writes: command -> (field, request field carrying the value)
_WRITES = {"set_trim": (F.TRIM, "trim"), "set_speed": (F.SPEED, "speed"), "set_accel": (F.ACCEL, "accel"),
           "set_home": (F.HOME, "pulse"), "set_failsafe_action": (F.FAILSAFE, "action")}


class ControllerModel:
    """Apply good requests with :meth:`request` between engine passes, run a pass with
    :meth:`period`. Requests the hardware would NACK are not modelled (the bench sends none)."""

    def __init__(self, plan, legs: int, period: int, table=None):
        self.plan, self.servos, self.table = plan, len(plan.outputs), table
        self.servo = ServoModel(legs * self.servos, pulse_bits(plan, period), ik_servos=self.servos)
        self.move_time = 0

    def request(self, msg: Message) -> None:
        assert not msg.nack, msg
        s, f = self.servo, msg.fields
        s.keepalive()          # every request taken restarts the failsafe timeout
        name = msg.command
        if name in _WRITES:
            fld, key = _WRITES[name]
            assert s.write(f["channel"], fld, f[key]), msg
        elif name == "set_limits":
            assert s.write(f["channel"], F.MIN, f["min"]) and s.write(f["channel"], F.MAX, f["max"]), msg
        elif name in ("enable", "relax"):
            for c in range(s.channels):
                if f["channels"] >> c & 1:
                    s.write(c, F.ENABLE, int(name == "enable"))
        elif name == "set_failsafe":
            s.write(0, F.TIMEOUT, f["periods"])
        elif name == "set_move_time":
            self.move_time = f["periods"]
        elif name == "set_pulse":
            s.stage(f["channel"], f["pulse"], self.move_time)
            s.commit()
        elif name in ("move_leg", "move_legs"):
            self._move(f)

    def _move(self, f: dict) -> None:
        if "leg" in f:
            legs, targets = [f["leg"]], [f["target"]]
        else:
            legs = [l for l in range(self.servo.channels // self.servos) if f["legs"] >> l & 1]
            targets = f["targets"]
        for leg, t in zip(legs, targets):
            for j, w in enumerate(golden_widths(self.plan, t, self.table, leg)):
                self.servo.stage(leg * self.servos + j, w, self.move_time)
        self.servo.commit()

    def period(self) -> list[int]:
        """One engine pass; the widths it loads (0: no pulse)."""
        return self.servo.period()[0]
