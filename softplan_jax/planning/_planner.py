"""Planning entry points: :func:`plan` (one scene) and :func:`plan_batch` (many), over the compiled
rollouts of :mod:`softplan_jax.planning._programs`. Each rollout records q, the tip and the true
clearance to every obstacle (the real curve or point set, whatever model the planner used), and
checks the motion between steps for a pass through an obstacle
(:func:`~softplan_jax.geometry._clearance.between_steps`) where the motion bound does not prove it
clear (:func:`~softplan_jax.geometry._clearance.swept_clear`; ``PlanOptions.swept_proof``)."""

from __future__ import annotations

import functools
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..base._compilation_cache import package_jit
from ..base._status import Status, status_name
from ..geometry._arm import PCC
from ..geometry._clearance import contact_tolerance
from ..geometry._closest import DEFAULT_OPTIONS
from ..geometry._kinematics import tip_jacobian
from ..geometry._obstacles import clearance_of, radius_and_mask, true_closest
from ..rod._arm import LoadedArm
from ..rod._equilibrium import solve_equilibrium, unconverged_error
from ..rod._model import RodModel, segment_material
from ..scenarios import Scenario
from ..scenarios._scenario import check_scenario, unreachable_reason
from ._engine import check_engine_sizes
from ._options import PlanOptions, make_options
from ._programs import prng_key, rollout_batch, rollout_jit, strong_gains
from ._records import Rollout
from ._step import GOAL_GAINS, GainFunction, Gains, default_gains

__all__ = ["PlanResult", "make_options", "check_gains", "plan", "plan_device", "unreachable_result",
           "result_from_rollout", "plan_batch"]


