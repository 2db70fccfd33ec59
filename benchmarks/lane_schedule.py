"""The rollout engine's lane schedule, replayed in plain Python (no jax): a benchmark helper.

:func:`replay` counts the loop steps :func:`softplan_jax.planning.engine.run_lanes` runs
for a batch whose scenes take known numbers of steps, idle lanes included, so that a
benchmark can predict a batch's time at any lane width from the cost of one lane's step
(``step_profile.py``). It imports nothing of the package, so tests import it in-process
(``_common`` turns the compilation cache off when imported).
"""

from __future__ import annotations

import collections


def replay(steps, lanes: int, quantum: int, chunk: int) -> int:
    """Loop steps :func:`~softplan_jax.planning.engine.run_lanes` runs for scenes taking
    ``steps`` (per scene, iterations + 1) at ``lanes`` lanes: its schedule in Python. A
    lane whose scene ends takes the next of the queue (the scenes not started, then the
    suspended), in lane order; a scene held ``quantum`` steps while others wait is
    suspended to the queue's tail; the loop stops at the end of the ``chunk`` of steps
    in which the last scene ended."""
    left = [int(x) for x in steps]
    L = min(lanes, len(left))
    queue = collections.deque(range(L, len(left)))
    lane, held = list(range(L)), [0] * L
    n = 0
    while any(s is not None for s in lane):
        n += 1
        for i, s in enumerate(lane):
            if s is not None:
                left[s] -= 1
                held[i] += 1
        spare = len(queue) - sum(1 for s in lane if s is not None and left[s] == 0)
        vacated = []
        for i, s in enumerate(lane):
            if s is None:
                continue
            if left[s] == 0:
                vacated.append(i)
            elif held[i] >= quantum and spare > 0:
                queue.append(s)
                spare -= 1
                vacated.append(i)
        for i in vacated:
            lane[i] = queue.popleft() if queue else None
            held[i] = 0
    return -(-n // chunk) * chunk
