"""The closest-point case generators (importing nothing else of ``softplan_jax`` and not jax):
each ``make_*_case(rng)`` draws one :class:`Case` (an arm configuration q and a polynomial
curve, lowest degree first) from a NumPy generator, random or constructed (touching, crossing,
parallel, minima on the boundary, long curves, the paper's obstacles of Tables 2-4), the
constructed ones with their answer (``expected``, ``exact``) from the construction, not from
any solver; :func:`build_cases` draws the ~1000 "main" cases of :mod:`.closest_cases`."""

from __future__ import annotations

import dataclasses

import numpy as np

from .oracle_geometry import OPoly, segment_point, segment_point_derivs

__all__ = [
    "N_RANDOM", "Case", "sample_theta", "random_q", "arm_geometry", "unit_perp", "poly_from_local",
    "make_random_case", "make_touch_case", "make_cross_case", "make_parallel_case", "make_boundary_case",
    "make_long_case", "PAPER_OBSTACLES", "paper_configs", "build_cases",
]

N_RANDOM = 470  # generic random cases; other families are added below


@dataclasses.dataclass
class Case:
    kind: str
    q: np.ndarray  # (n, 3)
    coeffs: np.ndarray  # (3, K)
    u_range: tuple
    expected: float | None = None  # known upper bound / value when constructed
    exact: bool = False  # expected is exact

    def ocurve(self):
        return OPoly(self.coeffs, *self.u_range)

    def describe(self):
        return (
            f"kind={self.kind} q=np.array({self.q.tolist()!r}), "
            f"coeffs=np.array({self.coeffs.tolist()!r}), u_range={self.u_range!r}"
        )


def sample_theta(rng):
    r = rng.random()
    if r < 0.12:
        return 0.0
    if r < 0.22:
        return float(rng.choice([1e-12, -1e-12]))
    if r < 0.27:
        return float(rng.choice([1e-8, -1e-6, 1e-4, -1e-4]))
    if r < 0.45:
        return float(rng.uniform(-6.0, -0.3))
    if r < 0.55:
        return float(rng.uniform(4.0, 6.0) * rng.choice([-1, 1]))
    return float(rng.uniform(-3.0, 3.0))


def random_q(rng, n, L_range=(0.3, 2.0)):
    return np.array(
        [[rng.uniform(*L_range), sample_theta(rng), rng.uniform(-np.pi, np.pi)] for _ in range(n)]
    )


def arm_geometry(q, i, s):
    """Point, unit tangent, unit 'outward' normal (away from the arc centre)."""
    F, dF, ddF = segment_point_derivs(q, i, [s])
    p, T = F[0], dF[0] / np.linalg.norm(dF[0])
    if np.linalg.norm(ddF[0]) > 1e-9:
        N = -ddF[0] / np.linalg.norm(ddF[0])  # outward (convex side)
    else:
        N = None
    return p, T, N


def unit_perp(rng, v):
    w = rng.normal(size=3)
    w -= (w @ v) * v
    return w / np.linalg.norm(w)


def poly_from_local(p0, t1, t2, t3, u_star, degree=3):
    """coeffs (3, degree+1) of c(u) = p0 + t1 (u-u*) + t2 (u-u*)^2 + t3 (u-u*)^3,
    the terms above `degree` dropped BEFORE expanding (so c(u*) = p0 always)."""
    P = np.polynomial.polynomial
    coeffs = np.zeros((3, degree + 1))
    for dim in range(3):
        base = np.array([p0[dim]])
        for k, tk in enumerate((t1, t2, t3)[:degree], start=1):
            base = P.polyadd(base, tk[dim] * P.polypow([-u_star, 1.0], k))
        coeffs[dim, : len(base)] = base
    return coeffs


def make_random_case(rng, n=None):
    n = int(rng.integers(1, 5)) if n is None else n
    q = random_q(rng, n)
    degree = int(rng.integers(1, 4))
    i = int(rng.integers(0, n))
    p = segment_point(q, i, rng.uniform())
    centre = p + rng.normal(size=3) * rng.choice([0.05, 0.3, 1.0])
    long = rng.random() < 0.5
    if long:
        a, b = np.sort(rng.uniform(-3, 3, 2))
        if b - a < 1.0:
            a, b = a - 0.5, b + 0.5
        scale = [1.0, rng.choice([0.3, 1.0, 5.0]), rng.choice([0.1, 0.3, 1.0])]
    else:
        mid = rng.uniform(-1, 1)
        half = rng.uniform(0.02, 0.08)
        a, b = mid - half, mid + half
        scale = [1.0, rng.choice([0.3, 1.0, 5.0]), 1.0]
    coeffs = np.zeros((3, degree + 1))
    for k in range(1, degree + 1):
        coeffs[:, k] = rng.normal(size=3) * scale[k - 1]
    umid = 0.5 * (a + b)
    cmid = sum(coeffs[:, k] * umid**k for k in range(1, degree + 1))
    coeffs[:, 0] = centre - cmid
    return Case("random", q, coeffs, (float(a), float(b)))


