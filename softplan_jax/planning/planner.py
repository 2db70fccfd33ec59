"""Planning entry points: :func:`plan` (one scene), :func:`plan_batch` (many), and
the jitted rollouts behind them.

The step (paper eq. 9 with the safe step) is :mod:`softplan_jax.step`; the loop
that rolls it out, stops when the work is done and refills a batch's lanes is
:mod:`softplan_jax.engine`. Each rollout records q, the tip and the TRUE
clearance to every obstacle (the real curve or point set, whatever model the
planner used), and checks the motion BETWEEN steps for a pass through an
obstacle (:func:`softplan_jax.metrics.between_steps`), searched only where the
motion bound does not prove the motion clear
(:func:`softplan_jax.metrics.swept_clear`; ``PlanOptions.swept_proof``).
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .batching import BATCH_AXIS, Progress, batch_mesh, gather, is_global, pad_batch, round_chunk, shard_batch
from ..base.compilation_cache import load_or_export, rollout_compiler_options
from .engine import DEFAULT_LANES, Rollout, check_engine_sizes, run, run_lanes
from ..geometry.clearance import apply_collision_checks as apply_collision_checks  # moved to metrics; old import path
from ..geometry.obstacles import radius_and_mask
from ..scenarios import Scenario
from ..base.status import STATUS_NAMES as STATUS_NAMES  # noqa: F401  (re-exported: the old import path)
from ..base.status import Status as Status  # noqa: F401  (re-exported: the old import path)
from ..base.status import status_name
from .step import (  # noqa: F401  (the step's names, re-exported: their old import path)
    PAPER_STEP,
    GainFunction,
    Gains,
    PlanOptions,
    apply_step,
    attraction,
    check_options,
    default_gains,
    field_velocity,
    planner_step,
    repulsion,
    repulsion_scale,
)

__all__ = [
    "Gains",
    "GainFunction",
    "default_gains",
    "attraction",
    "repulsion",
    "repulsion_scale",
    "PlanOptions",
    "PAPER_STEP",
    "planner_step",
    "Rollout",
    "rollout",
]


def rollout(scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, key=None, *,
            driver: str = "scan") -> Rollout:
    """Roll the planner out for up to ``max_steps`` steps (pure; wrap in jit/vmap/grad
    as needed; :func:`softplan_jax.plan` is the jitted entry point). The loop is
    :func:`softplan_jax.engine.run`.

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


# ----------------------------------------------------------------------------
# Entry points.


def strong_gains(gains: Gains, dtype) -> Gains:
    """Gains as arrays of the scenario's dtype, never weakly typed: a gain given as
    a Python float or ``jnp.asarray(0.1)`` (weak) would otherwise compile anew."""
    return type(gains)(*(jnp.asarray(v, dtype) for v in gains))


def prng_key(seed):
    """A PRNG key from an int seed (or a key, returned as it is)."""
    if seed is None:
        seed = 0
    if isinstance(seed, (int, np.integer)):
        return jax.random.PRNGKey(int(seed))
    return seed


def _start(world):
    """The start configuration of a Scenario or MovingScenario (batched or not)."""
    return world.scene.q0 if hasattr(world, "motion") else world.q0


def _plan_options(options) -> PlanOptions:
    """The PlanOptions of a rollout's options (PlanOptions, or TrackOptions' ``plan``)."""
    return options if isinstance(options, PlanOptions) else options.plan


def _rollout_jit(world, gains: Gains, options, max_steps: int, key) -> Rollout:
    return run(world, gains, options, max_steps, key, driver="chunks", step_chunk=_plan_options(options).step_chunk)


