"""A reader of PCL's point cloud files (``.pcd``, format v0.7 and the v0.5/v0.6 headers it
extends: the PCL documentation's "The PCD (Point Cloud Data) file format"): the header's
FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS and DATA lines, then the points
as ``ascii`` text, ``binary`` little-endian records (one point after another), or
``binary_compressed`` (LZF-compressed columns: every value of one field, then the next
field's), of which :func:`read_pcd` returns the x, y, z columns.
"""

from __future__ import annotations

import struct

import numpy as np

__all__ = ["read_pcd"]

_HEADER_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "<i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
          ("U", 1): "<u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}


def read_pcd(path: str) -> np.ndarray:
    """The x, y, z columns of a PCD file.

    Args:
      path: a ``.pcd`` file with fields x, y and z (other fields, such as rgb or
        intensity, are read past).

    Returns:
      (POINTS, 3) float64 array, in the file's point order (NaN where the file has NaN:
      an organized cloud's invalid pixels).

    Raises:
      ValueError: a malformed header (the line named), no x, y or z field, or data that
        does not match the header.
    """
    with open(path, "rb") as fh:
        raw = fh.read()
    header, offset = _header(raw, path)
    dtype, points = _record_dtype(header, path), header["POINTS"]
    body = raw[offset:]
    if header["DATA"] == "ascii":
        return _ascii(body, dtype, points, path)
    if header["DATA"] == "binary":
        if len(body) < points * dtype.itemsize:
            raise ValueError(f"{path}: DATA binary holds {len(body)} bytes, the header's {points} points need "
                             f"{points * dtype.itemsize}")
        data = np.frombuffer(body, dtype, count=points)
    else:
        data = _compressed(body, dtype, points, path)
    return np.stack([data[c].astype(np.float64) for c in "xyz"], axis=1)


def _header(raw: bytes, path: str):
    """``({key: value}, byte offset of the data)``; ValueError naming a malformed line."""
    header, pos, line_no = {}, 0, 0
    while "DATA" not in header:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise ValueError(f"{path}: not a PCD file, or its header ends before a DATA line")
        line_no += 1
        try:
            line = raw[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise ValueError(f"{path}, line {line_no}: not a PCD header line (not ASCII text)") from None
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _HEADER_KEYS:
            raise ValueError(f"{path}, line {line_no}: unknown PCD header entry {key!r} "
                             f"(expected one of {', '.join(_HEADER_KEYS)})")
        header[key] = values
    return _check_header(header, path), pos


def _check_header(h: dict, path: str) -> dict:
    """The header's entries as numbers and names, checked against each other."""
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "DATA"):
        if key not in h:
            raise ValueError(f"{path}: the PCD header has no {key} line")
    fields, n = h["FIELDS"], len(h["FIELDS"])
    h.setdefault("COUNT", ["1"] * n)
    for key in ("SIZE", "TYPE", "COUNT"):
        if len(h[key]) != n:
            raise ValueError(f"{path}: PCD {key} has {len(h[key])} entries for {n} FIELDS")
    try:
        sizes, counts = [int(v) for v in h["SIZE"]], [int(v) for v in h["COUNT"]]
        width, height = int(h["WIDTH"][0]), int(h["HEIGHT"][0])
        points = int(h["POINTS"][0]) if "POINTS" in h else width * height
    except (ValueError, IndexError):
        raise ValueError(f"{path}: PCD SIZE, COUNT, WIDTH, HEIGHT and POINTS must be integers") from None
    if points != width * height or points < 0:
        raise ValueError(f"{path}: PCD POINTS {points} is not WIDTH x HEIGHT = {width} x {height}")
    data = h["DATA"][0] if h["DATA"] else ""
    if data not in ("ascii", "binary", "binary_compressed"):
        raise ValueError(f"{path}: PCD DATA {data!r} is none of ascii, binary, binary_compressed")
    for c in "xyz":
        if c not in fields:
            raise ValueError(f"{path}: the PCD file has no {c} field (its fields: {' '.join(fields)})")
    return dict(FIELDS=fields, SIZE=sizes, TYPE=h["TYPE"], COUNT=counts, POINTS=points, DATA=data)


