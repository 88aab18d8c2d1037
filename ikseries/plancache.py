"""Per-user cache of fitted plans, keyed by the fit-relevant part of a robot description.

``ikseries eval`` without ``--plan`` needs a plan; a fit takes most of a minute, so the first
fit of a robot is stored under ``$XDG_CACHE_HOME/ikseries/plans/<key>.json`` (default
``~/.cache/ikseries/plans``), where ``<key>`` is the SHA-256 of the canonical JSON of
:func:`ikseries.robot.fit_record` and the ikseries version. Descriptions that differ only in
fields the fit does not read (name, architecture, ...) share one entry.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from . import __version__
from .atomic import atomic_write
from .robot import fit_record, robot_record

__all__ = ["PlanLookupError", "cache_dir", "plan_key", "cached_plan_path", "store_plan", "read_plan", "find_plan"]


class PlanLookupError(ValueError):
    """A given plan file that cannot be used, or a fit that fails; the message is one line."""


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/ikseries/plans``, or ``~/.cache/ikseries/plans`` when it is unset or
    not absolute (the XDG base directory rule)."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and os.path.isabs(base) else Path.home() / ".cache"
    return root / "ikseries" / "plans"


def plan_key(robot) -> str:
    """Hex SHA-256 of the robot's fit record and the ikseries version."""
    rec = {"fit": fit_record(robot_record(robot)), "ikseries_version": __version__}
    return hashlib.sha256(json.dumps(rec, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def cached_plan_path(robot) -> Path:
    """Where the cached plan of ``robot`` is (or would be) stored."""
    return cache_dir() / f"{plan_key(robot)}.json"


def store_plan(robot, text: str) -> Path:
    """Write the plan ``text`` of ``robot`` into the cache atomically (a temporary file in the
    cache directory, then renamed), so a concurrent reader never sees half a plan.

    Returns
    -------
    Path
        The cache file.

    Raises
    ------
    OSError
        If the cache directory cannot be created or written.
    """
    dest = cached_plan_path(robot)
    dest.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(dest, text)


def read_plan(robot, path: Path, given: bool):
    """The plan in ``path`` if it was fitted for ``robot``'s fit fields. A ``given`` path
    (``--plan``) that is missing, unreadable, not a plan or for another robot is an error
    (:class:`PlanLookupError`); otherwise such a file is passed over (None)."""
    from .fit.plan import Plan

    def refuse(msg):
        if given:
            raise PlanLookupError(msg)
        return None
    if not path.exists():
        return refuse(f"--plan must be an existing plan file, not {str(path)!r} (it does not exist)")
    if not path.is_file():
        return refuse(f"--plan must be a plan file, not {str(path)!r} (a directory or other non-file)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise ValueError(f"a plan is a JSON object, not a {type(data).__name__}")
        plan = Plan.from_json(data)
        described = plan.meta.get("robot_description") or {}
        same = fit_record(robot_record(robot)) == fit_record(described)
    except OSError as e:
        return refuse(f"cannot read plan file {str(path)!r}: {e.strerror}")
    except (ValueError, KeyError, TypeError, AttributeError, IndexError) as e:   # JSON of another shape
        return refuse(f"{path}: not a valid ikseries plan: {e}")
    if not same:
        return refuse(f"{path} was fitted for a different robot description than {robot.name!r}")
    return plan


def find_plan(robot, given: Path | None, progress, jobs: int = 1):
    """(plan, line saying which plan it is): the ``given`` file, else the robot's build under
    build/, else this cache, else a fit that is then cached."""
    from .architecture import ArchitectureError, cost_model
    from .build import default_output_dir
    from .fit.fitter import FitError, fit_robot
    if given is not None:
        return read_plan(robot, given, True), f"plan: {given}"
    for path, what in ((default_output_dir(robot) / "plan.json", "the build"), (cached_plan_path(robot), "cached")):
        plan = read_plan(robot, path, False)
        if plan is not None:
            return plan, f"plan: {path} ({what})"
    progress(f"no plan for {robot.name} under build/ or in the cache: fitting")
    try:
        plan = fit_robot(robot, progress, cost_model=cost_model(robot), jobs=jobs)[0]
    except (FitError, ArchitectureError) as e:
        raise PlanLookupError(str(e)) from None
    plan.meta["robot_description"] = robot_record(robot)
    try:
        return plan, f"plan: fitted and cached in {store_plan(robot, plan.dumps())}"
    except OSError as e:
        return plan, f"plan: fitted, not cached ({e.strerror}: {e.filename})"
