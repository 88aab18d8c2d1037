"""Reference re-implementations of five real robots' own IK and servo calibration, ported from
their published sources (docs/robots.md lists every number with its file and line).

One module per robot, each a function of a target in the robot's own frame and units to its
servo commands (us, AX-12 units or PCA9685 counts), in two forms where the source quantises:
``*_firmware`` as the robot computes it, ``*_exact`` the same formulas in float64 (the
reference for comparisons at a fraction of a pulse unit); and each robot's walking box.

- :mod:`.phoenix_code`: the Phoenix code's LegIK (shared by the next two);
- :mod:`.lynxmotion_phoenix`: Lynxmotion Phoenix, SSC-32;
- :mod:`.phantomx`: PhantomX AX Mk2, AX-12;
- :mod:`.freenove`: Freenove Big Hexapod, PCA9685;
- :mod:`.spotmicro`: SpotMicro (mike4192), PCA9685 via i2cpwm_board;
- :mod:`.mearm`: MeArm (York Hackspace library), Arduino Servo.
"""
