"""The paper's three simulations as data, with the results the paper prints (section 3):
Sim1 (Table 2), Sim2 (Table 3) and the tree (Table 4), three segments of static length 1
(Table 1) from :func:`~softplan_jax.scenarios.default_start`. Table 4 is garbled after its
fourth row (the text speaks of six curved obstacles, five rows are printed, the fifth a stray
``u - u^2`` fragment): the tree uses the four legible branches plus the trunk ``X = 1,
Y = 1, Z = u, u in [0, 3]`` (DESIGN.md)."""

from __future__ import annotations

import numpy as np

from ..base._validation import host_array
from ..geometry._curves import PolynomialCurve
from ._scenario import Scenario, default_start, make_scenario

__all__ = ["PAPER_SCENARIOS", "PAPER_RESULTS", "paper_scenario"]


def _poly(x, y, z, u_range):
    """PolynomialCurve from per-axis coefficient lists (lowest degree first)."""
    K = max(len(x), len(y), len(z))
    coeffs = np.zeros((3, K))
    for row, c in enumerate((x, y, z)):
        coeffs[row, : len(c)] = c
    return PolynomialCurve(coeffs, u_range)


PAPER_SCENARIOS = {
    # Table 2: X = 1, Y = u, Z = 0.5 - u, -2 < u < 2.
    "sim1": dict(goal=[1.1, -0.8, 0.9], curves=[([1.0], [0.0, 1.0], [0.5, -1.0], (-2.0, 2.0))]),
    # Table 3: X = 0.5, Y = u, Z = 5u^2, -2 < u < 2.
    "sim2": dict(goal=[1.0, 1.0, 1.0], curves=[([0.5], [0.0, 1.0], [0.0, 0.0, 5.0], (-2.0, 2.0))]),
    # Table 4, the four legible branches, plus the trunk X = 1, Y = 1, Z = u,
    # u in [0, 3]: the table is garbled after its fourth row (DESIGN.md).
    "tree": dict(
        goal=[1.0, 0.7, 1.45],
        curves=[
            ([1.0, -0.2], [1.0, -1.0], [2.0, 0.0, -1.0], (0.0, 1.0)),
            ([1.0, -0.5], [1.0, 1.0, -1.0], [1.7, 0.3], (0.0, 1.5)),
            ([1.0, 1.0, -1.0], [1.0, -1.0], [2.0, -0.1], (0.0, 1.5)),
            ([1.0], [1.0, -1.0], [1.5, 0.1], (0.0, 1.5)),
            ([1.0], [1.0], [0.0, 1.0], (0.0, 3.0)),
        ],
    ),
}

# The paper's reported results: (iterations to reach goal, average computation
# time in seconds) per obstacle model, Tables 2-4 ("curve" = proposed method).
PAPER_RESULTS = {
    "sim1": {"curve": (60, 0.2914), 1: (24, 0.0053), 10: (24, 0.0690), 50: (24, 0.4254), 100: (66, 1.6679)},
    "sim2": {"curve": (30, 0.2971), 1: (23, 0.0044), 10: (23, 0.0599), 50: (24, 0.2720), 100: (23, 0.5794)},
    # Table 4's numbers are not legible in the source; the text says the curve
    # method is "comparable to the 10-point method" and much faster than 50.
    "tree": {},
}


def paper_scenario(name: str, *, dtype=None, **kwargs) -> Scenario:
    """One of the paper's scenarios: "sim1" (Table 2), "sim2" (Table 3), "tree" (Table 4).

    Three segments of static length 1 (paper Table 1), starting from
    :func:`default_start`. The tree uses the four legible branches of Table 4
    plus the trunk X = 1, Y = 1, Z = u, u in [0, 3] (the table is garbled
    after its fourth row). Extra keyword arguments go to :func:`make_scenario`
    (padding, radii, limits).
    """
    if name not in PAPER_SCENARIOS:
        raise ValueError(f"unknown paper scenario {name!r}; choose one of {sorted(PAPER_SCENARIOS)}")
    spec = PAPER_SCENARIOS[name]
    curves = [_poly(x, y, z, ur) for x, y, z, ur in spec["curves"]]
    q0 = kwargs.pop("q0", None)
    q0 = default_start(dtype=dtype) if q0 is None else q0
    return make_scenario(host_array(spec["goal"], q0.dtype), curves, q0, **kwargs)