def make_touch_case(rng, n=None, delta=None):
    """Curve passing delta (1e-6..1e-3) off an arm point, on the convex side.

    For the touched segment alone the distance is exactly delta: the curve's
    offset along the outward normal is delta + a (u-u*)^2 (a >= 0) and the arc
    lies on the other side of its tangent plane.
    """
    n = int(rng.integers(1, 5)) if n is None else n
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    s = float(rng.choice([rng.uniform(0.05, 0.95), 0.0, 1.0], p=[0.8, 0.1, 0.1]))
    p, T, N = arm_geometry(q, i, s)
    nrm = N if N is not None else unit_perp(rng, T)
    delta = float(10 ** rng.uniform(-6, -3)) if delta is None else delta
    t1 = unit_perp(rng, nrm) * rng.uniform(0.5, 2.0)
    t3 = unit_perp(rng, nrm) * rng.uniform(0, 1.0)
    t2 = nrm * rng.uniform(0, 2.0) + unit_perp(rng, nrm) * rng.uniform(0, 1.0)
    degree = int(rng.integers(1, 4))
    u_star = float(rng.uniform(-1, 1))
    where = rng.random()
    if where < 0.6:
        a, b = u_star - rng.uniform(0.05, 1.5), u_star + rng.uniform(0.05, 1.5)
    elif where < 0.8:
        a, b = u_star, u_star + rng.uniform(0.05, 1.5)  # minimum at u0
    else:
        a, b = u_star - rng.uniform(0.05, 1.5), u_star  # minimum at u1
    coeffs = poly_from_local(p + delta * nrm, t1, t2, t3, u_star, degree)
    # with s at an end of the segment the curve may get closer to a
    # neighbouring segment, so the constructed value is an upper bound
    exact = n == 1 and 0 < s < 1
    return Case("touch", q, coeffs, (a, b), expected=delta, exact=exact)


def make_cross_case(rng):
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    s = float(rng.uniform(0.0, 1.0))
    p, T, _ = arm_geometry(q, i, s)
    t1 = rng.normal(size=3)
    t2 = rng.normal(size=3) * rng.uniform(0, 2)
    t3 = rng.normal(size=3) * rng.uniform(0, 0.5)
    degree = int(rng.integers(1, 4))
    u_star = float(rng.uniform(-1, 1))
    a, b = u_star - rng.uniform(0.05, 1.0), u_star + rng.uniform(0.05, 1.0)
    coeffs = poly_from_local(p, t1, t2, t3, u_star, degree)
    return Case("cross", q, coeffs, (a, b), expected=0.0)


