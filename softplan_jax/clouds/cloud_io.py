"""Point clouds read from files: ``.npy`` arrays and ``.csv`` or ``.xyz`` text.

A scan from a depth camera or a LiDAR, saved as an (N, 3) NumPy array, as
comma-separated ``x, y, z`` rows (an optional header line) or as
whitespace-separated ``x y z`` rows; lines starting with ``#`` are comments.
:func:`load_cloud` returns it as a float64 array, validated as the fits
validate their input.
"""

from __future__ import annotations

import os

import numpy as np

from ..base.validation import check_cloud

__all__ = ["CLOUD_EXTENSIONS", "load_cloud"]

CLOUD_EXTENSIONS = (".npy", ".csv", ".xyz")


def load_cloud(path) -> np.ndarray:
    """Read a point cloud from a file: ``.npy`` (an (N, 3) array), ``.csv``
    (comma-separated x, y, z per line; an optional header line) or ``.xyz``
    (whitespace-separated x y z per line). Lines starting with ``#`` are comments.

    Args:
      path: file path.

    Returns:
      (N, 3) float64 array (validated as by :func:`fit_curves`).
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in CLOUD_EXTENSIONS:
        raise ValueError(
            f"cannot read point cloud {path!r}: unknown extension {ext or '(none)'!r}; "
            f"use one of {', '.join(CLOUD_EXTENSIONS)}"
        )
    if not os.path.exists(path):
        raise ValueError(f"point cloud file not found: {path}")
    if os.path.isdir(path):
        raise ValueError(f"point cloud path {path} is a directory")
    try:
        if ext == ".npy":
            try:
                arr = np.load(path, allow_pickle=False)
            except ValueError as err:
                raise ValueError(f"{path} is not a NumPy .npy array file (or holds Python objects): {err}") from None
            if not isinstance(arr, np.ndarray):
                raise ValueError(f"{path} does not hold one array")
        else:
            arr = _read_text_cloud(path, "," if ext == ".csv" else None)
    except OSError as err:
        raise ValueError(f"cannot read point cloud {path}: {err.strerror or err}") from None
    return check_cloud(arr, f"point cloud {path}")


def _read_text_cloud(path: str, delimiter) -> np.ndarray:
    """Rows of numbers from a text file; a first non-numeric line is a header."""
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file (expected numbers x, y, z per line)") from None
    rows = []
    for k, line in enumerate(lines):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = [f.strip() for f in (text.split(delimiter) if delimiter else text.split())]
        try:
            values = [float(f) for f in fields]
        except ValueError:
            if not rows and all(not _is_number(f) for f in fields):
                continue  # a header line
            raise ValueError(f"{path}, line {k + 1}: not numbers: {text[:80]!r}") from None
        if rows and len(values) != len(rows[0]):
            raise ValueError(
                f"{path}, line {k + 1}: {len(values)} values, but earlier lines have {len(rows[0])}"
            )
        rows.append(values)
    if not rows:
        raise ValueError(f"point cloud {path} is empty (no rows of numbers)")
    return np.asarray(rows, dtype=np.float64)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
