"""Atomic file writes: a temporary file in the destination's directory, renamed over it, so a
reader or an interrupted run never sees half a file."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write"]


def atomic_write(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically, with the mode a plain ``open`` would
    give it (``mkstemp`` makes 0600); returns the path. Raises OSError."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:24]}-", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
