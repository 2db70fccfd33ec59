"""True clearance during a motion and the collision checks of a trajectory (docs: Conventions,
"Clearance and collision"). The true clearance is the distance from the arm backbone to the real
obstacle (the curve itself, or the point set), minus the arm's and the obstacle's radii, whatever
model the planner used; a collision is a clearance at or below the contact tolerance at a step or
during the straight motion in q between two steps. :func:`between_steps` searches that motion
(Gauss-Newton over (tau, s, u) from both ends' closest pairs: every point it visits is a real
configuration, so a collision is never invented) where :func:`swept_clear` cannot prove it clear
(the clearance at its start minus :func:`~softplan_jax.geometry._kinematics.motion_bound`);
:func:`dense_trajectory_clearance` is the brute-force check that the tests use as an independent
reference."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from ..base._compilation_cache import package_jit
from ..base._numerics import contact_floor, evaluate_where, get_epsilon, safe_norm, solve_small
from ._arm import PCC
from ._closest import ClosestPoint
from ._kinematics import backbone_points, segment_point
from ._obstacles import map_obstacle_groups, map_obstacles, radius_and_mask, true_closest
from ._point_sets import FixedPoint

__all__ = [
    "true_closest",
    "between_steps",
    "swept_clear",
    "contact_tolerance",
    "safety_floor",
    "searched_motions",
    "dense_trajectory_clearance",
]


# Rounding margin of the swept proof (:func:`swept_clear`): PROOF_TOLERANCE eps (1 + the scene's size).
PROOF_TOLERANCE = 64.0
# Gauss-Newton iterations of the between-step search (per start).
SEARCH_ITERATIONS = 8
# (motion, slot) entries searched at once by apply_collision_checks (the rollout: one); not tuned.
POST_HOC_CHUNK = 16


def _motion_pair_distance(q_a, dq, i, x0, curve, iterations: int):
    """Smallest distance found between the arm and a curve over the motion
    q(tau) = q_a + tau dq, tau in [0, 1], from S starts at once: Gauss-Newton on
    r(tau, s, u) = P_si(q(tau)) - F_o(u) from each start x0[k] = (tau, s, u) on
    segment i[k] against curve k (a curve pytree with leading axis S),
    box-clipped, never increasing |r| (best of the step lengths 1, 1/2, 1/4, 0).
    Returns the smallest distance over the starts.

    Every candidate is a real (configuration, arm point, obstacle point)
    triple, so the result is an upper bound on the true minimum over the
    motion: it can miss a dip, never invent one. The starts are vmapped inside
    the loop body, not around the loop (a vmapped loop is traced twice more).
    """
    dtype = q_a.dtype
    ts = jnp.array([1.0, 0.5, 0.25, 0.0], dtype)

    def box(curve):
        lo = jnp.stack([jnp.zeros((), dtype), jnp.zeros((), dtype), curve.u_range[0]])
        hi = jnp.stack([jnp.ones((), dtype), jnp.ones((), dtype), curve.u_range[1]])
        return lo, hi

    def residual(x, i, curve):
        return segment_point(q_a + x[0] * dq, i, x[1]) - curve.point(x[2])

    def residual_and_aux(x, i, curve):
        r = residual(x, i, curve)
        return r, r

    def update(x, i, curve):
        lo, hi = box(curve)
        J, r = jax.jacfwd(residual_and_aux, has_aux=True)(x, i, curve)  # (3, 3): d r / d(tau, s, u); r at x
        H = J.T @ J
        # Levenberg-Marquardt damping relative to the dtype (1e-10 vanishes in float32, where a
        # rank-deficient H, e.g. a straight arm's base point, then solved to NaN).
        H = H + (get_epsilon(dtype) * jnp.trace(H) + jnp.finfo(dtype).tiny) * jnp.eye(3, dtype=dtype)
        step = -solve_small(H, J.T @ r)  # no LAPACK call: see solve_small (sharded batches)
        step = jnp.where(jnp.all(jnp.isfinite(step)), step, 0.0)  # never a NaN candidate
        cands = jnp.clip(x[None, :] + ts[:, None] * step[None, :], lo, hi)
        f = jax.vmap(lambda c: jnp.sum(residual(c, i, curve) ** 2))(cands)
        f = jnp.where(jnp.isnan(f), jnp.inf, f)
        k = jnp.argmin(f)
        return cands[k], f[k]  # the step length 0 keeps x: |r| never increases

    x = jax.vmap(lambda x, c: jnp.clip(x, *box(c)))(x0, curve)
    if iterations == 0:
        return jnp.min(jax.vmap(lambda x, i, c: safe_norm(residual(x, i, c)))(x, i, curve))

    def body(_, state):
        return jax.vmap(update)(state[0], i, curve)

    # The candidates' squared distances are carried, so the FK chain is traced twice, not four times.
    _, f = jax.lax.fori_loop(0, iterations, body, (x, jnp.full(i.shape, jnp.inf, dtype)))
    return jnp.sqrt(jnp.min(f))


def _slot_motion_distance(q_a, q_b, ta: ClosestPoint, tb: ClosestPoint, curve, iterations: int):
    """Smallest distance found during the motion q_a -> q_b for ONE obstacle slot:
    Gauss-Newton over (tau, s, u) (:func:`_motion_pair_distance`) on the segment of
    each end's closest pair, started from both ends' closest pairs. ``curve``: the
    slot's curve, or None for a point set (the closest point of each end, fixed)."""
    dq = q_b - q_a
    dtype = q_a.dtype
    if curve is None:
        curve_a, curve_b = FixedPoint(ta.obstacle_point), FixedPoint(tb.obstacle_point)
        ta, tb = ta._replace(u=jnp.zeros_like(ta.u)), tb._replace(u=jnp.zeros_like(tb.u))
    else:
        curve_a = curve_b = curve
    # Stacked starts (tau, s, u) at tau = 0 and tau = 1, each on its own segment.
    seg = jnp.stack([ta.segment, tb.segment])
    ends = jnp.array([0.0, 1.0], dtype)
    x0 = jnp.stack([ends, jnp.stack([ta.s, tb.s]), jnp.stack([ta.u, tb.u])], axis=-1)
    curves = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), curve_a, curve_b)
    return _motion_pair_distance(q_a, dq, seg, x0, curves, iterations)