class PlanResult(NamedTuple):
    """What :func:`plan` returns (host-side, trimmed to the steps taken).

    Attributes:
      reached: bool, the tip reached the goal without collision.
      iterations: int, planner steps taken (paper: "iterations to reach goal").
      collided: bool, the true clearance fell to <= 0 at a step or between steps.
      min_clearance: float, minimum true clearance over the motion (exact where below
        ``d0 + far_margin``, see PlanOptions.far_margin; else a lower bound above it).
      q: (iterations + 1, n, 3) configurations, start first.
      tip: (iterations + 1, 3) tip positions.
      status: "reached", "collided", "start_in_collision" (the start pose is
        in collision: nothing planned), "stalled", "max_steps", "non_finite" or
        "unreachable" (proven before planning: the goal beyond the arm's reach
        or inside an obstacle, with ``reason``; or decided by the fallback).
      clearance: (iterations + 1, m) true clearance per step and real obstacle
        (above ``d0 + far_margin``: a certified lower bound, PlanOptions.far_margin).
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


# Largest k_att * dt of a sound explicit Euler step of the attraction (see check_gains).
EULER_BOUND = 2.0


def check_gains(gains: Gains | GainFunction | None, dtype, n_segments: int | None = None, q0=None):
    """Validate gains on the host: a :class:`Gains` or :class:`GainFunction` of finite
    positive scalars (``damping`` may be 0, ``rep_max`` inf) and, for a GainFunction,
    finite ``rep_profile`` (K >= 2), ``seg_weights`` (``n_segments``, when given) and
    ``goal_profile`` (None, or 4 rows of K >= 2);
    returned as arrays of ``dtype``. None gives :func:`default_gains`.

    Soundness: ``k_att * dt >= 2`` is past the stability bound of the explicit Euler step
    (within ``v_max / k_att`` of the goal the attraction is linear and the tip's error obeys
    ``e <- (1 - k_att dt) e``, which grows for ``k_att dt > 2``): a UserWarning saying so.
    ``damping = 0`` is the plain pseudo-inverse ``J^T (J J^T)^-1``, which does not exist where
    the Jacobian loses rank: with a start pose ``q0`` whose tip Jacobian is singular (a
    straight arm bending in one plane) a ValueError."""
    if gains is None:
        return default_gains(dtype)
    if not isinstance(gains, (Gains, GainFunction)):
        raise ValueError(f"gains must be a Gains or a GainFunction, got {type(gains).__name__}")
    vals = {}
    for k, v in gains._asdict().items():
        if k == "goal_profile" and v is None:  # a GainFunction without a dependence on the goal distance
            vals[k] = None
            continue
        if np.asarray(v).dtype == bool:
            raise ValueError(f"gain {k} must be a number, got {v!r}")
        try:
            vals[k] = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"gain {k} must be a number (a finite float), got {v!r}") from None
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
        g = vals["goal_profile"]
        if g is not None and (g.ndim != 2 or g.shape[0] != len(GOAL_GAINS) or g.shape[1] < 2
                              or not np.all(np.isfinite(g))):
            raise ValueError(f"goal_profile must be None or a finite ({len(GOAL_GAINS)}, K) array with K >= 2 "
                             f"(rows {', '.join(GOAL_GAINS)}), got shape {g.shape}")
    k_dt = float(vals["k_att"] * vals["dt"])
    g = vals.get("goal_profile")
    if g is not None:
        # A goal profile scales k_att with the goal distance: the bound holds for the largest k_att
        # within the linear zone, u <= 1/2 (the profile is piecewise linear: its knots there and u = 1/2).
        knots = np.linspace(0.0, 1.0, g.shape[1])
        row = g[GOAL_GAINS.index("k_att")]
        near = np.append(row[knots <= 0.5], np.interp(0.5, knots, row))
        k_dt *= float(np.exp(near.max()))
    if k_dt >= EULER_BOUND:
        warnings.warn(f"gain dt = {float(vals['dt']):g} with k_att = {float(vals['k_att']):g}"
                      f"{' (times its goal profile near the goal)' if g is not None else ''}: k_att * dt = {k_dt:g} "
                      f">= {EULER_BOUND:g}, past the stability bound of the explicit Euler step (dt < 2 / k_att = "
                      f"{EULER_BOUND / float(vals['k_att']):g}): near the goal the tip's error e <- (1 - k_att dt) e "
                      "grows instead of shrinking, so the arm oscillates about the goal and may never settle on it",
                      UserWarning, stacklevel=3)
    if q0 is not None and vals["damping"] == 0:
        s = np.linalg.svd(np.asarray(tip_jacobian(jnp.asarray(q0)), np.float64), compute_uv=False)
        if s[-1] <= 1e-9 * s[0]:
            raise ValueError("gain damping = 0 (the plain pseudo-inverse J^T (J J^T)^-1) does not exist at this "
                             "start pose: its tip Jacobian has rank < 3 (a straight arm bending in one plane); use "
                             "damping > 0 (default 0.05) or bend the start pose (the paper preset: theta 0.1)")
    return type(gains)(**{k: v if v is None else jnp.asarray(v, dtype) for k, v in vals.items()})


def plan(scenario: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
         max_steps: int = 600, seed=0, *, device=None, model=None, **options) -> PlanResult:
    """Plan a path for one scenario (jitted rollout; compiles once per padded
    scenario shape, method and option set).

    Args:
      scenario: a :class:`~softplan_jax.scenarios.Scenario` (make_scenario,
        paper_scenario or load_scenario).
      method: "curve" (the paper's exact closest points) or "points" (each curve
        modelled by ``n_points`` points).
      n_points: N of the N-point model (method "points").
      gains: :class:`Gains` or :class:`GainFunction` (e.g. from
        :func:`~softplan_jax.tuning._gains_file.load_gains`); default :func:`default_gains`.
      max_steps: the most planner steps.
      seed: int seed (or PRNG key) of the escapes' random walks.
      device: where the rollout runs: None (default) jax's default device,
        except where that is an accelerator: then the host CPU, which plans one
        scene faster (a step is a few hundred small kernels; docs: Performance,
        "On a GPU");
        ``"default"``: jax's default device whatever it is; or a ``jax.Device``
        (jax's default device itself, with the scenario on it, runs the same
        compiled program as None). Batches belong on the accelerator
        (:func:`plan_batch`). Results on another device agree to rounding.
      model: None (the PCC arm of paper §2.1) or a :class:`~softplan_jax.rod.RodModel`: the
        arm sags under its weight and tip load (:class:`~softplan_jax.rod.LoadedArm`). The
        clearances, the tip and eq. (9)'s Jacobians are then the loaded arm's, the safe step
        uses the loaded motion bound (it does not move where that bound does not close), and
        an equilibrium that does not converge ends the plan with status "non_finite".
        Static scenes only.
      **options: further :class:`PlanOptions` fields (step, safe_fraction,
        escapes, goal_tolerance, repulsion, stall_window, solver, ...).

    Returns:
      :class:`PlanResult`. A goal proven unreachable on the host
      (:func:`~softplan_jax.scenarios._scenario.unreachable_reason`: beyond the arm's reach,
      or inside an obstacle) returns at once, status "unreachable" with the reason, the start
      pose alone (:func:`unreachable_result`); a start pose in collision ends at step 0 with
      status "start_in_collision".
    """
    if isinstance(scenario, Scenario) and getattr(scenario.q0, "ndim", 2) == 3:
        raise ValueError("plan takes one scenario; use plan_batch for a batch")
    check_scenario(scenario, batched=False)
    dev = plan_device(device)
    if dev is None or _already_there(scenario, dev):
        # jax's default device already: no device context and no device_put, which
        # would each key another compilation of the same program.
        return _plan_here(scenario, method, n_points, gains, max_steps, seed, options, model)
    # Everything on the chosen device from here: the checks too (each small op on an
    # accelerator would be a round trip).
    with jax.default_device(dev):
        return _plan_here(jax.device_put(scenario, dev), method, n_points, gains, max_steps, seed, options, model)


def arm_model(model, n_segments: int):
    """The arm model of a plan: None (the PCC arm) for ``model=None``, else the
    :class:`~softplan_jax.rod.LoadedArm` of a :class:`~softplan_jax.rod.RodModel`, its
    per-segment fields checked against ``n_segments``. ValueError for anything else."""
    if model is None:
        return None
    if not isinstance(model, RodModel):
        raise ValueError(f"model must be None (the PCC arm) or a softplan_jax.RodModel, got {type(model).__name__}")
    segment_material(model, n_segments, jnp.float64)
    return LoadedArm(model)


def start_arm(model, q0):
    """:func:`arm_model` for an arm starting at q0 (n, 3), and a ValueError where the loaded arm
    has no stable equilibrium at q0 (the rod cannot carry the load there: nothing to plan from)."""
    arm = arm_model(model, q0.shape[0])
    if arm is not None:
        shape = solve_equilibrium(q0, model)
        if not bool(shape.converged):
            raise unconverged_error(shape.residual, shape.iterations, model)
    return arm


def _plan_here(scenario, method, n_points, gains, max_steps, seed, options, model=None) -> PlanResult:
    """:func:`plan` after the scenario's checks, on jax's default device."""
    T = check_engine_sizes(max_steps)[0]
    opts = make_options(method, n_points, **options)
    g = check_gains(gains, scenario.q0.dtype, scenario.q0.shape[0], scenario.q0)
    prng_key(seed)  # a bad seed is a ValueError before anything compiles
    arm = start_arm(model, scenario.q0)
    reason = unreachable_reason(scenario)  # its proofs hold for the loaded arm too (inextensible)
    if reason:
        return unreachable_result(scenario, opts, reason, arm)
    r = rollout_jit(scenario, g, opts, T, seed, arm=arm)
    return result_from_rollout(r, scenario)


def _already_there(scenario, dev) -> bool:
    """Whether ``dev`` is jax's default device and every array of ``scenario`` is on it."""
    default = jax.config.jax_default_device
    if default is None:
        default = jax.devices()[0]
    elif isinstance(default, str):
        default = jax.devices(default)[0]
    return dev == default and all(
        getattr(leaf, "devices", lambda: {dev})() == {dev} for leaf in jax.tree.leaves(scenario))


