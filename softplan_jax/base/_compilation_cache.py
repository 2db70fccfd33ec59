"""jax's persistent compilation cache for the planner's users, traced rollouts kept on disk, and the
XLA options of the package's programs (not part of the paper's method). ``import softplan_jax``
turns the cache on (:func:`enable_default_cache`; the directory ``$SOFTPLAN_CACHE_DIR/jax``, else
``$XDG_CACHE_HOME/softplan_jax/jax``, default ``~/.cache/softplan_jax/jax``) unless the user gave
jax a directory or opted out (``SOFTPLAN_JAX_NO_CACHE=1`` or ``SOFTPLAN_COMPILATION_CACHE=0`` before
the import, :func:`disable_compilation_cache` before the first plan); :func:`load_or_export` keeps a
traced rollout as a ``jax.export`` artifact keyed by everything its program depends on; and
:func:`compiler_options` gives each kind of program (``"exact"``, ``"samples"``, None) its XLA
options, passed per program (:class:`package_jit`), never through ``XLA_FLAGS`` or jax's global
configuration (``SOFTPLAN_XLA_OPTIONS=0``: XLA's defaults). Docs: "How the planner works inside",
"The compilation cache"."""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile

__all__ = ["compilation_cache_dir", "enable_compilation_cache", "enable_default_cache", "disable_compilation_cache",
           "load_or_export", "package_jit", "compiler_options", "PROGRAM_KINDS"]

# XLA CPU options of the package's programs (docs: Performance, "XLA options"): no YNN fusions for
# every planner program, and XLA's elemental IR emitter for the exact solves' many small kernels.
CPU_COMPILER_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}
CURVE_CPU_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
# XLA's own defaults of two options, named under every program's options so that XLA_FLAGS
# settings of them (the test suite lowers both) do not change the package's programs.
XLA_DEFAULT_OPTIONS = {"xla_backend_optimization_level": 3, "xla_cpu_use_fusion_emitters": True}
# A program compiled to run once (``softplan run``): XLA's lowest optimization level, which
# compiles a rollout in about two thirds of the time and runs its steps about 2.5 times slower
# (docs: Performance, "A first result from an empty cache").
ONE_SHOT_OPTIONS = {"xla_backend_optimization_level": 0}


_OFF = ("0", "false", "no", "off")
# The directory enable_default_cache gave jax (None: it set none), and whether
# disable_compilation_cache was called in this process.
_DEFAULT_DIR: str | None = None
_DISABLED = False


def _turned_off() -> bool:
    return (_DISABLED or os.environ.get("SOFTPLAN_COMPILATION_CACHE", "1").strip().lower() in _OFF
            or os.environ.get("SOFTPLAN_JAX_NO_CACHE", "0").strip().lower() not in ("", *_OFF))


def compilation_cache_dir() -> str | None:
    """The directory softplan_jax uses for compiled programs (None: turned off by
    ``SOFTPLAN_JAX_NO_CACHE=1``, ``SOFTPLAN_COMPILATION_CACHE=0`` or
    :func:`disable_compilation_cache`)."""
    if _turned_off():
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


def enable_default_cache() -> str | None:
    """What ``import softplan_jax`` does: :func:`enable_compilation_cache` unless the
    user turned the cache off (``SOFTPLAN_JAX_NO_CACHE=1``, ``SOFTPLAN_COMPILATION_CACHE=0``,
    ``jax_enable_compilation_cache=False``) or gave jax a directory of their own (kept).
    Returns the directory jax now uses (None: none)."""
    global _DEFAULT_DIR
    import jax

    if jax.config.jax_compilation_cache_dir or _turned_off() or not jax.config.jax_enable_compilation_cache:
        return jax.config.jax_compilation_cache_dir or None
    _DEFAULT_DIR = enable_compilation_cache()
    return _DEFAULT_DIR


