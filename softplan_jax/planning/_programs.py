"""The rollout as a pure function and as compiled programs. :func:`rollout` rolls the planner
of paper eq. (9) out on one scene, static or moving (pure: jit, vmap or grad it);
:data:`rollout_jit` (one scene) and :data:`rollout_batch` (a batch, sharded over devices, in
chunks of one shape) are :class:`RolloutProgram` objects, the one way the package runs a
compiled rollout: :func:`~softplan_jax.plan`, :func:`~softplan_jax.track`, the batch entry
points, the fallback and the command line all call them."""

from __future__ import annotations

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import load_or_export, package_jit
from ..base._numerics import shared_constant
from ..base._validation import check_bool, check_int
from ..geometry._arm import PCC
from ._batching import BATCH_AXIS, Progress, batch_mesh, gather, is_global, pad_batch, round_chunk, shard_batch
from ._engine import check_engine_sizes, default_lanes, run, run_lanes
from ._options import PROGRAM_KIND, plan_options, rollout_compiler_options, tracks
from ._records import Rollout, check_rollout_memory

__all__ = ["rollout", "strong_gains", "prng_key", "start_configuration", "batch_keys", "RolloutProgram",
           "rollout_jit", "rollout_batch"]


def rollout(world, gains, options, max_steps: int, key=None, *, driver: str = "scan", arm=PCC) -> Rollout:
    """Roll the planner out for up to ``max_steps`` steps (pure; :func:`softplan_jax.plan` and
    :func:`softplan_jax.track` are the jitted entry points). The loop is
    :func:`softplan_jax.planning._engine.run`; the statuses are
    :class:`~softplan_jax.base._status.Status`'s.

    Args:
      world: a Scenario (with PlanOptions or TrackOptions) or a MovingScenario (TrackOptions).
      gains, max_steps: as :func:`softplan_jax.plan`.
      options: PlanOptions (stop at the goal) or TrackOptions (hold the goal to the horizon).
      key: PRNG key of the escapes' random walks (default ``PRNGKey(0)``).
      driver: "scan" (default: a fixed-length ``lax.scan``, reverse-mode differentiable) or
        "chunks" (stops within ``step_chunk`` steps of the end). The same arrays either way.
      arm: the arm model (:mod:`softplan_jax.geometry._arm`).
    """
    key = jax.random.PRNGKey(0) if key is None else key
    return run(world, gains, options, max_steps, key, driver=driver, step_chunk=plan_options(options).step_chunk,
               arm=arm)


def strong_gains(gains, dtype):
    """Gains as arrays of the scenario's dtype, never weakly typed: a gain given as
    a Python float or ``jnp.asarray(0.1)`` (weak) would otherwise compile anew."""
    return type(gains)(*(v if v is None or _strong(v, dtype) else jnp.asarray(v, dtype) for v in gains))


def _strong(v, dtype) -> bool:
    """Whether ``v`` is already a jax array of ``dtype``, not weakly typed (nothing to convert)."""
    return isinstance(v, jax.Array) and v.dtype == dtype and not v.weak_type


def _seed_key(seed: int):
    """``jax.random.PRNGKey(seed)``, made once per seed and configuration (keys are immutable;
    one made while tracing is a tracer, never kept)."""
    return shared_constant(("seed key", seed, jax.config.jax_default_prng_impl, jax.config.jax_enable_x64),
                           lambda: jax.random.PRNGKey(seed))


def prng_key(seed):
    """A PRNG key from an int seed (None: 0), or a key returned as it is: a typed key array
    (``jax.random.key``) or raw uint32 keys (``jax.random.PRNGKey``: shape (..., 2)).
    Anything else (a float, a bool, a string, an int beyond 64 bits) is a ValueError."""
    if seed is None:
        seed = 0
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
        try:
            return _seed_key(int(seed))
        except (OverflowError, ValueError, TypeError):
            raise ValueError(f"seed {seed} is out of the range of a PRNG seed (a 64-bit signed int)") from None
    dtype = getattr(seed, "dtype", None)
    if dtype is not None and (jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
                              or (dtype == jnp.uint32 and np.ndim(seed) >= 1 and np.shape(seed)[-1] == 2)):
        return seed
    raise ValueError(f"seed must be an int or a PRNG key (jax.random.key / PRNGKey), got {seed!r}")


def start_configuration(world):
    """The start configuration of a Scenario or MovingScenario (batched or not)."""
    return world.scene.q0 if hasattr(world, "motion") else world.q0


