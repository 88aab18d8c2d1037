"""Per-plan memoisation of the schedules: computed once per plan object and options."""
import pytest

from helpers import tiny_plan
from ikseries.fit.plan import Plan
from ikseries.hdl.planmemo import MEMO_SIZE, per_plan


def _counting():
    calls = []

    @per_plan
    def f(plan, k, dsp=None):
        calls.append((id(plan), k, dsp))
        if k < 0:
            raise ValueError(f"k must be >= 0, not {k}")
        return [k, dsp]
    return f, calls


def test_one_computation_per_plan_object_and_options():
    f, calls = _counting()
    plan = tiny_plan(1)
    assert f(plan, 2) is f(plan, 2)
    assert f(plan, 2, dsp=(8, 8)) is f(plan, 2, dsp=(8, 8)) and f(plan, 3) == [3, None]
    twin = Plan.from_json(plan.to_json())     # an equal plan, another object
    assert f(twin, 2) == f(plan, 2) and f(twin, 2) is not f(plan, 2)
    assert len(calls) == 4


def test_unhashable_options_and_errors_are_not_stored():
    f, calls = _counting()
    plan = tiny_plan(1)
    assert f(plan, 1, [8, 8]) == f(plan, 1, [8, 8]) == [1, [8, 8]]
    for _ in range(2):
        with pytest.raises(ValueError, match="^k must be >= 0, not -1$"):
            f(plan, -1)
    assert len(calls) == 4


def test_only_the_most_recent_results_are_kept():
    f, calls = _counting()
    plan = tiny_plan(1)
    first = f(plan, 0)
    for k in range(1, MEMO_SIZE + 1):
        f(plan, k)
    assert f(plan, MEMO_SIZE) is f(plan, MEMO_SIZE)
    assert f(plan, 0) == first and f(plan, 0) is not first    # dropped, computed again
    assert len(calls) == MEMO_SIZE + 2
