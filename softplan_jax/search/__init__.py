"""The global fallback: reachability of the goal, a certified tree search, and
:func:`plan_fallback`, which runs them where the local planner of eq. (9) stops short.

* :mod:`.reach` -- is a collision-free configuration with the tip on the goal
  there? (:func:`reachability`; proofs of unreachability where it has one);
* :mod:`.tree` -- RRT-Connect over certified straight motions (conservative
  advancement), shortcuts, smoothing, and the densified path; the motions are
  :mod:`.motions`, and :mod:`.machine` runs the whole search as one loop with one
  exact solve per iteration;
* :mod:`.fallback` -- :func:`plan_fallback`: the local planner first, then the
  two above for every scene it left stalled;
* :mod:`.tracking` -- :func:`track_fallback`: the tracker among moving obstacles,
  then, where it never reaches the goal, a run guided by the search's path at rest.
"""

from .fallback import plan_fallback
from .reach import REACH_REASONS, Reachability, ReachOptions, reachability
from .tracking import track_fallback

__all__ = ["ReachOptions", "Reachability", "REACH_REASONS", "reachability", "plan_fallback", "track_fallback"]
