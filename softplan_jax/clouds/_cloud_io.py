"""Point clouds read from files: ``.npy`` arrays, ``.csv`` or ``.xyz`` text, PLY (``.ply``,
ASCII or binary, through ``plyfile``) and PCD (``.pcd``, PCL's format: ASCII, binary or
binary_compressed, :mod:`._pcd`), as a scanner, a depth camera or a LiDAR driver writes them;
:func:`load_cloud` returns the x, y, z of every point as a float64 array, validated as the fits
validate their input."""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..base._validation import check_cloud

__all__ = ["CLOUD_EXTENSIONS", "load_cloud"]

CLOUD_EXTENSIONS = (".npy", ".csv", ".xyz", ".ply", ".pcd")


def load_cloud(path) -> np.ndarray:
    """Read a point cloud from a file: ``.npy`` (an (N, 3) array), ``.csv``
    (comma-separated x, y, z per line; an optional header line), ``.xyz``
    (whitespace-separated x y z per line; in both, lines starting with ``#`` are comments),
    ``.ply`` (the ``vertex`` element's x, y, z properties; other properties and elements,
    such as colours or faces, are read past) or ``.pcd`` (the x, y, z fields). Points whose
    x, y and z are all NaN (an organized cloud's pixels without a measurement, in PLY or
    PCD) are dropped with a warning.

    Args:
      path: file path.

    Returns:
      (N, 3) float64 array (validated as by :func:`fit_curves`).

    Raises:
      ValueError: an unknown extension, a missing or unreadable file, or a malformed one
        (what is wrong, and where).
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
        elif ext == ".ply":
            arr = _without_empty_pixels(_read_ply(path), path)
        elif ext == ".pcd":
            from ._pcd import read_pcd

            arr = _without_empty_pixels(read_pcd(path), path)
        else:
            arr = _read_text_cloud(path, "," if ext == ".csv" else None)
    except OSError as err:
        raise ValueError(f"cannot read point cloud {path}: {err.strerror or err}") from None
    return check_cloud(arr, f"point cloud {path}")


def _read_ply(path: str) -> np.ndarray:
    """The ``vertex`` element's x, y, z of a PLY file (plyfile: ASCII and binary)."""
    try:
        from plyfile import PlyData, PlyParseError
    except ImportError:  # a core dependency; missing only in a broken install
        raise ValueError(f"cannot read {path}: PLY files need the package plyfile (pip install plyfile)") from None
    try:
        ply = PlyData.read(path)
    except PlyParseError as err:
        raise ValueError(f"{path} is not a valid PLY file: {err}") from None
    except (ValueError, EOFError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is not a valid PLY file ({type(err).__name__}: {err})") from None
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise ValueError(f"{path}: the PLY file has no 'vertex' element (its elements: {', '.join(names) or 'none'})")
    vertex = ply["vertex"]
    props = [p.name for p in vertex.properties]
    missing = [c for c in "xyz" if c not in props]
    if missing:
        raise ValueError(f"{path}: the PLY vertex element has no {', '.join(missing)} "
                         f"(its properties: {', '.join(props)})")
    return np.stack([np.asarray(vertex[c], np.float64) for c in "xyz"], axis=1)


def _without_empty_pixels(arr: np.ndarray, path: str) -> np.ndarray:
    """The points but those whose x, y and z are all NaN (warned, with their count)."""
    empty = np.all(np.isnan(arr), axis=1)
    if empty.any():
        warnings.warn(f"{path}: dropped {int(empty.sum())} of {arr.shape[0]} points whose x, y and z are all NaN "
                      "(pixels without a measurement)", UserWarning, stacklevel=3)
        arr = arr[~empty]
    return arr


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