def _rollout_batch(worlds, gains: Gains, options, max_steps: int, keys, mesh=None, lanes=None) -> Rollout:
    def laned(worlds, gains, keys):
        return run_lanes(worlds, gains, options, max_steps, keys, lanes=DEFAULT_LANES if lanes is None else lanes,
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
        self._jits = {}
        self._nested = None
        self._batched = batched
        self.__doc__ = doc

    def _jitted(self, options: PlanOptions):
        """``jax.jit`` of the rollout with this package's XLA options for the options'
        method (:func:`~softplan_jax.compilation_cache.rollout_compiler_options`), built
        on first use: the options depend on the backend, which importing must not start."""
        method = _plan_options(options).method
        if method not in self._jits:
            self._jits[method] = jax.jit(self._fn, static_argnames=self._static_argnames,
                                         compiler_options=rollout_compiler_options(method))
        return self._jits[method]

    def _call(self, *args):
        """The jitted rollout; inside the user's own jit (jax allows compiler options on
        top-level jits only) a plain jit of it, compiled with the enclosing program's options."""
        try:
            return self._jitted(args[2])(*args)
        except ValueError as e:
            if "top-level" not in str(e):
                raise
            if self._nested is None:
                self._nested = jax.jit(self._fn, static_argnames=self._static_argnames)
            return self._nested(*args)

    def _args(self, scenario, gains, options, max_steps, seed):
        dtype = _start(scenario).dtype
        key = batch_keys(seed, _start(scenario).shape[0]) if self._batched else prng_key(seed)
        return scenario, strong_gains(gains, dtype), options, max_steps, key

    def __call__(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0) -> Rollout:
        return self._call(*self._args(scenario, gains, options, max_steps, seed))

    def lower(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0):
        """``jax.jit(...).lower`` of the rollout for these arguments."""
        return self._jitted(options).lower(*self._args(scenario, gains, options, max_steps, seed))

    def cache_size(self) -> int:
        """Number of compilations so far (one per padded shape, dtype, options, max_steps)."""
        return sum(j._cache_size() for j in self._jits.values())

    def cached(self, scenario: Scenario, gains: Gains, options: PlanOptions, max_steps: int):
        """Compile ahead of time, keeping the TRACED program on disk for the next process
        (:func:`softplan_jax.compilation_cache.load_or_export`; ``softplan run`` uses it).

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
        batch = _start(s).shape[0]
        size = round_chunk(None, batch, mesh.size)
        (s, keys), g = shard_batch(mesh, pad_batch((s, keys), size), g)
        return (s, g, o, T, keys, mesh, lanes), size - batch

    def __call__(self, scenarios: Scenario, gains: Gains, options: PlanOptions, max_steps: int, seed=0,
                 devices=None, lanes=None) -> Rollout:
        args, pad = self._sharded_args(scenarios, gains, options, max_steps, seed, devices, lanes)
        r = self._call(*args)
        if pad:
            batch = _start(scenarios).shape[0]
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
(:func:`softplan_jax.engine.run_lanes`; None: ``engine.DEFAULT_LANES``), so the cost follows the
steps taken. A stacked MovingScenario with TrackOptions tracks instead (:func:`~softplan_jax.track_batch`).

With more than one local device the batch is sharded over all of them (``devices``: None = every
local device, an int k = the first k, 1 = no sharding, a sequence of jax devices, or ``"global"``:
every process's devices under ``jax.distributed``, the result then a global array; see
:func:`plan_batch`, which gathers it on every process): padded to a
multiple of the device count with copies of its last scenario (dropped from the result), each
device runs the vmapped rollout on its shard (``jax.shard_map``, no cross-device communication).
The result agrees with the unsharded call to rounding, not bit for bit (XLA optimises a
partitioned program differently); a rollout that amplifies rounding (a near-tie of the stall or
contact test) can end differently. ``.lower`` and ``.cache_size()`` as :class:`CompiledRollout`.""")


class PlanResult(NamedTuple):
    """What :func:`plan` returns (host-side, trimmed to the steps taken).

    Attributes:
      reached: bool, the tip reached the goal without collision.
      iterations: int, planner steps taken (paper: "iterations to reach goal").
      collided: bool, the true clearance fell to <= 0 at a step or between steps.
      min_clearance: float, minimum true clearance over the motion.
      q: (iterations + 1, n, 3) configurations, start first.
      tip: (iterations + 1, 3) tip positions.
      status: "reached", "collided", "stalled", "max_steps", "non_finite" or
        (with the fallback) "unreachable".
      clearance: (iterations + 1, m) true clearance per step and real obstacle.
      final_error: float, |goal - tip| at the end.
      planner: "local" (the path is the potential-field planner's) or "global"
        (:func:`~softplan_jax.plan_fallback`: the local path up to step
        ``global_start``, then the global search's certified path).
      reason: why the goal was not reached, from the fallback: "beyond_reach",
        "goal_in_obstacle" (proofs), "no_ik_solution" (status "unreachable"), or
        "search_exhausted" (reachable, but the search found no path); else "".
      best_error: the smallest tip distance of a collision-free configuration
        found by the reachability IK (None where it did not run).
      global_start: the step where the global search's path leaves the local
        path (None for a local path).
    """

    reached: bool
    iterations: int
    collided: bool
    min_clearance: float
    q: np.ndarray
    tip: np.ndarray
    status: str
    clearance: np.ndarray
    final_error: float
    planner: str = "local"
    reason: str = ""
    best_error: float | None = None
    global_start: int | None = None


def make_options(method="curve", n_points=10, **kwargs) -> PlanOptions:
    """PlanOptions from keyword arguments, validated."""
    unknown = set(kwargs) - set(PlanOptions._fields)
    if unknown:
        raise ValueError(f"unknown planner option(s) {sorted(unknown)}; known: {list(PlanOptions._fields)}")
    return check_options(PlanOptions(method=method, n_points=int(n_points), **kwargs))


