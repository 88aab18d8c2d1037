"""ikseries: robot-leg inverse kinematics as fitted integer power series, compiled to FPGA hardware."""
import os as _os

# The fitter solves many small, tall least-squares systems. Multi-threaded OpenBLAS spins
# on them: measured 12 s single-threaded vs 163 s with two threads on a loaded 2-core
# machine. Unless the user chose otherwise, keep BLAS single-threaded (this only takes
# effect if numpy has not been imported yet).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
