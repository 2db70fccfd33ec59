"""Dtype-aware numerics: the PCC kinematics' singular ratios ``(1 - cos x) / x`` and ``sin(x) / x``
(a Taylor series below a dtype-dependent threshold, the closed form above, joined by the "double
where" shim so that reverse mode never multiplies a NaN by zero; jaxlie ``_so3.py``, optax
``numerics.safe_norm``), a damped pseudo-inverse, small solves without LAPACK, masked and batched
evaluation, and every tolerance and threshold of the solvers (the closest point of paper §2.3, the
rollout's contact test). How the threshold was chosen: docs, "How the planner works inside"."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "batch_folded",
    "get_epsilon",
    "shared_constant",
    "series_threshold",
    "one_minus_cos_over_x",
    "sin_over_x",
    "safe_norm",
    "damped_pinv",
    "solve_small",
    "atan_over_x",
    "solver_tolerance",
    "curvature_floor",
    "psd_shift",
    "contact_floor",
    "evaluate_where",
    "when_any",
    "tie",
]


def get_epsilon(dtype) -> float:
    """Machine-precision scale used for tolerances: 1e-5 (float32), 1e-10 (float64)."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


def series_threshold(dtype) -> float:
    """|x| below which the Taylor branches of the sinc-like ratios are used."""
    return 0.1 if jnp.dtype(dtype) == jnp.float64 else 0.5


# Taylor coefficients in powers of x**2 (Horner order, highest first).
# sin(x)/x = 1 - x^2/3! + x^4/5! - ... ; (1-cos x)/x = x/2! - x^3/4! + x^5/6! - ...
_SIN_OVER_X = (1 / 362880, -1 / 5040, 1 / 120, -1 / 6, 1.0)
_ONE_MINUS_COS_OVER_X = (1 / 3628800, -1 / 40320, 1 / 720, -1 / 24, 1 / 2)


def _horner_x2(coeffs, x):
    x2 = x * x
    acc = jnp.zeros_like(x) + coeffs[0]
    for c in coeffs[1:]:
        acc = acc * x2 + c
    return acc


def sin_over_x(x):
    """``sin(x) / x`` with value 1 at 0; smooth, finite derivatives of all orders."""
    x = jnp.asarray(x)
    small = jnp.abs(x) < series_threshold(x.dtype)
    x_safe = jnp.where(small, jnp.ones_like(x), x)  # double-where shim
    return jnp.where(small, _horner_x2(_SIN_OVER_X, x), jnp.sin(x_safe) / x_safe)


def one_minus_cos_over_x(x):
    """``(1 - cos x) / x`` with value 0 at 0; smooth, finite derivatives of all orders.

    The closed form uses ``1 - cos x = 2 sin^2(x/2)`` to avoid cancellation.
    """
    x = jnp.asarray(x)
    small = jnp.abs(x) < series_threshold(x.dtype)
    x_safe = jnp.where(small, jnp.ones_like(x), x)
    closed = 2.0 * jnp.sin(0.5 * x_safe) ** 2 / x_safe
    return jnp.where(small, x * _horner_x2(_ONE_MINUS_COS_OVER_X, x), closed)


def safe_norm(v, axis=-1):
    """Euclidean norm whose gradient is finite (zero) at ``v = 0``."""
    sq = jnp.sum(v * v, axis=axis)
    zero = sq == 0
    sq_safe = jnp.where(zero, jnp.ones_like(sq), sq)
    return jnp.where(zero, jnp.zeros_like(sq), jnp.sqrt(sq_safe))


def damped_pinv(J, damping):
    """Damped least-squares pseudo-inverse ``J^T (J J^T + damping^2 I)^-1``.

    The paper's pseudo-inverse ``J^T (J J^T)^-1`` (paper §2.2) is singular for a
    straight arm, whose position Jacobian has rank 2; the damping term keeps it
    well defined and smooth (Wampler 1986; Nakamura & Hanafusa 1986).

    Args:
      J: (m, k) Jacobian, m <= k.
      damping: scalar lambda >= 0.

    Returns:
      (k, m) matrix.
    """
    m = J.shape[0]
    A = J @ J.T + (damping * damping) * jnp.eye(m, dtype=J.dtype)
    # A is symmetric positive definite for damping > 0: solve instead of invert.
    return solve_small(A, J).T