def check_gains(gains: Gains | GainFunction | None, dtype, n_segments: int | None = None):
    """Validate gains on the host: a :class:`Gains` or :class:`GainFunction` of finite
    positive scalars (``damping`` may be 0, ``rep_max`` inf) and, for a GainFunction,
    finite ``rep_profile`` (K >= 2) and ``seg_weights`` (``n_segments``, when given);
    returned as arrays of ``dtype``. None gives :func:`default_gains`."""
    if gains is None:
        return default_gains(dtype)
    if not isinstance(gains, (Gains, GainFunction)):
        raise ValueError(f"gains must be a Gains or a GainFunction, got {type(gains).__name__}")
    vals = {k: np.asarray(v) for k, v in gains._asdict().items()}
    for k in Gains._fields:
        v = vals[k]
        if v.shape != () or not np.isfinite(v) or v <= 0:
            if not ((k == "damping" and v.shape == () and v == 0) or (k == "rep_max" and v.shape == () and v == np.inf)):
                raise ValueError(f"gain {k} must be a finite positive scalar, got {v!r}")
    if isinstance(gains, GainFunction):
        p, w = vals["rep_profile"], vals["seg_weights"]
        if p.ndim != 1 or p.shape[0] < 2 or not np.all(np.isfinite(p)):
            raise ValueError(f"rep_profile must be a finite (K,) array with K >= 2, got shape {p.shape}")
        if w.ndim != 1 or w.shape[0] < 1 or not np.all(np.isfinite(w)):
            raise ValueError(f"seg_weights must be a finite (n,) array, got shape {w.shape}")
        if n_segments is not None and w.shape[0] != int(n_segments):
            raise ValueError(f"seg_weights has {w.shape[0]} entries for an arm of {n_segments} segments")
    return type(gains)(**{k: jnp.asarray(v, dtype) for k, v in vals.items()})


def plan(scenario: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
         max_steps: int = 600, seed=0, **options) -> PlanResult:
    """Plan a path for one scenario (jitted rollout; compiles once per padded
    scenario shape, method and option set).

    Args:
      scenario: a :class:`~softplan_jax.scenarios.Scenario` (make_scenario,
        paper_scenario or load_scenario).
      method: "curve" (the paper's exact closest points) or "points" (each curve
        modelled by ``n_points`` points).
      n_points: N of the N-point model (method "points").
      gains: :class:`Gains` or :class:`GainFunction` (e.g. from
        :func:`~softplan_jax.gains_file.load_gains`); default :func:`default_gains`.
      max_steps: the most planner steps.
      seed: int seed (or PRNG key) of the escapes' random walks.
      **options: further :class:`PlanOptions` fields (step, safe_fraction,
        escapes, goal_tolerance, repulsion, stall_window, solver, ...).

    Returns:
      :class:`PlanResult`.
    """
    if not isinstance(scenario, Scenario):
        raise ValueError(f"scenario must be a Scenario (see make_scenario), got {type(scenario).__name__}")
    if scenario.q0.ndim != 2:
        raise ValueError("plan takes one scenario; use plan_batch for a batch")
    T = check_engine_sizes(max_steps)[0]
    opts = make_options(method, n_points, **options)
    g = check_gains(gains, scenario.q0.dtype, scenario.q0.shape[0])
    r = rollout_jit(scenario, g, opts, T, seed)
    return result_from_rollout(r, scenario)


def result_from_rollout(r: Rollout, scenario: Scenario) -> PlanResult:
    """Trim a single (unbatched) Rollout to the steps taken, on the host."""
    it = int(r.iterations)
    _, mask = radius_and_mask(scenario)
    mask = np.asarray(mask)
    return PlanResult(
        reached=bool(r.reached),
        iterations=it,
        collided=bool(r.collided),
        min_clearance=float(r.min_clearance),
        q=np.asarray(r.q[: it + 1]),
        tip=np.asarray(r.tip[: it + 1]),
        status=status_name(r.status),
        clearance=np.asarray(r.clearance[: it + 1])[:, mask],
        final_error=float(r.final_error),
    )


