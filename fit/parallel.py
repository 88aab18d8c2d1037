"""Per-servo work on several cores: the fit and the certification of one servo do not depend on
another's, so :func:`servo_map` runs them in forked worker processes when a caller asks for
``jobs`` > 1.

The result does not depend on ``jobs``: each servo's computation is the same function of the
same inputs in either case (``tests/test_parallel.py`` compares the plans byte for byte). The
workers are forked, so they share the parent's robot, samples and plan without pickling them;
only a servo's index goes out and its result (or its exception) comes back. A worker's progress
messages reach the caller's ``progress`` as they are made, through a queue the parent drains
while it waits. Where the platform cannot fork, the servos run one after another.
"""
from __future__ import annotations

import multiprocessing
import os
import pickle
from concurrent.futures import ProcessPoolExecutor, wait

__all__ = ["check_jobs", "usable_cores", "servo_map"]

#: seconds between the parent's looks at the progress queue while workers run
_POLL_S = 0.1


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:     # not on Linux
        return os.cpu_count() or 1


def check_jobs(jobs) -> int:
    """``jobs`` if it is a positive integer, else ValueError naming it."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer (worker processes), not {jobs!r}")
    return jobs


class _Failed:
    """An exception raised in a worker, sent back as itself if it pickles, else as its text."""

    def __init__(self, exc: BaseException):
        try:
            pickle.loads(pickle.dumps(exc))
            self.exc, self.text = exc, None
        except Exception:          # an exception class whose arguments do not round-trip
            self.exc, self.text = None, f"{type(exc).__name__}: {exc}"

    def reraise(self):
        if self.exc is not None:
            raise self.exc
        raise RuntimeError(self.text)


# the work of the current servo_map, inherited by the forked workers
_WORK: dict = {}


def _run(k):
    fn, q = _WORK["fn"], _WORK["queue"]
    try:
        return fn(k, q.put)
    except BaseException as e:     # KeyboardInterrupt too: the parent decides
        return _Failed(e)


def servo_map(fn, items, jobs: int, progress) -> list:
    """``[fn(k, progress) for k in items]``, in up to ``jobs`` forked processes.

    ``fn(k, say)`` reports progress through ``say``; its return value must pickle. An exception
    in any call is raised here, the first in ``items`` order (so the same one whatever
    ``jobs``), after every worker has stopped; so is an interrupt of the parent, after the
    workers are killed.
    """
    items = list(items)
    jobs = min(check_jobs(jobs), len(items))
    if jobs <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [fn(k, progress) for k in items]
    ctx = multiprocessing.get_context("fork")
    # a SimpleQueue's put writes to the pipe at once (no feeder thread): every message a
    # worker made is readable by the time its result is
    q = ctx.SimpleQueue()
    _WORK.update(fn=fn, queue=q)
    pool = ProcessPoolExecutor(jobs, mp_context=ctx)
    try:
        futures = [pool.submit(_run, k) for k in items]
        while not all(f.done() for f in futures):
            _drain(q, progress)
            wait(futures, timeout=_POLL_S)
        _drain(q, progress)
        results = [f.result() for f in futures]     # BrokenProcessPool if a worker died
    except BaseException:
        # stop the workers at once (they write nothing): a worker would take a SIGTERM
        # through a handler it inherited, and finish its servo first
        for p in list((getattr(pool, "_processes", None) or {}).values()):
            p.kill()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        _WORK.clear()
    for r in results:
        if isinstance(r, _Failed):
            r.reraise()
    return results


def _drain(q, progress) -> None:
    while not q.empty():
        progress(q.get())
