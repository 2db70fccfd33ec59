"""Output files written whole or not at all: a temporary file in the target's folder,
then ``os.replace``. ``tempfile.mkstemp`` creates its file readable by its owner only
(mode 0600); :func:`publish` gives it the mode an ordinary ``open(path, "w")`` would
(0666 less the process's umask) before the rename, so the user's file is not private
by accident."""

from __future__ import annotations

import os
import tempfile

__all__ = ["new_file_mode", "publish", "write_text"]


def new_file_mode() -> int:
    """0666 less the process's umask: the mode ``open(path, "w")`` creates a file with."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def publish(tmp: str, path: str) -> None:
    """Give the temporary file ``tmp`` an ordinary file's mode and rename it to ``path`` (atomic on POSIX)."""
    os.chmod(tmp, new_file_mode())
    os.replace(tmp, path)


def write_text(path, text: str, overwrite: bool = False, suffix: str = "") -> None:
    """Write ``text`` to ``path`` whole (a temporary file in the same folder, then a rename) or
    not at all; an existing file is replaced only with ``overwrite=True``. Every failure (a
    missing folder, a directory, no permission, the file exists) is a ValueError naming ``path``."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise ValueError(f"cannot write {path}: it is a directory")
    if not os.path.isdir(folder):
        raise ValueError(f"cannot write {path}: the folder {folder} does not exist")
    if os.path.exists(path) and not overwrite:
        raise ValueError(f"{path} exists; pass overwrite=True to replace it")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".softplan-", suffix=suffix, dir=folder)
    except OSError as err:
        raise ValueError(f"cannot write {path}: {err.strerror or err}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        publish(tmp, path)
    except BaseException as err:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise ValueError(f"cannot write {path}: {err.strerror or err}") from None
        raise