# Largest system solve_small unrolls; larger ones go to jnp.linalg.solve (LAPACK on CPU).
SOLVE_SMALL_MAX = 4


def solve_small(A, B):
    """Solve ``A X = B`` for a small square ``A`` (n x n, n <= 4) by Gaussian
    elimination with partial pivoting, unrolled into element-wise jax operations.

    Why not ``jnp.linalg.solve``: on CPU that is a LAPACK custom call
    (``getrf``), and jaxlib's batched LAPACK kernels split a large batch over
    XLA's intra-op thread pool and block until the pieces finish. When every
    thread of that pool is already running a device's program -- a batch
    sharded over as many CPU devices as the pool has threads (e.g.
    ``--xla_force_host_platform_device_count=2`` on 2 cores) -- nothing is left
    to run the pieces and the program deadlocks (observed in the planner's
    sharded rollouts and collision checks). Unrolled, the solve is plain
    arithmetic that XLA fuses and vectorises over a vmapped batch. Same
    algorithm as LAPACK (pivot: the first largest ``|a_ik|``); a singular
    ``A`` gives inf/NaN, as there.

    Args:
      A: (n, n); n > 4 falls back to ``jnp.linalg.solve``.
      B: (n,) or (n, k).

    Returns:
      X with the shape of B.
    """
    n = A.shape[-1]
    if A.ndim != 2 or A.shape[0] != n or B.shape[0] != n:
        raise ValueError(f"solve_small takes A (n, n) and B (n,) or (n, k), got {A.shape} and {B.shape}")
    if n > SOLVE_SMALL_MAX:
        return jnp.linalg.solve(A, B)
    vector = B.ndim == 1
    M = jnp.concatenate([A, B[:, None] if vector else B], axis=1)
    rows = [M[i] for i in range(n)]
    for k in range(n):
        # Partial pivoting: bring the row with the largest |a_ik| (i >= k) to row k.
        p = jnp.argmax(jnp.stack([jnp.abs(rows[i][k]) for i in range(k, n)]))
        pivot_row = rows[k]
        for j in range(1, n - k):
            pivot_row = jnp.where(p == j, rows[k + j], pivot_row)
        for j in range(1, n - k):
            rows[k + j] = jnp.where(p == j, rows[k], rows[k + j])
        rows[k] = pivot_row
        for i in range(k + 1, n):
            rows[i] = rows[i] - (rows[i][k] / pivot_row[k]) * pivot_row
    # Back substitution on the upper triangle.
    X = [None] * n
    for i in reversed(range(n)):
        acc = rows[i][n:]
        for j in range(i + 1, n):
            acc = acc - rows[i][j] * X[j]
        X[i] = acc / rows[i][i]
    X = jnp.stack(X)
    return X[:, 0] if vector else X


def atan_series_threshold(dtype) -> float:
    """|w| below which :func:`atan_over_x` uses its Taylor series (truncation
    error below w**10 / 11: 1e-18 at 0.02 in float64, 1e-8 at 0.2 in float32)."""
    return 0.02 if jnp.dtype(dtype) == jnp.float64 else 0.2


def atan_over_x(w):
    """``atan(w) / w`` with value 1 at 0; smooth (series branch and double-where shim)."""
    small = jnp.abs(w) < atan_series_threshold(w.dtype)
    w_safe = jnp.where(small, jnp.ones_like(w), w)
    w2 = w * w
    series = 1.0 - w2 * (1.0 / 3.0 - w2 * (1.0 / 5.0 - w2 * (1.0 / 7.0 - w2 / 9.0)))
    return jnp.where(small, series, jnp.arctan(w_safe) / w_safe)


