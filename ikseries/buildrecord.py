"""The record of what ikseries wrote into a build directory (``.ikseries-build.json``).

A build replaces and removes only entries it finds in this record, so files of the user
that happen to share an output's name (``pnr.json``, ``sim.vcd``, a ``sim_models``
directory, ...) are never lost. ``ikseries build`` writes the record last, after moving its
outputs in; ``ikseries report --pnr`` adds ``pnr.json`` to it.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from .atomic import atomic_write

__all__ = ["staging", "RECORD_NAME", "RECORD_FORMAT", "BuildRecordError", "OutputDirError", "check_output_dir", "remove_created", "recorded_files",
           "write_record", "add_to_record"]

RECORD_NAME = ".ikseries-build.json"
RECORD_FORMAT = "ikseries-build-files"


class BuildRecordError(ValueError):
    """A build record that exists but cannot be read as one."""


class OutputDirError(ValueError):
    """An output directory that cannot be created or written."""


def check_output_dir(out_dir) -> Path | None:
    """Fail before any work if ``out_dir`` cannot be created or written (temporary files go
    inside it, so its parent need not be writable).

    Returns
    -------
    Path or None
        The outermost directory that will have to be created (None: ``out_dir`` exists).

    Raises
    ------
    OutputDirError
        Naming the directory and the ancestor that is not a writable directory.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputDirError(f"output directory {str(out_dir)!r} exists and is not a directory")
    anc, missing = out_dir, None
    while not anc.exists():
        anc, missing = anc.parent, anc
    if not anc.is_dir() or not os.access(anc, os.W_OK | os.X_OK):
        raise OutputDirError(f"cannot create or write the output directory {str(out_dir)!r} "
                             f"({str(anc)!r} is not a writable directory)")
    return missing


def remove_created(out_dir, created) -> None:
    """Remove the directories from ``out_dir`` up to ``created`` (as returned by
    :func:`check_output_dir`), as far as they are empty."""
    if created is None:
        return
    d = Path(out_dir)
    while True:
        try:
            d.rmdir()
        except OSError:
            return
        if d == created:
            return
        d = d.parent


def recorded_files(build_dir) -> set[str]:
    """Names (files or directories directly in ``build_dir``) the last ikseries build wrote
    there; empty if there is no record.

    Raises
    ------
    BuildRecordError
        If the record cannot be read or is not a build record.
    """
    path = Path(build_dir) / RECORD_NAME
    if not path.exists():
        return set()
    try:
        rec = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise BuildRecordError(f"{path} must be an ikseries build record, not unreadable ({e})") from None
    files = rec.get("files") if isinstance(rec, dict) and rec.get("format") == RECORD_FORMAT else None
    if not isinstance(files, list) or not all(_plain_name(f) for f in files):
        raise BuildRecordError(f"{path} must be an ikseries build record (format {RECORD_FORMAT!r} with a "
                               f"list of file names), not {str(rec)[:80]!r}")
    return set(files)


def _plain_name(name) -> bool:
    """A single path component: never lets a record name a file outside its directory."""
    return isinstance(name, str) and name not in ("", ".", "..", RECORD_NAME) and "/" not in name \
        and "\\" not in name and "\0" not in name


def write_record(build_dir, names) -> None:
    """Store ``names`` as the files of ``build_dir``'s build (atomically: a temporary file in
    the directory, then renamed over the record)."""
    build_dir = Path(build_dir)
    text = json.dumps({"format": RECORD_FORMAT, "files": sorted(set(names))}, indent=1) + "\n"
    atomic_write(build_dir / RECORD_NAME, text)


def add_to_record(build_dir, *names: str) -> None:
    """Add ``names`` to the record of ``build_dir`` (created if missing)."""
    write_record(build_dir, recorded_files(build_dir) | set(names))


@contextlib.contextmanager
def staging(out_dir: Path, created: Path | None, prefix: str, error: type, what: str):
    """A hidden temporary directory (``prefix``...) inside ``out_dir`` (made with it if need be)
    for a build's files; removed on leaving, and with it the directories the build created
    (``created``, from :func:`check_output_dir`) unless the body completed, so a failure or an
    interrupt leaves nothing behind. An OSError becomes ``error`` naming ``what`` was written."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=out_dir))
    except OSError as e:
        remove_created(out_dir, created)
        raise error(f"cannot create the output directory {str(out_dir)!r}: {e.strerror}") from None
    done = False
    try:
        yield tmp
        done = True
    except OSError as e:
        raise error(f"cannot write the {what} to {str(out_dir)!r}: {e}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            remove_created(out_dir, created)
