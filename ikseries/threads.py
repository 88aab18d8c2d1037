"""Single-threaded BLAS for the fitter, set by the entry point (never at import).

The fitter solves many small, tall least-squares systems. Multi-threaded OpenBLAS spins on
them: measured 12 s single-threaded vs 163 s with two threads on a loaded 2-core machine.
"""
from __future__ import annotations

import os

__all__ = ["THREAD_VARIABLES", "single_threaded_blas"]

#: environment variables that set the thread count of the BLAS / OpenMP libraries numpy uses
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """Set each of :data:`THREAD_VARIABLES` to 1 unless the user chose a value.

    Takes effect only if numpy has not been imported yet in this process (the libraries read
    the variables when they load), so call it first thing in a program's entry point.
    """
    for var in THREAD_VARIABLES:
        os.environ.setdefault(var, "1")
