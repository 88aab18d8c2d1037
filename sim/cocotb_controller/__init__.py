"""cocotb bench of the exported robot controller (:class:`ikseries.hdl.controller.RobotController`)
at its pins, from small pieces. Start it with
:func:`ikseries.sim.controller_runner.run_controller`.

:mod:`~ikseries.sim.cocotb_controller.config`
    the run configuration (no cocotb import);
:mod:`~ikseries.sim.cocotb_controller.uart`
    UART driver on ``rx`` (bytes from :func:`ikseries.host.protocol.encode`) and monitor on
    ``tx`` (answers through :class:`ikseries.host.protocol.Decoder`);
:mod:`~ikseries.sim.cocotb_controller.pwm`
    the PWM monitor: every channel's high time in every period;
:mod:`~ikseries.sim.cocotb_controller.model`
    requests applied to the servo controller's per-period model, leg targets through the
    golden model;
:mod:`~ikseries.sim.cocotb_controller.checker`
    pins against the model period by period, answers against requests;
:mod:`~ikseries.sim.cocotb_controller.stream`
    the fuzz traffic and the receiver model's verdict on it;
:mod:`~ikseries.sim.cocotb_controller.scene`
    target box, trims, the end-of-test checks;
:mod:`~ikseries.sim.cocotb_controller.host`
    reset, requests at a fixed phase of the period, their answers;
:mod:`~ikseries.sim.cocotb_controller.tests`
    the cocotb tests.
"""