def disable_compilation_cache() -> bool:
    """Turn softplan_jax's caches off in this process: the directory that
    ``import softplan_jax`` gave jax (not one the user set) and ``softplan run``'s
    traced programs. Call it before the first plan (jax opens its cache at its
    first compilation). Returns whether jax's cache directory was unset."""
    global _DISABLED, _DEFAULT_DIR
    import jax

    _DISABLED = True
    if _DEFAULT_DIR is None or jax.config.jax_compilation_cache_dir != _DEFAULT_DIR:
        return False
    jax.config.update("jax_compilation_cache_dir", None)
    _DEFAULT_DIR = None
    try:  # a cache jax already opened (a compilation happened): closed, opened again only with a directory
        from jax.experimental.compilation_cache import compilation_cache as jax_cache

        jax_cache.reset_cache()
    except Exception:  # noqa: BLE001 - a jax without it: the setting alone
        pass
    return True


_SOURCE_HASH: str | None = None


@functools.cache
def _known_option(name: str, value) -> bool:
    """Whether this jaxlib's CPU compiler accepts the option (XLA renames and retires
    them): a trivial program compiled with it, once per process."""
    import jax
    import numpy as np

    try:
        jax.jit(lambda x: x + 1, compiler_options={name: value}).lower(np.float32(0)).compile()
    except Exception:
        return False
    return True


def _known_options(options: dict) -> dict:
    """The options of ``options`` this jaxlib's CPU compiler accepts: all of them where a trivial
    program compiles with them together (one compile), else those that compile alone."""
    if _known_together(tuple(options.items())):
        return dict(options)
    return {name: value for name, value in options.items() if _known_option(name, value)}


@functools.cache
def _known_together(items: tuple) -> bool:
    import jax
    import numpy as np

    try:
        jax.jit(lambda x: x + 1, compiler_options=dict(items)).lower(np.float32(0)).compile()
    except Exception:
        return False
    return True


PROGRAM_KINDS = ("exact", "samples", None)


@functools.cache
def compiler_options(kind: str | None = "exact") -> dict | None:
    """The XLA options a package program of this ``kind`` compiles with on the CPU backend:
    :data:`XLA_DEFAULT_OPTIONS` (XLA's defaults, named), then for ``"exact"`` and ``"samples"``
    :data:`CPU_COMPILER_OPTIONS`, and for ``"exact"`` also :data:`CURVE_CPU_COMPILER_OPTIONS`;
    each kept only if this jaxlib knows it. None (XLA's defaults) on other backends, when it
    knows none of them, or with ``SOFTPLAN_XLA_OPTIONS=0``. Decided on the first call, not at
    import (importing does not initialise the backend). ValueError for an unknown kind."""
    import jax

    if kind not in PROGRAM_KINDS:
        raise ValueError(f"kind must be 'exact', 'samples' or None; got {kind!r}")
    if os.environ.get("SOFTPLAN_XLA_OPTIONS", "1") == "0" or jax.default_backend() != "cpu":
        return None
    wanted = {**XLA_DEFAULT_OPTIONS, **(CPU_COMPILER_OPTIONS if kind else {}),
              **(CURVE_CPU_COMPILER_OPTIONS if kind == "exact" else {})}
    return _known_options(wanted) or None


def one_shot_options(kind: str | None = "exact") -> dict | None:
    """:func:`compiler_options` ``(kind)`` for a program compiled to run once: with
    :data:`ONE_SHOT_OPTIONS` where the CPU compiler knows them; on other backends, or with
    ``SOFTPLAN_XLA_OPTIONS=0``, the same as :func:`compiler_options`."""
    base = compiler_options(kind)
    if base is None:
        return None
    return _known_options({**base, **ONE_SHOT_OPTIONS})


