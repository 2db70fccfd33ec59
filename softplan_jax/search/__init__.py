"""The global fallback, for where the local planner of paper eq. (9) stops short: reachability of
the goal (:mod:`._reach`: multi-start IK, with proofs of unreachability where it has one);
RRT-Connect over certified straight motions, with shortcuts, smoothing and a densified path
(:mod:`._tree`; its motions :mod:`._motions`; the whole search one loop with one exact solve per
iteration, :mod:`._machine`); :func:`plan_fallback` (:mod:`._fallback`: the local planner first,
then the two above for every scene it left stalled); and :func:`track_fallback` (:mod:`._tracking`:
the tracker among moving obstacles, then, where it never reaches the goal, a run guided by the
search's path at rest)."""

from ._fallback import plan_fallback
from ._reach import REACH_REASONS, Reachability, ReachOptions, reachability
from ._tracking import track_fallback

__all__ = ["ReachOptions", "Reachability", "REACH_REASONS", "reachability", "plan_fallback", "track_fallback"]
