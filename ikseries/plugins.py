"""Registered implementations: the entry points of a group (``pyproject.toml``) by name.

Architectures (``ikseries.architectures``) and geometries (``ikseries.geometries``) are found
through their entry-point groups; :func:`registered` lists a group and :func:`load_registered`
loads one by name, with the project's one-line message for an unknown name.
"""
from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points

__all__ = ["registered", "load_registered"]


def registered(group: str) -> dict[str, EntryPoint]:
    """The entry points of ``group`` by name, sorted by name."""
    eps = {ep.name: ep for ep in entry_points(group=group)}
    return {name: eps[name] for name in sorted(eps)}


def load_registered(group: str, name, what: str):
    """The object registered in ``group`` as ``name``.

    Parameters
    ----------
    group : str
        Entry-point group, e.g. ``"ikseries.architectures"``.
    name
        The registered name asked for (any value: a non-string is not registered).
    what : str
        What ``name`` is, for the message (``"geometry.type"``).

    Raises
    ------
    ValueError
        ``name`` is not registered: ``"<what> must be one of <names>, not <name>"``.
    """
    eps = registered(group)
    if not eps:
        raise ValueError(f"{what} must name an entry point of group {group} (none is installed), not {name!r}")
    if not isinstance(name, str) or name not in eps:
        raise ValueError(f"{what} must be one of {', '.join(eps)}, not {name!r}")
    return eps[name].load()
