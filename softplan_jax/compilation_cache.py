"""jax's persistent compilation cache for the planner's users (not part of the
paper's method: it keeps compiled rollouts on disk, so the second run of a
script, notebook or ``softplan run`` skips the XLA compilation).

``softplan run`` turns it on by itself; in scripts and notebooks call
:func:`enable_compilation_cache` once, before the first plan. The directory is
``$SOFTPLAN_CACHE_DIR/jax`` if set, else ``$XDG_CACHE_HOME/softplan_jax/jax``
(default ``~/.cache/softplan_jax/jax``). ``SOFTPLAN_COMPILATION_CACHE=0`` turns
it off. A cache directory the user already gave jax (the
``JAX_COMPILATION_CACHE_DIR`` environment variable or
``jax.config.update("jax_compilation_cache_dir", ...)``) is kept as it is.
"""

from __future__ import annotations

import os

__all__ = ["compilation_cache_dir", "enable_compilation_cache"]


def compilation_cache_dir() -> str | None:
    """The directory softplan_jax uses for compiled programs (None: turned off by
    ``SOFTPLAN_COMPILATION_CACHE=0``)."""
    if os.environ.get("SOFTPLAN_COMPILATION_CACHE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    root = os.environ.get("SOFTPLAN_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = os.path.join(xdg, "softplan_jax")
    return os.path.join(root, "jax")


def enable_compilation_cache(directory: str | None = None) -> str | None:
    """Turn on jax's persistent compilation cache (call before the first plan).

    Args:
      directory: where to keep compiled programs; None = :func:`compilation_cache_dir`.

    Returns:
      The cache directory in use, or None when the cache is off
      (``SOFTPLAN_COMPILATION_CACHE=0``, or the directory cannot be created:
      planning then works as usual, compiling every time).

    Only programs that took at least a second to compile are kept (jax's
    default threshold): the rollouts, not the many small helpers.
    """
    import jax

    current = jax.config.jax_compilation_cache_dir
    if current:  # the user's own setting wins
        return current
    directory = directory or compilation_cache_dir()
    if directory is None:
        return None
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", directory)
    return directory