def _record_dtype(h: dict, path: str) -> np.dtype:
    """One point's record: a field per FIELDS entry (COUNT values each; "_" fields are padding)."""
    parts = []
    for k, (name, size, kind, count) in enumerate(zip(h["FIELDS"], h["SIZE"], h["TYPE"], h["COUNT"], strict=True)):
        if (kind, size) not in _TYPES:
            raise ValueError(f"{path}: PCD field {name!r} has TYPE {kind} and SIZE {size}, which PCD does not define")
        if name in "xyz" and count != 1:
            raise ValueError(f"{path}: PCD field {name!r} has COUNT {count}; a coordinate is one value")
        parts.append((name if name != "_" else f"_pad{k}", _TYPES[kind, size], (count,) if count != 1 else ()))
    return np.dtype(parts)


def _ascii(body: bytes, dtype: np.dtype, points: int, path: str) -> np.ndarray:
    """DATA ascii: one point per line, its values separated by spaces; the (points, 3) x, y, z."""
    rows = [line.split() for line in body.decode("ascii", errors="replace").splitlines() if line.strip()]
    if len(rows) < points:
        raise ValueError(f"{path}: DATA ascii holds {len(rows)} points, the header says {points}")
    widths = [int(np.prod(dtype[name].shape, dtype=int)) for name in dtype.names]
    starts = np.concatenate([[0], np.cumsum(widths)])
    for i, row in enumerate(rows[:points]):
        if len(row) != starts[-1]:
            raise ValueError(f"{path}: point {i} of DATA ascii has {len(row)} values, the fields need {starts[-1]}")
    cols = [int(starts[dtype.names.index(c)]) for c in "xyz"]
    try:
        return np.asarray([[float(row[k]) for k in cols] for row in rows[:points]], np.float64).reshape(points, 3)
    except ValueError as err:
        raise ValueError(f"{path}: DATA ascii: a coordinate is not a number ({err})") from None


def _compressed(body: bytes, dtype: np.dtype, points: int, path: str) -> np.ndarray:
    """DATA binary_compressed: uint32 compressed and uncompressed sizes, then the LZF-compressed
    columns (every point's value of the first field, then of the second, ...)."""
    if len(body) < 8:
        raise ValueError(f"{path}: DATA binary_compressed ends before its sizes")
    packed, size = struct.unpack("<II", body[:8])
    if size != points * dtype.itemsize:
        raise ValueError(f"{path}: DATA binary_compressed unpacks to {size} bytes, the header's {points} points "
                         f"need {points * dtype.itemsize}")
    flat = _lzf_decompress(body[8 : 8 + packed], size, path)
    out, pos = np.zeros(points, dtype), 0
    for name in dtype.names:
        column = np.dtype((dtype[name].base, dtype[name].shape)) if dtype[name].shape else dtype[name]
        nbytes = points * column.itemsize
        out[name] = np.frombuffer(flat[pos : pos + nbytes], column, count=points)
        pos += nbytes
    return out


def _lzf_decompress(data: bytes, size: int, path: str) -> bytes:
    """LZF (liblzf's format, which PCL writes): a control byte below 32 copies that many + 1
    literal bytes; above, a back reference of length ``(ctrl >> 5) + 2`` (7: plus the next
    byte) at distance ``((ctrl & 31) << 8) + next byte + 1``."""
    out, i, n = bytearray(), 0, len(data)
    try:
        while i < n:
            ctrl = data[i]
            i += 1
            if ctrl < 32:
                out += data[i : i + ctrl + 1]
                i += ctrl + 1
                continue
            length = ctrl >> 5
            if length == 7:
                length += data[i]
                i += 1
            ref = len(out) - ((ctrl & 31) << 8) - data[i] - 1
            i += 1
            if ref < 0:
                raise IndexError
            for k in range(length + 2):  # byte by byte: a reference may overlap what it writes
                out.append(out[ref + k])
    except IndexError:
        raise ValueError(f"{path}: DATA binary_compressed is not valid LZF data") from None
    if len(out) != size:
        raise ValueError(f"{path}: DATA binary_compressed unpacked to {len(out)} bytes, not {size}")
    return bytes(out)
