"""pytest configuration: float64 everywhere, strict dtype promotion,
and jax's persistent compilation cache (``session.py``).

x64 must be switched on before any array is created, i.e. at import time of
this conftest (pytest imports it before the test modules). Tests marked
``slow`` are deselected by default (pyproject.toml); ``pytest -m slow`` runs
them.
"""

import os
import sys

# The oracle calls scipy.optimize thousands of times on tiny problems;
# multi-threaded BLAS only adds overhead there (4x slower measured on 2
# cores).  Must be set before numpy is imported.  XLA does not read it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import jax  # noqa: E402

TESTS = os.path.dirname(os.path.abspath(__file__))

jax.config.update("jax_enable_x64", True)
# Strict promotion: any silent float32/float64 (or int/float) mixing in the
# library is an error under test.  SOFTPLAN_TEST_STRICT=0 turns it off (to
# tell a promotion error from another failure).
if os.environ.get("SOFTPLAN_TEST_STRICT", "1") != "0":
    jax.config.update("jax_numpy_dtype_promotion", "strict")

# `import helpers` / `import session` from tests/; `import oracle` /
# `import closest_cases` (the independent reference and the closest-point case
# corpus, shared with the benchmarks) and the benchmark scripts from benchmarks/.
sys.path.insert(0, os.path.join(os.path.dirname(TESTS), "benchmarks"))
sys.path.insert(0, TESTS)

import session  # noqa: E402

session.enable()
