"""The rollout as a pure function and its compiled programs.

:func:`rollout` rolls the planner of paper eq. (9) out on one scene (pure: wrap
it in jit, vmap or grad). :data:`rollout_jit` is its jitted entry point (the
"chunks" driver of :func:`~softplan_jax.planning.engine.run`: it stops within a
chunk of the end), :data:`rollout_batch` the batched one (the "lanes" driver,
:func:`~softplan_jax.planning.engine.run_lanes`, sharded over devices). Both
normalise their arguments before the jit boundary (gains as strong arrays of
the scene's dtype, an int seed as a PRNG key), so that equal shapes hit one
compilation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..base.compilation_cache import load_or_export, package_jit, rollout_compiler_options
from ..scenarios import Scenario
from .batching import BATCH_AXIS, batch_mesh, pad_batch, round_chunk, shard_batch
from .engine import check_engine_sizes, default_lanes, run, run_lanes
from .options import PlanOptions, tracks
from .records import Rollout, check_rollout_memory
from .step import Gains

__all__ = ["rollout", "strong_gains", "prng_key", "start_configuration", "batch_keys", "CompiledRollout",
           "rollout_jit", "BatchedRollout", "rollout_batch"]


def rollout(scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, key=None, *,
            driver: str = "scan") -> Rollout:
    """Roll the planner out for up to ``max_steps`` steps (pure; wrap in jit/vmap/grad
    as needed; :func:`softplan_jax.plan` is the jitted entry point). The loop is
    :func:`softplan_jax.planning.engine.run`.

    Step k (k = 0..max_steps) looks at q_k: exact closest pairs to every
    obstacle (shared by the clearance record and, for the curve method, by the
    planner), the true clearance at q_k and during the motion from q_{k-1};
    then the status; then, while running, the step to q_{k+1}
    (clearance-bounded for ``options.step = "safe"``).

    Status: non-finite (a clearance or a step is NaN/inf: the last finite
    configuration is kept; a NaN clearance never counts as clear), collided
    (true clearance <= the contact tolerance at a step or during the motion
    between two steps; this wins over reached), reached (|V_e| <
    goal_tolerance), stalled (the best |V_e| did not improve by
    stall_tolerance over stall_window steps, and no escape is left; while one
    is, a random walk of ``escape_steps`` steps starts instead), else
    max_steps. After the end the records are frozen.

    Args:
      scenario, gains, options, max_steps: as :func:`softplan_jax.plan`.
      key: PRNG key of the escapes' random walks (default ``PRNGKey(0)``).
      driver: "scan" (default: a fixed-length ``lax.scan``, reverse-mode
        differentiable) or "chunks" (stops within ``options.step_chunk`` steps
        of the end; what :data:`rollout_jit` runs). The same arrays either way.
    """
    key = jax.random.PRNGKey(0) if key is None else key
    return run(scenario, gains, options, max_steps, key, driver=driver, step_chunk=options.step_chunk)


def strong_gains(gains: Gains, dtype) -> Gains:
    """Gains as arrays of the scenario's dtype, never weakly typed: a gain given as
    a Python float or ``jnp.asarray(0.1)`` (weak) would otherwise compile anew."""
    return type(gains)(*(v if v is None else jnp.asarray(v, dtype) for v in gains))


def prng_key(seed):
    """A PRNG key from an int seed (None: 0), or a key returned as it is: a typed key array
    (``jax.random.key``) or raw uint32 keys (``jax.random.PRNGKey``: shape (..., 2)).
    Anything else (a float, a bool, a string, an int beyond 64 bits) is a ValueError."""
    if seed is None:
        seed = 0
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
        try:
            return jax.random.PRNGKey(int(seed))
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


def _plan_options(options) -> PlanOptions:
    """The PlanOptions of a rollout's options (PlanOptions, or TrackOptions' ``plan``)."""
    return options if isinstance(options, PlanOptions) else options.plan


def _rollout_jit(world, gains: Gains, options, max_steps: int, key) -> Rollout:
    return run(world, gains, options, max_steps, key, driver="chunks", step_chunk=_plan_options(options).step_chunk)


def _rollout_batch(worlds, gains: Gains, options, max_steps: int, keys, mesh=None, lanes=None) -> Rollout:
    platform = jax.default_backend() if mesh is None else mesh.devices.flat[0].platform
    width = default_lanes(platform, tracking=tracks(options)) if lanes is None else lanes

    def laned(worlds, gains, keys):
        return run_lanes(worlds, gains, options, max_steps, keys, lanes=width,
                         step_chunk=_plan_options(options).step_chunk)

    if mesh is None:
        return laned(worlds, gains, keys)
    # Every device runs its own lanes on its own shard of the batch: the scenes are
    # independent, so there is no cross-device communication. check_vma=False: the loop's
    # carries start from constants (unvarying over the mesh), its outputs vary.
    batch, shared = jax.sharding.PartitionSpec(BATCH_AXIS), jax.sharding.PartitionSpec()
    return jax.shard_map(laned, mesh=mesh, in_specs=(batch, shared, batch), out_specs=batch,
                         check_vma=False)(worlds, gains, keys)


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


class CompiledRollout:
    """A jitted rollout entry point: normalises its arguments (gains as strong
    arrays of the scenario's dtype, an int seed as a PRNG key) before the jit
    boundary, so that equal shapes always hit one compilation.

    Call it as ``f(scenario, gains, options, max_steps, seed=0)``; ``f.lower``
    takes the same arguments and lowers ahead of time (``.compile()`` then
    compiles without running); ``f.cache_size()`` counts the compilations.
    """

    def __init__(self, fn, static_argnames, batched: bool, doc: str):
        self._fn = fn
        self._static_argnames = static_argnames
        self._programs = {}
        self._batched = batched
        self.__doc__ = doc

    def _program(self, options: PlanOptions):
        """The rollout jitted with this package's XLA options for the options' method
        (:class:`~softplan_jax.base.compilation_cache.package_jit`), one per method."""
        method = _plan_options(options).method
        if method not in self._programs:
            self._programs[method] = package_jit(self._fn, method, static_argnames=self._static_argnames)
        return self._programs[method]

    def _jitted(self, options: PlanOptions):
        """The top-level ``jax.jit`` of the rollout for the options' method."""
        return self._program(options).jitted()

    def _call(self, *args):
        """The jitted rollout; inside the user's own jit a plain jit of it (package_jit)."""
        return self._program(args[2])(*args)

    def _args(self, scenario, gains, options, max_steps, seed):
        q0 = start_configuration(scenario)
        max_steps = check_engine_sizes(max_steps)[0]
        scenes = q0.shape[0] if self._batched else 1
        # Before anything is allocated: the records of max_steps steps must fit in memory.
        check_rollout_memory(scenario, options, max_steps, scenes, min(scenes, default_lanes(tracking=tracks(options))))
        key = batch_keys(seed, scenes) if self._batched else prng_key(seed)
        return scenario, strong_gains(gains, q0.dtype), options, max_steps, key

    def __call__(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0) -> Rollout:
        return self._call(*self._args(scenario, gains, options, max_steps, seed))

    def lower(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0):
        """``jax.jit(...).lower`` of the rollout for these arguments."""
        return self._jitted(options).lower(*self._args(scenario, gains, options, max_steps, seed))

    def cache_size(self) -> int:
        """Number of compilations so far (one per padded shape, dtype, options, max_steps)."""
        return sum(p._cache_size() for p in self._programs.values())

    def cached(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int):
        """Compile ahead of time, keeping the TRACED program on disk for the next process
        (:func:`softplan_jax.base.compilation_cache.load_or_export`; ``softplan run`` uses it).

        Returns:
          ``(run, loaded)``: ``run(scenario, gains, seed=0) -> Rollout`` for arguments
          of these shapes (options and max_steps fixed), and whether the traced
          program came from disk. Without an artifact (cache off, a ParametricCurve
          in the scenario, jax.export unavailable) ``run`` is :meth:`lower`'s
          compiled program and ``loaded`` False; the results are the same.
        """
        args = self._args(scenario, gains, options, max_steps, 0)
        dynamic = (args[0], args[1], args[4])  # scenario, gains, key: options and max_steps are static
        leaves, treedef = jax.tree_util.tree_flatten(dynamic)
        # A static scene's Rollout: the tracking fields are None (no tracing needed to know it).
        required = len(Rollout._fields) - len(Rollout._field_defaults)
        out_def = jax.tree_util.tree_structure(Rollout(*([0] * required)))

        def flat(*xs):  # arrays in, arrays out: the artifact needs no pytree registrations
            s, g, k = jax.tree_util.tree_unflatten(treedef, xs)
            return tuple(jax.tree_util.tree_leaves(self._fn(s, g, options, max_steps, k)))

        compiled, loaded = (None, False)
        if not scenario.parametric and not self._batched:
            compiled, loaded = load_or_export(flat, leaves, (repr(options), str(int(max_steps)), str(treedef)),
                                              rollout_compiler_options(options.method))
        if compiled is None:
            plain = self._jitted(options).lower(*self._args(scenario, gains, options, max_steps, 0)).compile()

            def run(scenario, gains, seed=0):
                s, g, _, _, k = self._args(scenario, gains, options, max_steps, seed)
                return plain(s, g, k)

            return run, False

        def run(scenario, gains, seed=0):
            s, g, _, _, k = self._args(scenario, gains, options, max_steps, seed)
            return jax.tree_util.tree_unflatten(out_def, compiled(*jax.tree_util.tree_leaves((s, g, k))))

        return run, loaded


rollout_jit = CompiledRollout(_rollout_jit, ("options", "max_steps"), batched=False, doc="""\
:func:`rollout` under ``jit`` (options and
max_steps static): ``rollout_jit(scenario, gains, options, max_steps, seed=0)``. One compilation per
padded scenario shape, dtype, options and max_steps; new goals, obstacles, gain values or seeds reuse
it. ``seed``: an int or a PRNG key for the escapes. ``rollout_jit.lower(...)`` lowers ahead of time;
``rollout_jit.cache_size()`` counts compilations (see :class:`CompiledRollout`).""")

class BatchedRollout(CompiledRollout):
    """The batched, jitted rollout, sharded over devices (see :data:`rollout_batch`).

    Call it as ``f(scenarios, gains, options, max_steps, seed=0, devices=None)``;
    ``f.lower`` takes the same arguments; ``f.cache_size()`` counts the
    compilations (one per batch shape, dtype, options, max_steps and device set).
    """

    def _sharded_args(self, scenarios, gains, options, max_steps, seed, devices, lanes=None):
        s, g, o, T, keys = self._args(scenarios, gains, options, max_steps, seed)
        lanes = check_engine_sizes(T, 1, lanes)[2]
        mesh = batch_mesh(devices)
        if mesh is None:
            return (s, g, o, T, keys, None, lanes), 0
        batch = start_configuration(s).shape[0]
        size = round_chunk(None, batch, mesh.size)
        (s, keys), g = shard_batch(mesh, pad_batch((s, keys), size), g)
        return (s, g, o, T, keys, mesh, lanes), size - batch

    def __call__(self, scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0,
                 devices=None, lanes=None) -> Rollout:
        args, pad = self._sharded_args(scenarios, gains, options, max_steps, seed, devices, lanes)
        r = self._call(*args)
        if pad:
            batch = start_configuration(scenarios).shape[0]
            r = jax.tree_util.tree_map(lambda x: x[:batch], r)
        return r

    def lower(self, scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0,
              devices=None, lanes=None):
        """``jax.jit(...).lower`` of the batched rollout for these arguments (the batch
        padded to a multiple of the device count)."""
        args = self._sharded_args(scenarios, gains, options, max_steps, seed, devices, lanes)[0]
        return self._jitted(options).lower(*args)


rollout_batch = BatchedRollout(_rollout_batch, ("options", "max_steps", "mesh", "lanes"), batched=True, doc="""\
:func:`rollout` over a batch of
scenarios of one padded shape (every leaf of ``scenarios`` has a leading batch axis; gains shared),
jitted: ``rollout_batch(scenarios, gains, options, max_steps, seed=0, devices=None, lanes=None)``.
Scenario b's escapes use ``jax.random.split(key(seed), B)[b]`` (or ``seed[b]`` when ``seed`` holds B
keys). ``lanes`` scenes step side by side, each lane taking the next scene when its scene finishes
(:func:`softplan_jax.planning.engine.run_lanes`; None: :func:`~softplan_jax.planning.engine.default_lanes`: on
a CPU 64 when planning and up to 1,024 when tracking, the whole batch up to 16,384 on an accelerator), so
the cost follows the steps taken. A stacked MovingScenario with TrackOptions tracks instead
(:func:`~softplan_jax.track_batch`).

With more than one local device the batch is sharded over all of them (``devices``: None = every
local device, an int k = the first k, 1 = no sharding, a sequence of jax devices, or ``"global"``:
every process's devices under ``jax.distributed``, the result then a global array; see
:func:`plan_batch`, which gathers it on every process): padded to a
multiple of the device count with copies of its last scenario (dropped from the result), each
device runs the vmapped rollout on its shard (``jax.shard_map``, no cross-device communication).
The result agrees with the unsharded call to rounding, not bit for bit (XLA optimises a
partitioned program differently); a rollout that amplifies rounding (a near-tie of the stall or
contact test) can end differently. ``.lower`` and ``.cache_size()`` as :class:`CompiledRollout`.""")
