"""Pure functions of an evaluation plan computed once per plan object and options.

A build asks for the schedule of its core several times (the architecture's timing, its
multiplier count, then the evaluator it builds); :func:`per_plan` makes those one computation.
Plans are not changed once built but are unhashable dataclasses, so results are keyed by the
plan's identity; each entry keeps its plan referenced (no other object can take its identity
while it is cached), and only the most recent entries are kept, so a long run that makes many
plans holds a bounded number of them.
"""
from __future__ import annotations

import functools
from collections import OrderedDict

__all__ = ["per_plan", "MEMO_SIZE"]

#: (plan, options) results each memoised function keeps, most recently used
MEMO_SIZE = 16


def per_plan(fn):
    """Memoise ``fn(plan, *args, **kwargs)`` per plan object and options.

    ``fn`` must be pure and its result never changed by its callers. Calls whose options are
    unhashable go straight to ``fn`` (which checks its arguments and reports bad ones), as do
    calls whose ``fn`` raises (nothing is stored).
    """
    memo: OrderedDict = OrderedDict()

    @functools.wraps(fn)
    def memoised(plan, *args, **kwargs):
        key = (id(plan), args, tuple(sorted(kwargs.items())))
        try:
            hit = memo.get(key)
        except TypeError:        # unhashable options
            return fn(plan, *args, **kwargs)
        if hit is not None:
            memo.move_to_end(key)
            return hit[1]
        result = fn(plan, *args, **kwargs)
        memo[key] = (plan, result)
        while len(memo) > MEMO_SIZE:
            memo.popitem(last=False)
        return result

    memoised.cache_clear = memo.clear
    return memoised
