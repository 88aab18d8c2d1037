"""cocotb bench of the exported leg core (:func:`ikseries.hdl.export.leg_verilog`) and robot core
(:func:`ikseries.hdl.export.robot_verilog`), from small pieces.

Start it with :func:`ikseries.sim.runner.run`, which writes a run configuration JSON and names it
in the one environment variable :data:`~ikseries.sim.cocotb_leg.config.ENV_CONFIG`; the design's
ports, widths, latency, initiation interval, legs, PWM period and stream rule come from its
``manifest.json``. The pieces:

:mod:`~ikseries.sim.cocotb_leg.config`
    the run configuration and the manifest as a :class:`~ikseries.sim.cocotb_leg.config.Design`
    (no cocotb import);
:mod:`~ikseries.sim.cocotb_leg.ports`, :mod:`~ikseries.sim.cocotb_leg.timebase`
    the design's signals (widths checked against the manifest) and the clock / edge arithmetic;
:mod:`~ikseries.sim.cocotb_leg.driver`
    drives targets with a valid/gap pattern and o_ready backpressure;
:mod:`~ikseries.sim.cocotb_leg.monitor`
    samples each cycle and records input and output transfers and stalls with their edges;
:mod:`~ikseries.sim.cocotb_leg.model`
    the golden model of the plan (:mod:`ikseries.sim.golden`) and of the PWM generators;
:mod:`~ikseries.sim.cocotb_leg.scoreboard`
    compares, counts mismatches, checks latency, interval and throughput;
:mod:`~ikseries.sim.cocotb_leg.rules`
    one timing rule per stream rule (what i_ready must be at each edge, when an output may
    arrive); its docstring says how to add a timing rule for a new architecture;
:mod:`~ikseries.sim.cocotb_leg.pwm`
    the PWM test's schedule, targets and waveform comparison;
:mod:`~ikseries.sim.cocotb_leg.bench`
    one test's composition of the pieces, the reset sequence and the streaming loop;
:mod:`~ikseries.sim.cocotb_leg.tests`
    the cocotb test module: ``test_back_to_back``, ``test_backpressure``, ``test_pwm``.

To add a timing rule for a new architecture: name its stream rule in
:func:`ikseries.hdl.export.stream_rule`, subclass
:class:`~ikseries.sim.cocotb_leg.rules.TimingRule` and add it to
:data:`~ikseries.sim.cocotb_leg.rules.RULES` (details in :mod:`ikseries.sim.cocotb_leg.rules`).
"""
