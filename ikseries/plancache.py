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
import tempfile
from pathlib import Path

from . import __version__
from .robot import fit_record, robot_record

__all__ = ["cache_dir", "plan_key", "cached_plan_path", "store_plan"]


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
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.stem[:16]}-", suffix=".tmp", dir=dest.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, dest)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return dest
