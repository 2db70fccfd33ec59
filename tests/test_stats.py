"""benchmarks/_stats.py against textbook and hand-computed values."""

from __future__ import annotations

import math

import _stats as stats
import numpy as np
import pytest


@pytest.mark.parametrize(
    "k, n, lo, hi",
    [
        # Newcombe (1998), Stat. Med. 17:857, Table I, method 3 (Wilson score, no continuity correction).
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ],
)
def test_wilson_textbook(k, n, lo, hi):
    got = stats.wilson(k, n)
    assert got == pytest.approx((lo, hi), abs=6e-5)


def test_wilson_by_hand_and_edges():
    # k = 5, n = 10, z = 1.96: (0.5 + 0.19208) / 1.38416 +- 1.96 sqrt(0.025 + 0.009604) / 1.38416
    z = stats.Z95
    mid = (0.5 + z * z / 20) / (1 + z * z / 10)
    half = z * math.sqrt(0.025 + z * z / 400) / (1 + z * z / 10)
    assert stats.wilson(5, 10) == pytest.approx((mid - half, mid + half), rel=1e-12)
    assert stats.wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert stats.wilson(10, 10)[1] == pytest.approx(1.0) and stats.wilson(0, 10)[0] == pytest.approx(0.0)
    assert all(math.isnan(x) for x in stats.wilson(0, 0))
    assert stats.fmt_rate(5, 10) == "5 (50.0 % [23.7, 76.3])"


def test_mcnemar_exact_by_hand():
    # b = 1, c = 9: 2 (C(10,0) + C(10,1)) / 2^10 = 22 / 1024
    assert stats.mcnemar_exact(1, 9) == pytest.approx(22 / 1024, rel=1e-15)
    assert stats.mcnemar_exact(9, 1) == stats.mcnemar_exact(1, 9)
    assert stats.mcnemar_exact(0, 5) == pytest.approx(2 / 32)
    assert stats.mcnemar_exact(3, 3) == 1.0 and stats.mcnemar_exact(0, 0) == 1.0
    # Against the exact binomial test two-sided p-value of scipy.
    scipy_stats = pytest.importorskip("scipy.stats")
    for b, c in [(2, 11), (7, 20), (30, 12)]:
        assert stats.mcnemar_exact(b, c) == pytest.approx(scipy_stats.binomtest(b, b + c, 0.5).pvalue, rel=1e-12)


def test_paired_table_and_bootstrap():
    x = np.array([1, 1, 0, 0, 1, 0], bool)
    y = np.array([1, 0, 1, 0, 0, 0], bool)
    t = stats.paired_table(x, y)
    assert (t["both"], t["only_x"], t["only_y"], t["neither"]) == (1, 2, 1, 2)
    assert t["mcnemar_p"] == pytest.approx(1.0)
    d, lo, hi = stats.paired_bootstrap(x, y, n_boot=2000)
    assert d == pytest.approx(1 / 6) and lo <= d <= hi
    same = stats.paired_bootstrap(x, x, n_boot=200)
    assert same == (0.0, 0.0, 0.0)
