"""Batches over devices (not part of the paper's method): the device mesh, padding, sharding and
progress of :func:`~softplan_jax.plan_batch` and :data:`~softplan_jax.planning.rollout_batch`. The
scenarios are independent, so a batch is split along its leading axis over a one-axis
``jax.sharding.Mesh`` (``"batch"``) and every device runs the vmapped rollout on its own shard
(``jax.shard_map``, no cross-device communication); ``devices="global"`` makes the mesh of every
process's devices under ``jax.distributed``, each process putting only its own devices' shards
(:func:`shard_batch`) and getting the whole result back (:func:`gather`). Docs: Performance,
"Many scenarios, several devices"."""

from __future__ import annotations

import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["BATCH_AXIS", "batch_mesh", "is_global", "pad_batch", "lanes_map", "shard_batch", "gather", "round_chunk",
           "Progress"]

BATCH_AXIS = "batch"


def batch_mesh(devices=None) -> Mesh | None:
    """The 1-D mesh a batch is sharded over, or None for one default device (no sharding).

    Args:
      devices: None (every local device: ``jax.local_devices()``), an int k
        (the first k local devices; 1 = no sharding), a sequence of distinct
        local ``jax.Device`` objects (one explicit device: a 1-device mesh, so
        the batch runs there), or ``"global"``: every device of every process
        (``jax.devices()``, after ``jax.distributed.initialize``; with one
        process, the local devices).

    Raises:
      ValueError: an int outside [1, local device count], an empty sequence,
        something that is not a local device, a device given twice, or a string
        other than "global".
    """
    local = jax.local_devices()
    if isinstance(devices, str):
        if devices != "global":
            raise ValueError(f'devices must be None, an int, a sequence of jax devices or "global", got {devices!r}')
        every = jax.devices()
        return None if len(every) == 1 else Mesh(np.array(every), (BATCH_AXIS,))
    if devices is None:
        chosen = local
    elif isinstance(devices, (bool, np.bool_)):
        raise ValueError(f"devices must be None, an int or a sequence of jax devices, got {devices!r}")
    elif isinstance(devices, (int, np.integer)):
        k = int(devices)
        if not 1 <= k <= len(local):
            raise ValueError(f"devices={k}: choose 1 to {len(local)} (the local device count)")
        if k == 1:
            return None
        chosen = local[:k]
    else:
        try:
            chosen = list(devices)
        except TypeError:
            raise ValueError(
                f"devices must be None, an int or a sequence of jax devices, got {type(devices).__name__}"
            ) from None
        if not chosen:
            raise ValueError("devices is empty")
        ids = {d.id for d in local}
        for d in chosen:
            if not isinstance(d, jax.Device) or d.id not in ids:
                raise ValueError(f"devices: {d!r} is not a local jax device ({local})")
        if len({d.id for d in chosen}) != len(chosen):
            raise ValueError("devices: a device is given twice")
        return Mesh(np.array(chosen), (BATCH_AXIS,))
    return None if len(chosen) == 1 else Mesh(np.array(chosen), (BATCH_AXIS,))


def pad_batch(tree, size: int):
    """Pad every leaf's leading (batch) axis to ``size`` with copies of its last
    entry (a real scenario, so padding never creates a degenerate input).
    NumPy leaves stay NumPy, jax leaves stay jax."""

    def pad(x):
        extra = size - x.shape[0]
        if extra < 0:
            raise ValueError(f"cannot pad a batch of {x.shape[0]} to {size}")
        if extra == 0:
            return x
        xp = np if isinstance(x, np.ndarray) else jnp
        return xp.concatenate([x, xp.repeat(x[-1:], extra, axis=0)])

    return jax.tree_util.tree_map(pad, tree)


def lanes_map(f, *args):
    """``jax.vmap(f)(*args)`` (every leaf of ``args`` with a leading lane axis B); for one lane
    (B = 1), ``f`` of the lane itself with the axis added back: the same values, traced without
    vmap's batching rules (cheaper to trace, and a while_loop whose trip count is a lane's stays
    a loop with an unbatched predicate; docs: "How the planner works inside").
    XLA may round the two programs differently (last bits)."""
    if jax.tree_util.tree_leaves(args)[0].shape[0] != 1:
        return jax.vmap(f)(*args)
    out = f(*jax.tree_util.tree_map(lambda x: x[0], args))
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], out)


def is_global(mesh: Mesh | None) -> bool:
    """Whether the mesh holds devices of other processes (``devices="global"`` under
    ``jax.distributed``)."""
    return mesh is not None and any(d.process_index != jax.process_index() for d in mesh.devices.flat)


def shard_batch(mesh: Mesh, batched, shared):
    """``jax.device_put`` the batched tree split along its leading axis over the
    mesh, and the shared tree replicated on every device. On a mesh over several
    processes every process holds the same (host) trees and puts only the shards
    of its own devices (``jax.make_array_from_callback``)."""
    split, same = NamedSharding(mesh, PartitionSpec(BATCH_AXIS)), NamedSharding(mesh, PartitionSpec())
    if not is_global(mesh):
        return jax.device_put(batched, split), jax.device_put(shared, same)

    def put(sharding):
        def leaf(x):
            x = np.asarray(x)
            return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])

        return leaf

    return jax.tree_util.tree_map(put(split), batched), jax.tree_util.tree_map(put(same), shared)


def gather(tree):
    """The tree's arrays as NumPy arrays on the host; arrays sharded over several
    processes are gathered whole on every process
    (``jax.experimental.multihost_utils.process_allgather``)."""

    def leaf(x):
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            from jax.experimental import multihost_utils

            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return np.asarray(jax.device_get(x))

    return jax.tree_util.tree_map(leaf, tree)


def round_chunk(chunk: int | None, batch: int, n_devices: int) -> int:
    """Scenarios per call: ``chunk`` (None: the whole batch), at most the batch,
    rounded up to a multiple of the device count (every device gets as many)."""
    c = batch if chunk is None else min(int(chunk), batch)
    return math.ceil(c / n_devices) * n_devices


class Progress:
    """One line on stderr per finished chunk (rewritten in place on a terminal)::

        plan_batch: 3/20 chunks, 1,536/10,000 scenarios on 2 devices, 41.2 s, eta 232 s (compile 14.1 s)
    """

    def __init__(self, n_chunks: int, batch: int, n_devices: int, label: str = "plan_batch", stream=None):
        self.n_chunks, self.batch, self.n_devices, self.label = n_chunks, batch, n_devices, label
        self.stream = sys.stderr if stream is None else stream
        self.t0 = time.perf_counter()
        self.compile_s = None
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def compiled(self, seconds: float) -> None:
        """The first chunk's call returned after ``seconds``: tracing and compilation (the
        execution is asynchronous)."""
        self.compile_s = seconds

    def update(self, chunks_done: int, scenarios_done: int) -> None:
        elapsed = time.perf_counter() - self.t0
        line = (
            f"{self.label}: {chunks_done}/{self.n_chunks} chunks, {scenarios_done:,}/{self.batch:,} scenarios "
            f"on {self.n_devices} device{'s' if self.n_devices > 1 else ''}, {elapsed:.1f} s"
        )
        if 0 < chunks_done < self.n_chunks:
            run = elapsed - (self.compile_s or 0.0)
            line += f", eta {run / chunks_done * (self.n_chunks - chunks_done):.0f} s"
        if self.compile_s is not None:
            line += f" (compile {self.compile_s:.1f} s)"
        end = "\n" if not self.tty or chunks_done >= self.n_chunks else ""
        self.stream.write(("\r" if self.tty else "") + line + end)
        self.stream.flush()