def batch_keys(seed, batch: int):
    """One key per scenario: ``jax.random.split(key(seed), batch)``, or ``seed`` itself when it
    already holds one key per scenario (shape (batch, 2) raw keys, or (batch,) typed keys)."""
    key = prng_key(seed)
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    if key.ndim == (1 if typed else 2):
        if key.shape[0] != batch:
            raise ValueError(f"seed holds {key.shape[0]} keys for a batch of {batch} scenarios")
        return key
    return jax.random.split(key, batch)


def _one(world, gains, options, max_steps: int, key, arm=None) -> Rollout:
    return run(world, gains, options, max_steps, key, driver="chunks", step_chunk=plan_options(options).step_chunk,
               arm=PCC if arm is None else arm)


def _batch(worlds, gains, options, max_steps: int, keys, mesh=None, lanes=None, arm=None) -> Rollout:
    platform = jax.default_backend() if mesh is None else mesh.devices.flat[0].platform

    def laned(worlds, gains, keys):  # worlds: this device's share of the batch
        scenes = jax.tree_util.tree_leaves(worlds)[0].shape[0]
        width = (default_lanes(platform, tracking=tracks(options), scenes=scenes, max_steps=max_steps)
                 if lanes is None else lanes)
        return run_lanes(worlds, gains, options, max_steps, keys, lanes=width,
                         step_chunk=plan_options(options).step_chunk, arm=PCC if arm is None else arm)

    if mesh is None:
        return laned(worlds, gains, keys)
    # Every device runs its own lanes on its own shard of the batch: the scenes are
    # independent, so there is no cross-device communication. check_vma=False: the loop's
    # carries start from constants (unvarying over the mesh), its outputs vary.
    batch, shared = jax.sharding.PartitionSpec(BATCH_AXIS), jax.sharding.PartitionSpec()
    return jax.shard_map(laned, mesh=mesh, in_specs=(batch, shared, batch), out_specs=batch,
                         check_vma=False)(worlds, gains, keys)


def _rollout_structure(options):
    """The pytree structure of a rollout's result: a planned one leaves the tracking fields None."""
    n = len(Rollout._fields) if tracks(options) else len(Rollout._fields) - len(Rollout._field_defaults)
    return jax.tree_util.tree_structure(Rollout(*([0] * n)))


