"""The C allocator's reuse of freed memory, set by the entry point (never at import).

The fitter's structure search builds and drops monomial columns of its sample pools, arrays
of a few hundred kB to a few MB each, by the thousand. glibc's malloc hands memory freed at the
top of its heap back to the system once more than ``M_TRIM_THRESHOLD`` (128 kB by default)
is free there, and serves larger requests by ``mmap``; every array then starts on fresh pages,
one page fault per 4 kB. A cylinder-leg fit touched about half again its peak memory that way,
the kernel's share of its CPU time a tenth to a sixth. :func:`keep_freed_memory` makes
malloc keep and reuse such memory instead.
"""
from __future__ import annotations

import ctypes
import sys

__all__ = ["keep_freed_memory", "TRIM_THRESHOLD", "MMAP_THRESHOLD"]

#: free memory at the top of the heap kept for reuse (bytes; glibc's ``M_TRIM_THRESHOLD``)
TRIM_THRESHOLD = 256 << 20
#: requests served by ``mmap`` (fresh pages, returned on free) from this size on (bytes;
#: glibc's ``M_MMAP_THRESHOLD``, at most 32 MB on 64-bit systems)
MMAP_THRESHOLD = 32 << 20

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3     # mallopt parameters, glibc <malloc.h>


def keep_freed_memory() -> bool:
    """Make glibc's malloc keep up to :data:`TRIM_THRESHOLD` of freed memory and serve
    requests below :data:`MMAP_THRESHOLD` from its heap; returns whether it took effect.

    The process's memory no longer shrinks after a peak by the amount kept. Does nothing (and
    returns False) where the C library has no ``mallopt`` (not Linux, or not glibc).
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)) and bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD))
