"""The servos of a fit in several processes (``fit/parallel.py``): same plan, progress, errors,
interrupts."""
from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import time

import pytest

from ikseries.chain.enclose import ChainEnclosureError
from ikseries.cli import main
from ikseries.fit.fitter import fit_robot
from ikseries.fit.parallel import check_jobs, servo_map
from ikseries.robot import load_preset


class _Odd(Exception):
    def __init__(self, a, b):          # does not round-trip through pickle
        super().__init__(f"{a}/{b}")


def _square(k, say):
    say(f"servo {k}")
    return k * k


def test_results_in_order_with_every_message():
    got = []
    assert servo_map(_square, range(5), 3, got.append) == [0, 1, 4, 9, 16]
    assert sorted(got) == [f"servo {k}" for k in range(5)]


def test_one_job_runs_in_this_process():
    pids = servo_map(lambda k, say: os.getpid(), range(3), 1, None)
    assert pids == [os.getpid()] * 3


def test_workers_are_other_processes():
    pids = servo_map(lambda k, say: (time.sleep(0.2), os.getpid())[1], range(2), 2, print)
    assert os.getpid() not in pids


def test_first_failure_in_item_order_is_raised():
    def fn(k, say):
        if k == 1:
            time.sleep(0.3)            # finishes after servo 2's error: the order is the items'
            raise ValueError("servo 1 failed")
        if k == 2:
            raise KeyError("servo 2 failed")
        return k
    with pytest.raises(ValueError, match="servo 1 failed"):
        servo_map(fn, range(3), 3, print)


def test_an_exception_that_does_not_pickle_comes_back_as_its_text():
    def fn(k, say):
        raise _Odd(k, "x")
    with pytest.raises(RuntimeError, match=r"^_Odd: 0/x$"):
        servo_map(fn, range(2), 2, print)


def test_chain_enclosure_error_pickles_with_its_reason():
    e = pickle.loads(pickle.dumps(ChainEnclosureError("over the cell ...: why", "why")))
    assert (str(e), e.reason) == ("over the cell ...: why", "why")


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_jobs_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match=rf"^jobs must be a positive integer \(worker processes\), not {bad!r}$"):
        check_jobs(bad)
    with pytest.raises(ValueError, match="jobs must be a positive integer"):
        fit_robot(load_preset("planar-arm"), jobs=bad)


def test_the_plan_does_not_depend_on_jobs():
    robot = load_preset("planar-arm")
    seen = []
    one, two = fit_robot(robot, jobs=1).plan.dumps(), fit_robot(robot, seen.append, jobs=2).plan.dumps()
    assert one == two
    assert [m for m in seen if m.startswith("fitting ")] and [m for m in seen if "certified <=" in m]


def test_cli_refuses_a_bad_jobs_value_before_fitting(capsys, tmp_path):
    assert main(["build", "--preset", "planar-arm", "-j", "0", "-o", str(tmp_path / "o")]) != 0
    assert "--jobs must be a positive integer (processes for the servos), not '0'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


_HANGING_FIT = """
import os, signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
import ikseries.fit.fitter as fitter
from ikseries.cli import main

def hang(ctx, name, *args):
    # One write of a whole line: a pipe write under PIPE_BUF is atomic, so two workers' lines never interleave.
    os.write(1, b"worker\\n")
    time.sleep(600)
fitter.fit_servo = hang
sys.exit(main(["build", "--preset", "planar-arm", "-q", "--no-synth", "--cocotb", "none", "-j", "2",
               "-o", sys.argv[1]]))
"""


def _workers_of(marker: str) -> list[int]:
    pids = []
    for pid in os.listdir("/proc"):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if marker.encode() in f.read():
                    pids.append(int(pid))
        except (OSError, ValueError):
            pass
    return pids


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc to find the workers")
def test_an_interrupted_parallel_fit_stops_its_workers(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-c", _HANGING_FIT, str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout.readline() == "worker\n"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGINT and err == "ikseries: interrupted\n"
    deadline = time.monotonic() + 10
    while _workers_of(str(out)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _workers_of(str(out))
    assert not out.exists()
