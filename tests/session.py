"""Settings of the test session that its subprocesses share.

* The checkout under test: :func:`subprocess_env` puts this repository first on
  ``PYTHONPATH``, so that a benchmark script, a notebook kernel or ``python -m
  softplan_jax.cli`` started by a test imports the same ``softplan_jax`` as the
  tests (not another installed copy).
* jax's persistent compilation cache, below.

Compiled programs are kept on disk between sessions, every program however
small or quick to compile: in ``$SOFTPLAN_CACHE_DIR/jax`` or ``.cache/jax`` at
the repository root (git-ignored). ``JAX_COMPILATION_CACHE_DIR`` overrides the
directory; ``SOFTPLAN_TEST_COMPILATION_CACHE=0`` turns the cache off.
Subprocesses the tests start (benchmark scripts, notebook kernels) get the same
settings from :func:`jax_cache_env`. Importing this module changes nothing.
"""

from __future__ import annotations

import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def compilation_cache_dir() -> str | None:
    """The persistent compilation cache directory of the test session (None: off)."""
    if os.environ.get("SOFTPLAN_TEST_COMPILATION_CACHE", "1") == "0":
        return None
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return os.environ["JAX_COMPILATION_CACHE_DIR"]
    root = os.environ.get("SOFTPLAN_CACHE_DIR") or os.path.join(REPO, ".cache")
    return os.path.join(root, "jax")


def jax_cache_env() -> dict:
    """Environment variables that give a subprocess the same compilation cache."""
    d = compilation_cache_dir()
    if d is None:
        return {}
    return {
        "JAX_COMPILATION_CACHE_DIR": d,
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0",
    }


def subprocess_env(base=None) -> dict:
    """``base`` (default ``os.environ``) with the checkout first on PYTHONPATH and :func:`jax_cache_env`."""
    env = dict(os.environ if base is None else base)
    path = [REPO] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join(path)
    env.update(jax_cache_env())
    return env


def one_device_env() -> dict:
    """:func:`subprocess_env` without a host device count: one CPU device per subprocess
    (the jax.distributed tests' processes)."""
    env = subprocess_env()
    env["XLA_FLAGS"] = " ".join(f for f in env.get("XLA_FLAGS", "").split()
                                if "xla_force_host_platform_device_count" not in f)
    return env


def free_port() -> int:
    """A free TCP port on localhost (a jax.distributed coordinator's)."""
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def enable() -> str | None:
    """Turn the cache on in this process (before the first compilation); returns its directory."""
    import jax

    d = compilation_cache_dir()
    if d is None:
        # The library's own on-disk caches (softplan run's traced rollouts) off as well.
        os.environ.setdefault("SOFTPLAN_COMPILATION_CACHE", "0")
        return None
    # The library's on-disk caches (softplan run keeps traced rollouts in <root>/exported)
    # beside the suite's, never in the user's ~/.cache; subprocesses inherit it.
    os.environ.setdefault("SOFTPLAN_CACHE_DIR", os.path.dirname(d))
    os.makedirs(d, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", d)
    # cache every program: the suite compiles many small ones
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return d
