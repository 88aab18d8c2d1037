"""ikseries: robot-leg inverse kinematics as fitted integer power series, compiled to FPGA hardware."""
__version__ = "0.1.0"