def searched_motions(q_a, q_b, truth_a: ClosestPoint, truth_b: ClosestPoint, scenario, search,
                      iterations: int, chunk: int):
    """The between-step search of T motions q_a[t] -> q_b[t], run only for the
    (motion, slot) entries where ``search`` (T, m) is True: smallest distance found
    (T, m), +inf where not searched. Per group of slots of one kind
    (:func:`~softplan_jax.geometry._obstacles.map_obstacle_groups`), the entries to search
    go through :func:`~softplan_jax.base._numerics.evaluate_where`, ``chunk`` at a time."""
    T = q_a.shape[0]

    def take(tree, t, j):
        return jax.tree_util.tree_map(lambda x: x[t, j], tree)

    def group(curves, ta, tb, todo):
        # ta, tb: ClosestPoint (g, T); todo (g, T) -- the group's rows of the (m, T) slot args.
        g = todo.shape[0]

        def one(p):
            j, t = p // T, p % T
            curve = None if curves is None else jax.tree_util.tree_map(lambda x: x[j], curves)
            return _slot_motion_distance(q_a[t], q_b[t], take(ta, j, t), take(tb, j, t), curve, iterations)

        inf = jnp.full((g * T,), jnp.inf, q_a.dtype)
        return evaluate_where(todo.reshape(-1), one, chunk, inf).reshape(g, T)

    no_grad = jax.lax.stop_gradient
    # Slot args with the slot axis first (map_obstacle_groups splits the leading axis m).
    slot_first = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), (truth_a, truth_b, search))
    found = map_obstacle_groups(
        scenario,
        lambda curves, ta, tb, todo: group(jax.tree_util.tree_map(no_grad, curves), ta, tb, todo),
        lambda points, mask, ta, tb, todo: group(None, ta, tb, todo),
        slot_first,
        empty=jnp.zeros((0, T), q_a.dtype),
    )
    return jnp.swapaxes(found, 0, 1)


def between_steps(q_a, q_b, truth_a: ClosestPoint, truth_b: ClosestPoint, scenario, radius_sum,
                  iterations: int = SEARCH_ITERATIONS, search=None):
    """Smallest clearance found (m,) during the motion from q_a to q_b.

    For every obstacle slot, Gauss-Newton over (tau, s, u) on the segment of
    the closest pair at either end, started from both ends' closest pairs
    (see :func:`_motion_pair_distance`); point sets use the closest point of
    each end. ``truth_a``/``truth_b``: :func:`~softplan_jax.geometry._obstacles.true_closest`
    at q_a and q_b. ``radius_sum`` (m,) = arm radius + obstacle radius.

    ``search`` (m,) bool, optional: search only these slots, one after the
    other in a while loop (the rollout passes the slots that
    :func:`swept_clear` cannot prove clear); the others get the smaller of
    the two ends' clearances, also an achieved clearance. None (default):
    every slot, vectorised.
    """
    q_a, q_b = jax.lax.stop_gradient(q_a), jax.lax.stop_gradient(q_b)
    truth_a, truth_b = jax.lax.stop_gradient(truth_a), jax.lax.stop_gradient(truth_b)
    dtype = q_a.dtype
    if search is None:
        found = map_obstacles(
            scenario,
            lambda c, a, b: _slot_motion_distance(q_a, q_b, a, b, c, iterations),
            lambda points, mask, a, b: _slot_motion_distance(q_a, q_b, a, b, None, iterations),
            (truth_a, truth_b),
            empty=jnp.zeros((0,), dtype),
        )
    else:
        found = searched_motions(q_a[None], q_b[None], *jax.tree_util.tree_map(lambda x: x[None], (truth_a, truth_b)),
                                  scenario, search[None], iterations, chunk=1)[0]
    D_min = jnp.minimum(found, jnp.minimum(truth_a.distance, truth_b.distance))
    return D_min - radius_sum


