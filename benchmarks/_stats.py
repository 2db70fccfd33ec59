"""Statistics shared by the benchmark scripts (NumPy and the standard library
only; no jax): Wilson intervals of rates, McNemar's exact test of paired
outcomes, and a paired bootstrap of a difference of rates.
"""

from __future__ import annotations

import math

import numpy as np

Z95 = 1.959963984540054  # the 97.5 % quantile of the standard normal


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """95 % Wilson score interval of a rate k / n (Wilson 1927):
    ``(p + z^2/2n +- z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)``."""
    if n == 0:
        return (float("nan"), float("nan"))
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, mid - half), min(1.0, mid + half))


def fmt_rate(k: int, n: int) -> str:
    """``k (p % [lo, hi])`` with the 95 % Wilson interval."""
    lo, hi = wilson(k, n)
    return f"{k} ({100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}])"


def pct_interval(k: int, n: int) -> str:
    """``p % [lo, hi]`` (Wilson 95 %)."""
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value of paired binary outcomes (McNemar 1947):
    ``b`` pairs with outcome (yes, no), ``c`` with (no, yes); under H0 the
    discordant pairs split Binomial(b + c, 1/2):
    ``p = min(1, 2 sum_{i <= min(b, c)} C(b+c, i) / 2^(b+c))``; 1 when b + c = 0."""
    n = int(b) + int(c)
    if n == 0:
        return 1.0
    k = min(int(b), int(c))
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def paired_table(x, y) -> dict:
    """Counts of paired booleans: both, only x, only y, neither; McNemar p."""
    x, y = np.asarray(x, bool), np.asarray(y, bool)
    b, c = int((x & ~y).sum()), int((~x & y).sum())
    return dict(both=int((x & y).sum()), only_x=b, only_y=c, neither=int((~x & ~y).sum()),
                mcnemar_p=mcnemar_exact(b, c))


def paired_bootstrap(x, y, n_boot: int = 10_000, seed: int = 0) -> tuple[float, float, float]:
    """Difference of rates mean(x) - mean(y) of paired booleans, with a 95 %
    percentile interval from resampling the pairs (scenes) with replacement."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    d = x - y
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(d), size=(n_boot, len(d)))
    boots = d[idx].mean(axis=1)
    return float(d.mean()), float(np.percentile(boots, 2.5)), float(np.percentile(boots, 97.5))
