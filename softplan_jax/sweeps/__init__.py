"""Sweeps at scale: the planner over a seeded random suite of any size, in constant memory,
streamed to disk chunk by chunk, resumable, with the global fallback where asked
(:mod:`._runner`: :func:`sweep` and its suite; :mod:`._chunks`: the chunk loop, shared with
``softplan batch``; :mod:`._store`: the sweep folder; :mod:`._processes`: several processes;
:mod:`._report`: progress and summary)."""

from ._runner import SCENE_BLOCK, sweep, sweep_keys, sweep_scenarios
from ._store import load_trajectory, read_table, wilson_interval

__all__ = ["sweep", "sweep_scenarios", "sweep_keys", "SCENE_BLOCK", "read_table", "load_trajectory",
           "wilson_interval"]