def swept_clear(q_a, q_b, truth_a: ClosestPoint, clearance_a, contact, arm=PCC):
    """(m,) bool: the motion q_a -> q_b provably keeps every obstacle slot's
    clearance above ``contact``, so the between-step search cannot find a collision there.

    :func:`~softplan_jax.geometry._kinematics.motion_bound` B bounds how far any arm point
    moves during the straight-line motion, and the distance to a set is
    1-Lipschitz, so the clearance to obstacle j stays >= c_a[j] - B at every
    instant (c_a: the exact clearance at q_a). Proven where
    ``c_a[j] - B > contact + margin`` and the exact solve at q_a converged; the
    margin ``PROOF_TOLERANCE eps (1 + sum_i max(L_i) + D_a[j])`` covers rounding.
    With the safe step (``PlanOptions.step = "safe"``) the planner keeps
    ``B <= f (c_min - 2 contact)``, so this holds at almost every step of the
    curve method. NaN gives False.

    Args:
      q_a, q_b: (n, 3) the motion's ends.
      truth_a: ClosestPoint (leading axis m) at q_a.
      clearance_a: (m,) its clearance (distance minus radii; +inf: padding).
      contact: the contact tolerance (:func:`contact_tolerance`).
      arm: the arm model whose motion bound B is (default the PCC arm; ``clearance_a`` then
        the model's clearance, e.g. a loaded arm's widened by its pieces' gap).
    """
    bound = arm.motion_bound(q_a, q_b)
    length = jnp.sum(jnp.maximum(q_a[:, 0], q_b[:, 0]))
    margin = PROOF_TOLERANCE * jnp.finfo(q_a.dtype).eps * (1.0 + length + jnp.abs(truth_a.distance))
    return truth_a.converged & (clearance_a - bound > contact + margin)


def contact_tolerance(options, dtype) -> float:
    """Clearance at or below which a rollout counts as collided: the planner options'
    ``contact_tolerance``, but never below ten times sqrt(eps) of ``dtype``."""
    return max(float(options.contact_tolerance), contact_floor(dtype))


def safety_floor(contact: float) -> float:
    """The clearance a certified motion never reaches: twice the contact tolerance ``contact``
    (:func:`contact_tolerance`), so that rounding never brings it to the contact tolerance."""
    return 2.0 * contact


@partial(package_jit, static_argnames=("substeps", "arm_samples", "curve_samples"))
def dense_trajectory_clearance(qs, scenario, substeps: int = 20, arm_samples: int = 200, curve_samples: int = 2000):
    """Brute-force minimum clearance of a trajectory, for checking.

    Interpolates each step linearly in q with ``substeps`` sub-steps, samples
    the arm at ``arm_samples`` points per segment and each curve at
    ``curve_samples`` points, and returns (T, m) minimum clearance per step
    interval and obstacle slot (padding slots: +inf). Slow: for tests and audits.
    Jitted (the sample counts static): one compilation per shape of ``qs`` and scene.
    """
    from ._curves import curve_points

    radius, mask = radius_and_mask(scenario)
    taus = jnp.linspace(0.0, 1.0, substeps + 1)

    def min_dist(arm, pts, mask=None):
        # The square root of the least squared distance: the same number as the least distance
        # (sqrt is correctly rounded and monotone), one square root instead of one per pair.
        # Coordinate by coordinate on (arm, pts) planes, summed x + y + z: a layout XLA fuses
        # into one pass, where the (arm, pts, 3) differences were written out whole.
        dx, dy, dz = ((arm[:, None, k] - pts[None, :, k]) ** 2 for k in range(3))
        d2 = (dx + dy) + dz
        if mask is not None:
            d2 = jnp.where(mask[None, :], d2, jnp.inf)
        return jnp.sqrt(jnp.min(d2))

    def at(q):
        arm = backbone_points(q, arm_samples)
        arm = jnp.concatenate([jnp.zeros((1, 3), arm.dtype), arm])
        d = map_obstacles(
            scenario,
            lambda c: min_dist(arm, curve_points(c, curve_samples)),
            lambda p, m: min_dist(arm, p, m),
            empty=jnp.zeros((0,), q.dtype),
        )
        return d - radius - scenario.arm_radius

    def interval(q_a, q_b):
        return jnp.min(jax.vmap(lambda t: at(q_a + t * (q_b - q_a)))(taus), axis=0)

    res = jax.lax.map(lambda ab: interval(ab[0], ab[1]), (qs[:-1], qs[1:]))
    return jnp.where(mask[None, :], res, jnp.inf)