class package_jit:
    """``jax.jit(fn, **jit_kwargs)`` with :func:`compiler_options` ``(kind)``: how this package
    jits its programs. Built on the first call (the options depend on the backend, which importing must not start).
    Inside the user's own jit, where jax takes compiler options on top-level jits only, a plain
    jit of ``fn`` (compiled with the enclosing program's options). ``lower`` and ``_cache_size``
    are the top-level jit's (``jitted()``: the jit itself)."""

    def __init__(self, fn, kind: str | None = "exact", **jit_kwargs):
        functools.update_wrapper(self, fn)
        self._fn, self._kind, self._jit_kwargs = fn, kind, jit_kwargs
        self._top = self._nested = None

    def jitted(self):
        """The top-level ``jax.jit`` (with the package's options)."""
        if self._top is None:
            import jax

            self._top = jax.jit(self._fn, compiler_options=compiler_options(self._kind), **self._jit_kwargs)
        return self._top

    def __call__(self, *args, **kwargs):
        try:
            return self.jitted()(*args, **kwargs)
        except ValueError as e:
            if "top-level" not in str(e):
                raise
        if self._nested is None:
            import jax

            self._nested = jax.jit(self._fn, **self._jit_kwargs)
        return self._nested(*args, **kwargs)

    def lower(self, *args, **kwargs):
        return self.jitted().lower(*args, **kwargs)

    def _cache_size(self) -> int:
        return 0 if self._top is None else self._top._cache_size()


def _source_hash() -> str:
    """sha256 of every module of this package (path and bytes), once per process."""
    global _SOURCE_HASH
    if _SOURCE_HASH is None:
        root = os.path.dirname(os.path.abspath(__file__))
        h = hashlib.sha256()
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames.sort()
            for name in sorted(filenames):
                if name.endswith(".py"):
                    path = os.path.join(dirpath, name)
                    h.update(os.path.relpath(path, root).encode())
                    with open(path, "rb") as f:
                        h.update(f.read())
        _SOURCE_HASH = h.hexdigest()
    return _SOURCE_HASH


def _exported_dir() -> str | None:
    directory = compilation_cache_dir()
    return None if directory is None else os.path.join(os.path.dirname(directory), "exported")


def _artifact_key(leaves, key_parts) -> str:
    import jax
    import jaxlib

    parts = [
        _source_hash(),
        jax.__version__,
        getattr(jaxlib, "__version__", ""),
        jax.default_backend(),
        jax.devices()[0].device_kind,
        str(bool(jax.config.jax_enable_x64)),
        os.environ.get("XLA_FLAGS", ""),
        *key_parts,
        ";".join(f"{x.shape}:{x.dtype}" for x in leaves),
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def load_or_export(fn, leaves, key_parts, compiler_options=None):
    """Compile ``fn`` for ``leaves``, tracing it only when no artifact with this key is on disk.

    Args:
      fn: a function of flat arrays returning a tuple of arrays (no pytrees:
        the artifact then needs no pytree registrations).
      leaves: the arrays to compile for (their shapes and dtypes enter the key).
      key_parts: strings naming everything else ``fn``'s program depends on
        (static options, the caller's pytree structure); the package source,
        jax/jaxlib versions, backend, device kind, x64 and XLA_FLAGS are added.
      compiler_options: XLA options to compile the program with (jax's own
        cache keys on them), e.g. :func:`compiler_options`.

    Returns:
      ``(compiled, loaded)``: the compiled program (call it with arrays of the
      same shapes), and whether the traced program came from disk. ``None,
      False`` when the cache is off or an artifact cannot be made (then compile
      ``fn`` the usual way).
    """
    import jax

    directory = _exported_dir()
    if directory is None:
        return None, False
    try:
        from jax import export  # needs the flatbuffers package to (de)serialise

        path = os.path.join(directory, _artifact_key(leaves, key_parts) + ".bin")
        exported, loaded = None, False
        if os.path.exists(path):
            try:
                with open(path, "rb") as f:
                    exported = export.deserialize(bytearray(f.read()))
                loaded = True
            except Exception:  # a damaged or foreign file: trace again and overwrite it
                exported = None
        if exported is None:
            exported = export.export(jax.jit(fn))(*leaves)
            os.makedirs(directory, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=directory, suffix=".tmp")
            with os.fdopen(fd, "wb") as f:
                f.write(exported.serialize())
            os.replace(tmp, path)  # atomic: a concurrent run reads the old file or the new one
        return jax.jit(exported.call, compiler_options=compiler_options).lower(*leaves).compile(), loaded
    except Exception:  # jax.export or flatbuffers missing, a read-only disk, ...
        return None, False