def solver_tolerance(dtype):
    """Relative tolerance of the closest-point solver's first-order test: sqrt(eps)."""
    return jnp.sqrt(jnp.finfo(dtype).eps)


def curvature_floor(scale, dtype):
    """Smallest curvature a Newton step trusts, relative to ``scale``: 10 eps scale."""
    return 10 * jnp.finfo(dtype).eps * scale


def psd_shift(a, b, c, dtype):
    """Shift mu >= 0 making the symmetric 2x2 matrix [[a, b], [b, c]] + mu I
    safely positive definite (smallest eigenvalue at least :func:`curvature_floor`
    of the matrix's scale)."""
    half_tr = 0.5 * (a + c)
    lam_min = half_tr - jnp.sqrt((0.5 * (a - c)) ** 2 + b * b)
    scale = jnp.abs(a) + jnp.abs(c) + jnp.abs(b) + jnp.finfo(dtype).tiny
    floor = curvature_floor(scale, dtype)
    return jnp.where(lam_min > floor, 0.0, floor - lam_min)


def contact_floor(dtype) -> float:
    """Smallest meaningful contact tolerance of ``dtype``: 10 sqrt(eps)."""
    return 10.0 * float(np.sqrt(np.finfo(dtype).eps))


def tie(tree, ref):
    """``tree`` unchanged, as values that depend on ``ref`` (any array): a loop's
    initial carry made of constants, tied to a batched input, is batched from the
    start under ``vmap``. The batching rule of ``lax.scan`` / ``lax.while_loop``
    batches the loop body once more for every carry leaf that starts unbatched
    and comes out batched (a fixpoint); tracing is most of a rollout's compile
    time (docs: "How the planner works inside").
    The ``select(p, x, x)`` is removed by XLA's algebraic simplifier; no runtime
    cost. Integer and bool leaves are tied too; NaN-safe (no arithmetic on ref)."""
    if jnp.size(ref) == 0:
        return tree
    first = jnp.ravel(ref)[0]
    p = jnp.isnan(first) if jnp.issubdtype(first.dtype, jnp.inexact) else first == jnp.zeros((), first.dtype)
    return jax.tree_util.tree_map(lambda x: jax.lax.select(jnp.broadcast_to(p, jnp.shape(x)), x, x), tree)


def evaluate_where(todo, fn, chunk: int, fill):
    """``out[p] = fn(p)`` where ``todo[p]``, ``fill[p]`` elsewhere; todo (P,) bool.

    ``fn`` runs on ``chunk`` flat indices at a time (vmapped), in a
    ``lax.while_loop`` over the entries still to do: the cost is
    ceil(#todo / chunk) iterations, and under ``vmap`` (a batch) the batch's
    largest number of iterations, not a select over all P entries (what a
    ``lax.cond`` becomes under vmap). ``fn(p)`` returns a pytree shaped like one
    row of ``fill`` (a pytree of arrays with leading axis P) and must accept any
    index in [0, P) (chunk slots left over run on index P - 1 and are dropped).
    Used by the between-step search (:mod:`softplan_jax.geometry._clearance`) and the warm
    start's fallback (:mod:`softplan_jax.geometry._warm_start`).
    """
    P = todo.shape[0]

    def body(state):
        out, left = state
        idx = jnp.nonzero(left, size=chunk, fill_value=P)[0]
        if chunk == 1:  # no vmap of one: its batching of fn's loops costs tracing time
            vals = jax.tree_util.tree_map(lambda v: v[None], fn(jnp.minimum(idx[0], P - 1)))
        else:
            vals = jax.vmap(fn)(jnp.minimum(idx, P - 1))
        out = jax.tree_util.tree_map(lambda o, v: o.at[idx].set(v, mode="drop"), out, vals)
        return out, left.at[idx].set(False, mode="drop")

    return jax.lax.while_loop(lambda state: jnp.any(state[1]), body, (tie(fill, todo), todo))[0]