def make_parallel_case(rng):
    """A straight line (nearly) parallel to a straight arm segment."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    i = int(rng.integers(0, n))
    q[i, 1] = float(rng.choice([0.0, 1e-12, 0.0]))
    s = float(rng.uniform(0.2, 0.8))
    p, T, _ = arm_geometry(q, i, s)
    nrm = unit_perp(rng, T)
    m = unit_perp(rng, T)
    delta = float(10 ** rng.uniform(-6, -2))
    alpha = float(rng.choice([0.0, 1e-9, 1e-6, 1e-4, 1e-2]))
    direction = np.cos(alpha) * T + np.sin(alpha) * m
    half = rng.uniform(0.05, 1.5) * q[i, 0]
    u_star = float(rng.uniform(-0.5, 0.5))
    coeffs = poly_from_local(p + delta * nrm, direction, 0 * T, 0 * T, u_star, 1)
    shift = rng.uniform(-0.5, 0.5) * half
    return Case("parallel", q, coeffs, (u_star - half + shift, u_star + half + shift), expected=delta)


def make_boundary_case(rng):
    """Minima on the boundary: beyond the tip / below the base / past u ends."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    degree = int(rng.integers(1, 4))
    kind = rng.choice(["tip", "tip_pair", "base_pair", "u_end"])
    d = float(10 ** rng.uniform(-5, -0.5))
    if kind in ("tip", "tip_pair"):
        p, T, _ = arm_geometry(q, n - 1, 1.0)
        if kind == "tip":  # line across the tangent ray beyond the tip
            m = unit_perp(rng, T)
            coeffs = poly_from_local(p + d * T, m, 0.3 * unit_perp(rng, T) * rng.random(), 0 * T, 0.0, degree)
            a, b = -rng.uniform(0.1, 1), rng.uniform(0.1, 1)
        else:  # a curve starting beyond the tip and leaving it: endpoint pair
            e = T + 0.3 * unit_perp(rng, T)
            e /= np.linalg.norm(e)
            coeffs = poly_from_local(p + d * e, e * rng.uniform(0.5, 2), 0.2 * e, 0 * T, 0.0, degree)
            a, b = 0.0, rng.uniform(0.1, 2)
    elif kind == "base_pair":  # below the base, pointing down: (s=0, u=u0)
        e = np.array([0.0, 0.0, -1.0]) + 0.3 * np.append(rng.normal(size=2), 0)
        e /= np.linalg.norm(e)
        coeffs = poly_from_local(d * e, e * rng.uniform(0.5, 2), 0.1 * e, 0 * e, 0.0, degree)
        a, b = 0.0, rng.uniform(0.1, 2)
    else:  # the foot of the perpendicular lies past u1: minimum at u = u1
        i = int(rng.integers(0, n))
        s = float(rng.uniform(0.1, 0.9))
        p, T, N = arm_geometry(q, i, s)
        nrm = N if N is not None else unit_perp(rng, T)
        t1 = unit_perp(rng, nrm)
        coeffs = poly_from_local(p + d * nrm, t1, 0.2 * unit_perp(rng, nrm), 0 * t1, 0.0, degree)
        off = rng.uniform(0.01, 0.3)
        a, b = -off - rng.uniform(0.1, 1), -off
    return Case("boundary_" + str(kind), q, coeffs, (float(a), float(b)))


def make_long_case(rng):
    """Long ranges and large coefficients (Sim2-like X=c, Y=u, Z=5u^2)."""
    n = int(rng.integers(1, 5))
    q = random_q(rng, n)
    X0 = rng.uniform(-1.5, 1.5)
    coeffs = np.array(
        [
            [X0, rng.normal() * 0.2, 0.0, 0.0],
            [rng.normal() * 0.3, 1.0, 0.0, 0.0],
            [rng.uniform(-1, 2), rng.normal() * 0.5, rng.choice([5.0, -5.0, 3.0]), rng.normal()],
        ]
    )
    span = rng.uniform(1, 3)
    return Case("long", q, coeffs[:, : int(rng.integers(3, 5))].copy(), (-span, span))


# The paper's obstacles (Tables 2-4; the tree uses the four legible branches
# plus the trunk X=1, Y=1, Z=u, u in [0, 3], as DESIGN.md prescribes).
PAPER_OBSTACLES = {
    "sim1": (np.array([[1.0, 0.0], [0.0, 1.0], [0.5, -1.0]]), (-2.0, 2.0)),
    "sim2": (np.array([[0.5, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 5.0]]), (-2.0, 2.0)),
    "branch1": (np.array([[1.0, -0.2, 0.0], [1.0, -1.0, 0.0], [2.0, 0.0, -1.0]]), (0.0, 1.0)),
    "branch2": (np.array([[1.0, -0.5, 0.0], [1.0, 1.0, -1.0], [1.7, 0.3, 0.0]]), (0.0, 1.5)),
    "branch3": (np.array([[1.0, 1.0, -1.0], [1.0, -1.0, 0.0], [2.0, -0.1, 0.0]]), (0.0, 1.5)),
    "branch4": (np.array([[1.0, 0.0], [1.0, -1.0], [1.5, 0.1]]), (0.0, 1.5)),
    "trunk": (np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), (0.0, 3.0)),
}


def paper_configs(rng, count):
    out = []
    for k in range(count):
        q = np.array(
            [[rng.uniform(0.7, 1.3), sample_theta(rng), rng.uniform(-np.pi, np.pi)] for _ in range(3)]
        )
        if k == 0:
            q[:, 1] = 0.0  # the straight start
        out.append(q)
    return out


def build_cases():
    rng = np.random.default_rng(20240601)
    out = [make_random_case(rng) for _ in range(N_RANDOM)]
    out += [make_touch_case(rng) for _ in range(150)]
    out += [make_cross_case(rng) for _ in range(80)]
    out += [make_parallel_case(rng) for _ in range(80)]
    out += [make_boundary_case(rng) for _ in range(140)]
    out += [make_long_case(rng) for _ in range(60)]
    return out
