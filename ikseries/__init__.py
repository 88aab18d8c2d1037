"""ikseries: robot-leg inverse kinematics as fitted integer power series, compiled to FPGA hardware.

Importing the package changes no environment; the ``ikseries`` command sets single-threaded
BLAS itself (:func:`ikseries.threads.single_threaded_blas`).
"""

__version__ = "0.3.0"