class RolloutProgram:
    """A compiled rollout: ``program(world, gains, options, max_steps, seed=0)`` checks and
    normalises its arguments (the records fit in memory; gains as strong arrays of the scene's
    dtype; an int seed as a PRNG key, one per scene of a batch), so equal shapes hit one
    compilation, and runs the jitted rollout (options and max_steps static). A batch program
    also takes ``devices`` and ``lanes`` (:data:`rollout_batch`).

    :meth:`args` and :meth:`run` split that call (checks once, runs many);
    :meth:`lower` lowers ahead of time; :meth:`cached` compiles ahead of time and keeps the
    traced program on disk; :meth:`cache_size` counts compilations; :meth:`in_chunks` runs a
    batch in chunks of one shape.
    """

    def __init__(self, fn, static_argnames, batched: bool, doc: str):
        self._fn = fn
        self._static_argnames = static_argnames
        self._programs = {}
        self._batched = batched
        self.__doc__ = doc

    def _program(self, options):
        """The rollout jitted with the package's XLA options for the options' method."""
        method = plan_options(options).method
        if method not in self._programs:
            self._programs[method] = package_jit(self._fn, PROGRAM_KIND[method], static_argnames=self._static_argnames)
        return self._programs[method]

    def args(self, world, gains, options, max_steps, seed=0) -> tuple:
        """The normalised arguments of :meth:`run`: ``(world, gains, options, max_steps, key)``
        (one key per scene of a batch). ValueError for a bad max_steps or seed, or records that
        would not fit in memory."""
        q0 = start_configuration(world)
        max_steps = check_engine_sizes(max_steps)[0]
        scenes = q0.shape[0] if self._batched else 1
        # Before anything is allocated: the records of max_steps steps must fit in memory.
        check_rollout_memory(world, options, max_steps, scenes, min(scenes, default_lanes(tracking=tracks(options))))
        key = batch_keys(seed, scenes) if self._batched else prng_key(seed)
        return world, strong_gains(gains, q0.dtype), options, max_steps, key

    def run(self, *args, mesh=None, lanes=None, arm=None) -> Rollout:
        """The compiled rollout on normalised arguments (:meth:`args`); a batch program also
        takes its device ``mesh`` (None: one device) and ``lanes``; ``arm``: the arm model
        (None: the PCC arm; :mod:`softplan_jax.geometry._arm`). Inside the user's own jit, a
        plain jit of the rollout."""
        extra = (mesh, lanes) if self._batched else ()
        if arm is None:
            return self._program(args[2])(*args, *extra)
        return self._program(args[2])(*args, *extra, arm=arm)

    def __call__(self, world, gains, options, max_steps: int, seed=0, devices=None, lanes=None,
                 arm=None) -> Rollout:
        if not self._batched:
            return self.run(*self.args(world, gains, options, max_steps, seed), arm=arm)
        args, mesh, pad = self._sharded(world, gains, options, max_steps, seed, devices, lanes)
        r = self.run(*args, mesh=mesh, lanes=lanes, arm=arm)
        if pad:
            r = jax.tree_util.tree_map(lambda x: x[: start_configuration(world).shape[0]], r)
        return r

    def _sharded(self, worlds, gains, options, max_steps, seed, devices, lanes):
        """``(args, mesh, pad)``: a batch's arguments, padded to a multiple of the device count
        (``pad`` copies of its last scene) and sharded over the mesh."""
        w, g, o, T, keys = self.args(worlds, gains, options, max_steps, seed)
        check_engine_sizes(T, 1, lanes)
        mesh = batch_mesh(devices)
        if mesh is None:
            return (w, g, o, T, keys), None, 0
        batch = start_configuration(w).shape[0]
        size = round_chunk(None, batch, mesh.size)
        (w, keys), g = shard_batch(mesh, pad_batch((w, keys), size), g)
        return (w, g, o, T, keys), mesh, size - batch

    def lower(self, world, gains, options, max_steps: int, seed=0, devices=None, lanes=None):
        """``jax.jit(...).lower`` of the rollout for these arguments (a batch padded to a
        multiple of the device count)."""
        jitted = self._program(options).jitted()
        if not self._batched:
            return jitted.lower(*self.args(world, gains, options, max_steps, seed))
        args, mesh, _ = self._sharded(world, gains, options, max_steps, seed, devices, lanes)
        return jitted.lower(*args, mesh, lanes)

    def cache_size(self) -> int:
        """Number of compilations so far (one per padded shape, dtype, options, max_steps)."""
        return sum(p._cache_size() for p in self._programs.values())

    def cached(self, world, gains, options, max_steps: int, one_shot: bool = False):
        """Compile one scene's rollout ahead of time, keeping the TRACED program on disk for the
        next process (:func:`softplan_jax.base._compilation_cache.load_or_export`). ``one_shot``:
        compiled to run once, for the time to its first result
        (:func:`~softplan_jax.planning._options.rollout_compiler_options`; the results agree with
        the default program's to rounding).

        Returns:
          ``(run, loaded)``: ``run(world, gains, seed=0) -> Rollout`` for arguments of these
          shapes (options and max_steps fixed), and whether the traced program came from disk.
          Without an artifact (cache off, a ParametricCurve in the scene, jax.export
          unavailable) ``run`` is :meth:`lower`'s compiled program and ``loaded`` False; the
          results are the same.
        """
        if self._batched:
            raise ValueError("cached compiles one scene's rollout: use rollout_jit.cached")
        w, g, _, T, key = self.args(world, gains, options, max_steps, 0)
        leaves, treedef = jax.tree_util.tree_flatten((w, g, key))
        scene = w.scene if hasattr(w, "motion") else w

        def flat(*xs):  # arrays in, arrays out: the artifact needs no pytree registrations
            s, g, k = jax.tree_util.tree_unflatten(treedef, xs)
            return tuple(jax.tree_util.tree_leaves(self._fn(s, g, options, T, k)))

        compiled, loaded = (None, False)
        xla = rollout_compiler_options(plan_options(options).method, one_shot)
        if not scene.parametric:
            compiled, loaded = load_or_export(flat, leaves, (repr(options), str(T), str(treedef)), xla)
        if compiled is None:
            plain = self.lower(world, gains, options, T).compile(xla if one_shot else None)

            def run_plain(world, gains, seed=0):
                s, g, _, _, k = self.args(world, gains, options, T, seed)
                return plain(s, g, k)

            return run_plain, False
        out_def = _rollout_structure(options)

        def run_loaded(world, gains, seed=0):
            s, g, _, _, k = self.args(world, gains, options, T, seed)
            return jax.tree_util.tree_unflatten(out_def, compiled(*jax.tree_util.tree_leaves((s, g, k))))

        return run_loaded, loaded

    def in_chunks(self, worlds, gains, options, max_steps: int, seed=0, *, chunk: int | None = None, devices=None,
                  progress: bool = False, lanes: int | None = None, label: str = "plan_batch", arm=None) -> Rollout:
        """A batch (a stacked Scenario with PlanOptions, or a stacked MovingScenario with
        TrackOptions; checked gains) in chunks of ``chunk`` scenes of one shape (None: one
        call), each chunk one call of this batch program; a line per chunk on stderr with
        ``progress``; ``arm``: the arm model (None: PCC). Arrays on the host (NumPy) when there
        are several chunks."""
        T, _, lanes = check_engine_sizes(max_steps, 1, lanes)
        if chunk is not None:
            check_int(chunk, "chunk", 1)
        check_bool(progress, "progress")
        mesh = batch_mesh(devices)
        batch = start_configuration(worlds).shape[0]
        size = round_chunk(chunk, batch, 1 if mesh is None else mesh.size)
        check_rollout_memory(worlds, options, T, batch, min(size, lanes or default_lanes(tracking=tracks(options))))
        n_chunks = math.ceil(batch / size)
        bar = Progress(n_chunks, batch, 1 if mesh is None else mesh.size, label=label) if progress else None
        if n_chunks == 1 and bar is None and not is_global(mesh):
            return self(worlds, gains, options, T, seed, devices=devices, lanes=lanes, arm=arm)
        return _chunked(self, worlds, gains, options, T, batch_keys(seed, batch), mesh, size, lanes, bar, arm)