def plan_batch(scenarios: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
               max_steps: int = 600, seed=0, *, chunk: int | None = None, devices=None, progress: bool = False,
               lanes: int | None = None, **options) -> Rollout:
    """Plan a batch of scenarios: vmapped and jitted, sharded over the local
    devices, in chunks of one shape.

    Args:
      scenarios: a batched Scenario (:func:`stack_scenarios`, or
        :func:`softplan_jax.scenarios.random_scenarios`).
      seed: int seed or PRNG key; scenario b's escapes use
        ``jax.random.split(key(seed), B)[b]`` whatever the chunk. Or one key per
        scenario (B raw keys (B, 2), or B typed keys): then scenario b uses
        ``seed[b]`` (a share of a larger suite keeps the suite's keys, see the
        README's "Many scenarios, several devices").
      chunk: scenarios per call (None: the whole batch in one call). Rounded up
        to a multiple of the device count; the last chunk is padded with copies
        of the last scenario, so every call has the same shape and compiles
        once.
      devices: None (every local device), an int k (the first k local devices;
        1: no sharding), a sequence of local jax devices, or ``"global"``: every
        device of every process under ``jax.distributed`` (call it with the
        same arguments on every process; each process computes its devices'
        shards and every process gets the whole result as NumPy arrays). With
        more than one device, every chunk is split over them (see
        :data:`rollout_batch`).
      progress: write one line per finished chunk to stderr (chunks done,
        scenarios, elapsed time, estimated time left, compile time).
      lanes: scenes stepped side by side on each device (None:
        ``engine.DEFAULT_LANES``); a lane whose scene finished takes the next
        scene of its chunk (:func:`softplan_jax.engine.run_lanes`), so a
        chunk's cost follows the steps its scenes take.
      Other arguments as :func:`plan`.

    Returns:
      A batched :class:`Rollout` (leading axis: scenario; time padded to
      max_steps + 1). In one call its arrays are jax arrays; in several chunks
      (or with ``devices="global"`` on several processes) they are NumPy arrays
      assembled on the host, so the devices hold about
      two chunks at a time. Size: about ``(max_steps + 1) * (8 * (13 + 2 m) + 5)``
      bytes per scenario in float64 (m obstacle slots): 142 kB for 600 steps and
      8 slots, 1.4 GB for 10^4 such scenarios.

    Rounding: a vmapped program's rounding depends on its batch shape and on
    the device count, so results agree with another chunk size or device count
    to rounding (not bit for bit); a rollout that amplifies rounding (a
    near-tie of the stall test or of the contact test) can end differently.
    """
    if not isinstance(scenarios, Scenario) or scenarios.q0.ndim != 3:
        raise ValueError("plan_batch takes a batched Scenario (see stack_scenarios)")
    opts = make_options(method, n_points, **options)
    dtype = scenarios.q0.dtype
    g = strong_gains(check_gains(gains, dtype, scenarios.q0.shape[-2]), dtype)
    return run_batch(scenarios, g, opts, max_steps, seed, chunk=chunk, devices=devices, progress=progress,
                     lanes=lanes)


def run_batch(worlds, gains, options, max_steps: int, seed=0, *, chunk: int | None = None, devices=None,
              progress: bool = False, lanes: int | None = None, label: str = "plan_batch") -> Rollout:
    """The batch loop of :func:`plan_batch` and :func:`~softplan_jax.track_batch`: ``worlds``
    (a stacked Scenario with PlanOptions, or a stacked MovingScenario with TrackOptions;
    checked gains) in chunks of one shape, each chunk one call of :data:`rollout_batch`."""
    T, _, lanes = check_engine_sizes(max_steps, 1, lanes)
    if chunk is not None and (isinstance(chunk, (bool, np.bool_)) or not isinstance(chunk, (int, np.integer))
                              or chunk < 1):
        raise ValueError(f"chunk must be None or an int >= 1, got {chunk!r}")
    if not isinstance(progress, (bool, np.bool_)):
        raise ValueError(f"progress must be True or False, got {progress!r}")
    mesh = batch_mesh(devices)
    n_dev = 1 if mesh is None else mesh.size
    batch = _start(worlds).shape[0]
    size = round_chunk(chunk, batch, n_dev)
    n_chunks = math.ceil(batch / size)
    bar = Progress(n_chunks, batch, n_dev, label=label) if progress else None
    spread = is_global(mesh)  # several processes: results are gathered on every host
    if n_chunks == 1 and bar is None and not spread:
        return rollout_batch(worlds, gains, options, T, seed, devices=devices, lanes=lanes)

    keys = batch_keys(seed, batch)
    host = jax.tree_util.tree_map(np.asarray, worlds)
    out, done = None, 0

    def call(a):
        part = pad_batch(jax.tree_util.tree_map(lambda x: x[a : a + size], (host, keys)), size)
        if mesh is None:
            (s, k), g_dev = jax.device_put(part), gains  # jax arrays, as rollout_batch's: one jit signature
        else:
            (s, k), g_dev = shard_batch(mesh, part, gains)
        return rollout_batch._call(s, g_dev, options, T, k, mesh, lanes)

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

    # Dispatch chunk i + 1 before fetching chunk i: the devices stay busy while the host copies.
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
