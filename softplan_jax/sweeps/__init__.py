"""Sweeps at scale: the planner over a seeded random suite of any size, in constant memory,
streamed to disk chunk by chunk, resumable, with the global fallback where asked
(:mod:`.runner`: :func:`sweep` and its suite; :mod:`.chunks`: the chunk loop, shared with
``softplan batch``; :mod:`.store`: the sweep folder; :mod:`.processes`: several processes;
:mod:`.report`: progress and summary)."""

from .runner import SCENE_BLOCK, sweep, sweep_keys, sweep_scenarios
from .store import load_trajectory, read_table, wilson_interval

__all__ = ["sweep", "sweep_scenarios", "sweep_keys", "SCENE_BLOCK", "read_table", "load_trajectory",
           "wilson_interval"]