def plan_device(device=None):
    """The device :func:`plan` runs one scene on, or None for jax's default device.

    ``device``: None (auto: the host CPU where jax's default backend is an
    accelerator and a CPU device exists, else the default), ``"default"``, or a
    ``jax.Device``. ValueError for anything else."""
    if device is None:
        if jax.default_backend() == "cpu":
            return None
        try:
            return jax.devices("cpu")[0]
        except RuntimeError:  # no CPU backend in this process
            return None
    if isinstance(device, str):
        if device != "default":
            raise ValueError(f'device must be None, "default" or a jax.Device, got {device!r}')
        return None
    if not isinstance(device, jax.Device):
        raise ValueError(f'device must be None, "default" or a jax.Device, got {type(device).__name__}')
    return device


@functools.cache
def _start_program(solver):
    def start(arm, q, scenario):
        posed = arm.at(q)
        sc = posed.widened(scenario)
        return clearance_of(true_closest(posed.shape(q), sc, solver), sc), posed.tip(q)

    return package_jit(start)


def unreachable_result(scenario: Scenario, options: PlanOptions, reason: str, arm=None) -> PlanResult:
    """The result of a scene whose goal is proven unreachable (``reason``: "beyond_reach" or
    "goal_in_obstacle"), without planning: the start pose alone (iterations 0), its exact
    clearance (the true closest points, as a rollout's record), status "unreachable". ``arm``:
    None (the PCC arm) or a loaded arm (:func:`arm_model`), whose tip and clearance (a lower
    bound, as its rollouts record) are reported."""
    q0 = scenario.q0
    solver = options.solver if options.method == "curve" else DEFAULT_OPTIONS
    clearance, tip = (np.asarray(x) for x in _start_program(solver)(PCC if arm is None else arm, q0, scenario))
    _, mask = radius_and_mask(scenario, np)
    c = clearance[mask]
    min_c = float(np.min(c, initial=np.inf))
    return PlanResult(
        reached=False, iterations=0, collided=bool(min_c <= contact_tolerance(options, q0.dtype)),
        min_clearance=min_c, q=np.asarray(q0)[None], tip=tip[None], status=status_name(Status.UNREACHABLE),
        clearance=c[None], final_error=float(np.linalg.norm(np.asarray(scenario.goal) - tip)), reason=reason)


