"""Triangle meshes of the view, built in NumPy on the host: a tube of a given radius along a
polyline (the arm's backbone, an obstacle curve) with rotation-minimizing frames (the double
reflection method of Wang, Juettler, Zheng and Liu, ACM TOG 27(1), 2008), a UV sphere (point
obstacles, the goal) and the line segments of a polyline."""

from __future__ import annotations

import numpy as np

__all__ = ["TUBE_SIDES", "tube_frames", "tube_mesh", "sphere_mesh", "polyline_segments", "merge_meshes"]

TUBE_SIDES = 12  # vertices around a tube's circle


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Rows of ``v`` scaled to length 1; a (near) zero row becomes ``fallback``'s row."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n > 1e-12
    return np.where(ok, v / np.where(ok, n, 1.0), fallback)


def _tangents(points: np.ndarray) -> np.ndarray:
    """(N, 3) unit tangents of a polyline: central differences, one-sided at the ends; a
    repeated point takes its neighbour's tangent (a polyline that does not move at all: +z)."""
    d = np.empty_like(points)
    d[1:-1] = points[2:] - points[:-2]
    d[0] = points[1] - points[0]
    d[-1] = points[-1] - points[-2]
    t = _unit(d, np.full_like(d, np.nan))
    good = np.nonzero(~np.isnan(t[:, 0]))[0]
    if good.size == 0:
        return np.tile([0.0, 0.0, 1.0], (points.shape[0], 1))
    # Each undefined tangent takes the nearest defined one before it (or the first after it).
    idx = np.maximum.accumulate(np.where(~np.isnan(t[:, 0]), np.arange(len(t)), 0))
    idx = np.where(np.arange(len(t)) < good[0], good[0], idx)
    return t[idx]