def batch_folded(fn):
    """``fn`` with a batching rule (``jax.custom_batching.custom_vmap``) that calls ``fn``
    itself on the batched arguments, every argument given the batch axis: for a ``fn`` that
    takes any leading axes and folds them into one array of work (a loop over the work to do,
    :func:`evaluate_where`), so that a batch pays for its members' work together instead of
    running the loop as long as its busiest member. Nested ``vmap`` folds one axis per level.
    custom_vmap has no reverse-mode rule: the arguments must be ``stop_gradient``-ed."""

    @jax.custom_batching.custom_vmap
    def folded(*args):
        return fn(*args)

    @folded.def_vmap
    def _rule(axis_size, in_batched, *args):
        def lift(x, batched):
            return x if batched else jnp.broadcast_to(x, (axis_size, *jnp.shape(x)))

        args = [jax.tree_util.tree_map(lift, a, b) for a, b in zip(args, in_batched, strict=True)]
        out = folded(*args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return folded


def when_any(pred, fn, skip, operands, chunk: int | str | None = None):
    """``fn(operands)`` where ``pred`` (a () bool), ``skip(operands)`` elsewhere: a true branch
    (``lax.cond``), also under ``vmap``.

    Under vmap a ``lax.cond`` with a batched predicate becomes a select that runs both
    branches for every element at every call. Here the batch takes one branch for all
    its elements: ``fn`` vmapped over the whole batch when ANY element needs it (the
    others keep ``skip``'s value), else ``skip`` alone. For a step that almost never
    needs ``fn`` (the evasive step of :mod:`softplan_jax.planning._evasion`) this costs
    the batch a predicate, less than ``evaluate_where``'s loop (docs: Moving scenes).
    ``fn`` and ``skip`` return pytrees of the same structure; not differentiable
    (``jax.custom_batching.custom_vmap``). ``chunk``: None, ``fn`` vmapped over the whole
    batch; an int, over the elements that need it only, ``chunk`` at a time
    (:func:`evaluate_where`); ``"auto"``: a 64th of the batch, at least 1 (16 at a
    time for the 1,024 lanes of a tracked batch on a CPU, 256 for an accelerator's 16,384).
    """

    @jax.custom_batching.custom_vmap
    def gate(pred, operands):
        return jax.lax.cond(pred, fn, skip, operands)

    @gate.def_vmap
    def _batched(axis_size, in_batched, pred, operands):
        batched_pred, batched_ops = in_batched
        pred = pred if batched_pred else jnp.broadcast_to(pred, (axis_size,))
        operands = jax.tree_util.tree_map(lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x))),
                                          operands, batched_ops)

        def some(operands):
            kept = jax.vmap(skip)(operands)
            size = max(1, axis_size // 64) if chunk == "auto" else chunk
            if size is None:
                done = jax.vmap(fn)(operands)
                return jax.tree_util.tree_map(
                    lambda a, b: jnp.where(pred.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), done, kept)
            one = lambda i: fn(jax.tree_util.tree_map(lambda x: x[i], operands))  # noqa: E731
            return evaluate_where(pred, one, size, kept)

        out = jax.lax.cond(jnp.any(pred), some, jax.vmap(skip), operands)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return gate(pred, operands)


# Constants made once per key and the default device: jax arrays are immutable, so every call
# can share them (shared_constant).
_SHARED = {}
_SHARED_MAX = 512


def shared_constant(key, make):
    """``make()``, made once per hashable ``key`` and jax default device and then shared (a
    pytree of jax arrays, immutable). One made while tracing (it holds a tracer) is returned
    but never kept; at most ``_SHARED_MAX`` are kept."""
    key = (key, jax.config.jax_default_device)
    value = _SHARED.get(key)
    if value is None:
        value = make()
        if len(_SHARED) < _SHARED_MAX and not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(value)):
            _SHARED[key] = value
    return value