def result_from_rollout(r: Rollout, scenario: Scenario) -> PlanResult:
    """Trim a single (unbatched) Rollout to the steps taken, on the host."""
    # One transfer, then NumPy slices: slicing the device arrays at steps taken would compile
    # a slice program for every new step count (docs: Performance, "One scene").
    r = jax.device_get(r)
    it = int(r.iterations)
    _, mask = radius_and_mask(scenario, np)
    return PlanResult(
        reached=bool(r.reached),
        iterations=it,
        collided=bool(r.collided),
        min_clearance=float(r.min_clearance),
        q=r.q[: it + 1],
        tip=r.tip[: it + 1],
        status=status_name(r.status),
        clearance=r.clearance[: it + 1][:, mask],
        final_error=float(r.final_error),
    )


def plan_batch(scenarios: Scenario, method: str = "curve", n_points: int = 10, gains: Gains | None = None,
               max_steps: int = 600, seed=0, *, chunk: int | None = None, devices=None, progress: bool = False,
               lanes: int | None = None, model=None, **options) -> Rollout:
    """Plan a batch of scenarios: vmapped and jitted, sharded over the local
    devices, in chunks of one shape.

    Args:
      scenarios: a batched Scenario (:func:`~softplan_jax.scenarios.stack_scenarios`, or
        :func:`softplan_jax.scenarios.random_scenarios`).
      seed: int seed or PRNG key; scenario b's escapes use
        ``jax.random.split(key(seed), B)[b]`` whatever the chunk. Or one key per
        scenario (B raw keys (B, 2), or B typed keys): then scenario b uses
        ``seed[b]`` (a share of a larger suite keeps the suite's keys, see the
        documentation's Performance page, "Many scenarios, several devices").
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
        :func:`~softplan_jax.planning._engine.default_lanes`: on a CPU 8 to 128, fewer
        for a small chunk at a large max_steps; the device's whole share up to 16,384
        on a GPU); a lane whose scene finished takes the next scene of its chunk
        (:func:`softplan_jax.planning._engine.run_lanes`), so a chunk's cost follows
        the steps its scenes take.
      model: None (the PCC arm) or a :class:`~softplan_jax.rod.RodModel`, one for every
        scene (as :func:`plan`).
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
    if not isinstance(scenarios, Scenario) or getattr(scenarios.q0, "ndim", 0) != 3:
        raise ValueError("plan_batch takes a batched Scenario (see stack_scenarios)")
    check_scenario(scenarios, batched=True)
    if scenarios.q0.shape[0] == 0:
        raise ValueError("plan_batch: the batch holds no scenario")
    opts = make_options(method, n_points, **options)
    dtype = scenarios.q0.dtype
    g = strong_gains(check_gains(gains, dtype, scenarios.q0.shape[-2]), dtype)
    arm = arm_model(model, scenarios.q0.shape[-2])
    return rollout_batch.in_chunks(scenarios, g, opts, max_steps, seed, chunk=chunk, devices=devices,
                                   progress=progress, lanes=lanes, arm=arm)