def tube_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation-minimizing frames along a polyline (the double reflection method, Wang et al.
    2008, Algorithm "double reflection"): the normal is carried from point to point without
    twisting about the tangent.

    Args:
      points: (N, 3) polyline, N >= 2.

    Returns:
      ``(normals, binormals)``, each (N, 3), unit, orthogonal to each other and to the tangent.
    """
    t = _tangents(points)
    n = np.empty_like(points)
    # First normal: the axis least aligned with the first tangent, made orthogonal to it.
    axis = np.eye(3)[np.argmin(np.abs(t[0]))]
    n[0] = _unit((axis - t[0] * (axis @ t[0]))[None], np.array([[1.0, 0.0, 0.0]]))[0]
    for i in range(points.shape[0] - 1):
        v1 = points[i + 1] - points[i]
        c1 = v1 @ v1
        if c1 < 1e-24:  # a repeated point: project the normal on the next tangent plane
            r = n[i] - t[i + 1] * (n[i] @ t[i + 1])
        else:
            r_l = n[i] - (2.0 / c1) * (v1 @ n[i]) * v1  # reflect the normal in the bisecting plane
            t_l = t[i] - (2.0 / c1) * (v1 @ t[i]) * v1  # and the tangent
            v2 = t[i + 1] - t_l
            c2 = v2 @ v2
            r = r_l if c2 < 1e-24 else r_l - (2.0 / c2) * (v2 @ r_l) * v2  # second reflection
        r = r - t[i + 1] * (r @ t[i + 1])  # remove rounding's drift out of the normal plane
        n[i + 1] = _unit(r[None], n[i][None])[0]
    b = np.cross(t, n)
    return n, b


def tube_mesh(points, radius: float, sides: int = TUBE_SIDES, caps: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A closed tube of ``radius`` around a polyline.

    Args:
      points: (N, 3) polyline, N >= 2.
      radius: the tube's radius, > 0.
      sides: vertices around each circle, >= 3.
      caps: close both ends with a fan of triangles.

    Returns:
      ``(vertices (N * sides [+ 2], 3) float32, faces (F, 3) uint32)``, faces wound outwards.

    Raises:
      ValueError: fewer than 2 points, non-finite points, a radius <= 0 or sides < 3.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
        raise ValueError(f"tube_mesh: points must have shape (N, 3) with N >= 2, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("tube_mesh: points contain non-finite values")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"tube_mesh: radius must be a finite number > 0, got {radius}")
    if int(sides) < 3:
        raise ValueError(f"tube_mesh: sides must be >= 3, got {sides}")
    k, N = int(sides), p.shape[0]
    n, b = tube_frames(p)
    a = 2.0 * np.pi * np.arange(k) / k
    ring = np.cos(a)[None, :, None] * n[:, None, :] + np.sin(a)[None, :, None] * b[:, None, :]
    verts = (p[:, None, :] + radius * ring).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(N - 1), np.arange(k), indexing="ij")
    v00, v01 = i * k + j, i * k + (j + 1) % k
    v10, v11 = v00 + k, v01 + k
    # (t, n, b) is right-handed, so a ring runs anticlockwise about the tangent: these face outwards.
    faces = np.concatenate([np.stack([v00, v01, v11], -1).reshape(-1, 3),
                            np.stack([v00, v11, v10], -1).reshape(-1, 3)])
    if caps:
        start, end = N * k, N * k + 1
        verts = np.concatenate([verts, p[:1], p[-1:]])
        j = np.arange(k)
        faces = np.concatenate([faces, np.stack([np.full(k, start), (j + 1) % k, j], -1),
                                np.stack([np.full(k, end), (N - 1) * k + j, (N - 1) * k + (j + 1) % k], -1)])
    return verts.astype(np.float32), faces.astype(np.uint32)


def sphere_mesh(radius: float, rings: int = 8, sides: int = TUBE_SIDES) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere of ``radius`` about the origin: ``(vertices (V, 3) float32, faces (F, 3) uint32)``,
    faces wound outwards; ``rings`` >= 2 bands of latitude, ``sides`` >= 3 of longitude."""
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"sphere_mesh: radius must be a finite number > 0, got {radius}")
    if int(rings) < 2 or int(sides) < 3:
        raise ValueError(f"sphere_mesh: rings >= 2 and sides >= 3, got {rings}, {sides}")
    r, k = int(rings), int(sides)
    polar = np.pi * np.arange(1, r) / r  # the inner circles of latitude
    az = 2.0 * np.pi * np.arange(k) / k
    ring = np.stack([np.sin(polar)[:, None] * np.cos(az), np.sin(polar)[:, None] * np.sin(az),
                     np.cos(polar)[:, None] * np.ones(k)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]]) * radius
    top, bottom = 0, len(verts) - 1
    j = np.arange(k)
    faces = [np.stack([np.full(k, top), 1 + j, 1 + (j + 1) % k], -1)]
    for b in range(r - 2):
        a0, a1 = 1 + b * k + j, 1 + b * k + (j + 1) % k
        faces += [np.stack([a0, a0 + k, a1 + k], -1), np.stack([a0, a1 + k, a1], -1)]
    last = 1 + (r - 2) * k
    faces.append(np.stack([np.full(k, bottom), last + (j + 1) % k, last + j], -1))
    return verts.astype(np.float32), np.concatenate(faces).astype(np.uint32)


def polyline_segments(points) -> np.ndarray:
    """(N - 1, 2, 3) float32 line segments joining consecutive points of an (N, 3) polyline
    (viser's line-segment layout); N < 2 gives none."""
    p = np.asarray(points, np.float32).reshape(-1, 3)
    if p.shape[0] < 2:
        return np.zeros((0, 2, 3), np.float32)
    return np.stack([p[:-1], p[1:]], axis=1)


def merge_meshes(meshes) -> tuple[np.ndarray, np.ndarray]:
    """One mesh of several ``(vertices, faces)`` pairs (the faces' indices shifted)."""
    verts, faces, offset = [], [], 0
    for v, f in meshes:
        verts.append(np.asarray(v, np.float32))
        faces.append(np.asarray(f, np.uint32) + offset)
        offset += len(v)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)
    return np.concatenate(verts), np.concatenate(faces)