def _chunked(program, worlds, gains, options, T, keys, mesh, size, lanes, bar, arm=None) -> Rollout:
    """:meth:`RolloutProgram.in_chunks` for several chunks (or a progress bar, or several
    processes): chunk i + 1 is dispatched before chunk i is fetched, so the devices stay busy
    while the host copies."""
    batch = keys.shape[0]
    n_chunks = math.ceil(batch / size)
    spread = is_global(mesh)  # several processes: results are gathered on every host
    host = jax.tree_util.tree_map(np.asarray, worlds)
    out, done = None, 0

    def call(a):
        part = pad_batch(jax.tree_util.tree_map(lambda x: x[a : a + size], (host, keys)), size)
        if mesh is None:
            (s, k), g_dev = jax.device_put(part), gains  # jax arrays, as rollout_batch's: one jit signature
        else:
            (s, k), g_dev = shard_batch(mesh, part, gains)
        return program.run(s, g_dev, options, T, k, mesh=mesh, lanes=lanes, arm=arm)

    def collect(a, r):
        nonlocal out, done
        n = min(size, batch - a)
        if n_chunks == 1 and not spread:
            out = jax.tree_util.tree_map(lambda x: x[:n], r) if n < size else r
        else:
            r = gather(r)
            if out is None:
                out = jax.tree_util.tree_map(lambda x: np.empty((batch, *x.shape[1:]), x.dtype), r)
            for o, x in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(r), strict=True):
                o[a : a + n] = x[:n]
        done += 1
        if bar is not None:
            jax.block_until_ready(out)
            bar.update(done, a + n)

    pending = None
    for i, a in enumerate(range(0, batch, size)):
        t0 = time.perf_counter()
        r = call(a)
        if i == 0 and bar is not None:
            bar.compiled(time.perf_counter() - t0)
        if pending is not None:
            collect(*pending)
        pending = (a, r)
    collect(*pending)
    return out


rollout_jit = RolloutProgram(_one, ("options", "max_steps"), batched=False, doc="""\
:func:`rollout` of one scene under ``jit`` (options and max_steps static):
``rollout_jit(world, gains, options, max_steps, seed=0)``. One compilation per padded scene shape,
dtype, options and max_steps; new goals, obstacles, gain values or seeds reuse it. See
:class:`RolloutProgram`.""")

rollout_batch = RolloutProgram(_batch, ("options", "max_steps", "mesh", "lanes"), batched=True, doc="""\
:func:`rollout` over a batch of scenes of one padded shape (every leaf with a leading batch axis;
gains shared), jitted: ``rollout_batch(worlds, gains, options, max_steps, seed=0, devices=None,
lanes=None)``. Scene b's escapes use ``jax.random.split(key(seed), B)[b]`` (or ``seed[b]`` when
``seed`` holds B keys). ``lanes`` scenes step side by side, each lane taking the next scene when its
scene finishes (:func:`softplan_jax.planning._engine.run_lanes`; None:
:func:`~softplan_jax.planning._engine.default_lanes`), so the cost follows the steps taken.

With more than one device the batch is sharded over them (``devices``: None = every local device,
an int k = the first k, 1 = no sharding, a sequence of jax devices, or ``"global"``: every process's
devices under ``jax.distributed``): padded to a multiple of the device count with copies of its last
scene (dropped from the result), each device runs its lanes on its shard (``jax.shard_map``). The
result agrees with the unsharded call to rounding, not bit for bit (XLA optimises a partitioned
program differently). See :class:`RolloutProgram`.""")
