"""Sweeps at scale: the planner over a seeded random suite of any size, in
constant memory, streamed to disk chunk by chunk, resumable, with the global
fallback where asked.

* :mod:`.runner` -- :func:`sweep` (the chunk loop), and the suite it plans:
  :func:`sweep_scenarios` and :func:`sweep_keys` (scene ``i`` depends on the seed
  and ``i`` only, so every sweep with the same seed starts with the same scenes);
* :mod:`.store` -- the sweep folder: the header, per-chunk CSV tables written
  atomically, the merged table, trajectory shards, :func:`read_table`,
  :func:`load_trajectory` and :func:`wilson_interval`;
* :mod:`.processes` -- one sweep on several processes (``jax.distributed``): the
  chunks shared out, the processes' meetings;
* :mod:`.report` -- progress lines and the summary.
"""

from .runner import SCENE_BLOCK, sweep, sweep_keys, sweep_scenarios
from .store import load_trajectory, read_table, wilson_interval

__all__ = ["sweep", "sweep_scenarios", "sweep_keys", "SCENE_BLOCK", "read_table", "load_trajectory",
           "wilson_interval"]
