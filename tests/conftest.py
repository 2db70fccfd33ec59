"""pytest configuration: float64 everywhere (strict dtype promotion on request).

x64 must be switched on before any array is created, i.e. at import time of
this conftest (pytest imports it before the test modules).
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

jax.config.update("jax_enable_x64", True)
# Strict promotion makes any silent float32/float64 (or int/float) mixing
# an error.  It is OFF by default because the library does not survive it
# yet: fit_polynomial_curve computes `u[:, None] ** jnp.arange(degree + 1)`
# (float64 ** int64), a TypePromotionError under "strict".  Everything else
# in these tests passes under strict; run with SOFTPLAN_TEST_STRICT=1 to check.
if os.environ.get("SOFTPLAN_TEST_STRICT", "0") == "1":
    jax.config.update("jax_numpy_dtype_promotion", "strict")

# make `import oracle` / `import helpers` work regardless of rootdir
sys.path.insert(0, os.path.dirname(__file__))


def pytest_sessionfinish(session, exitstatus):
    """Stop the oracle worker pool that test_closest.py may have started."""
    mod = sys.modules.get("test_closest")
    pool = getattr(mod, "_POOL", None) if mod is not None else None
    if pool is not None:
        pool.shutdown(wait=True, cancel_futures=True)
