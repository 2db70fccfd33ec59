"""Output files written whole or not at all: a temporary file in the target's folder,
then ``os.replace``. ``tempfile.mkstemp`` creates its file readable by its owner only
(mode 0600); :func:`publish` gives it the mode an ordinary ``open(path, "w")`` would
(0666 less the process's umask) before the rename, so the user's file is not private
by accident."""

from __future__ import annotations

import os

__all__ = ["new_file_mode", "publish"]


def new_file_mode() -> int:
    """0666 less the process's umask: the mode ``open(path, "w")`` creates a file with."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def publish(tmp: str, path: str) -> None:
    """Give the temporary file ``tmp`` an ordinary file's mode and rename it to ``path`` (atomic on POSIX)."""
    os.chmod(tmp, new_file_mode())
    os.replace(tmp, path)
