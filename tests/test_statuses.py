"""The status rule at the end of a rollout (planning/records.finish), on hand-made records:
"held" (left the goal and back within the hold tolerance at the end) against "lost", and the
start pose in collision as its own status. No rollout is compiled here.
"""

from __future__ import annotations

from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest

import softplan_jax as sp
from softplan_jax.base._status import Status, status_name
from softplan_jax.planning._records import finish, record_zeros
from softplan_jax.planning._tracking import make_track_options

HOLD = 0.02  # hold tolerance; goal tolerance 0.01


def _finish(world, options, errors=None, status=Status.RUNNING, iterations=None):
    T = 6
    rec = record_zeros(world, options, T + 1)
    if errors is not None:
        rec = rec._replace(error=jnp.asarray(errors + [errors[-1]] * (T + 1 - len(errors)), rec.q.dtype))
    end = len(errors) - 1 if iterations is None else iterations
    final = SimpleNamespace(iterations=jnp.asarray(end, jnp.int32), status=jnp.asarray(status, jnp.int32),
                            escapes=jnp.zeros((), jnp.int32))
    return finish(world, options, rec, final)


@pytest.fixture(scope="module")
def moving():
    return sp.moving_scenario("tree_fruit")


@pytest.mark.parametrize("errors,want", [
    ([0.5, 0.3, 0.005, 0.004, 0.01, 0.003], "reached"),  # reached, never left the hold tolerance
    ([0.5, 0.005, 0.05, 0.3, 0.01, 0.001], "held"),  # reached, left, back within it at the end
    ([0.5, 0.005, 0.05, 0.3, 0.2, 0.1], "lost"),  # reached, left, not back
    ([0.5, 0.005, 0.05, 0.019], "held"),  # back within the hold tolerance (not the goal tolerance)
    ([0.5, 0.4, 0.3, 0.2], "max_steps"),  # never reached
])
def test_tracking_status_at_the_end(moving, errors, want):
    r = _finish(moving, make_track_options(hold_tolerance=HOLD), errors)
    assert status_name(r.status) == want
    assert bool(r.reached) == (want != "max_steps")
    assert bool(r.held_to_end) == (want == "reached")


def test_a_collision_at_step_zero_is_the_start_pose(moving):
    opts = make_track_options(hold_tolerance=HOLD)
    r = _finish(moving, opts, [0.5], status=Status.COLLIDED, iterations=0)
    assert status_name(r.status) == "start_in_collision" and bool(r.collided) and not bool(r.reached)
    r = _finish(moving, opts, [0.5, 0.4, 0.3], status=Status.COLLIDED)
    assert status_name(r.status) == "collided" and bool(r.collided)
    scene = sp.paper_scenario("sim1")
    plan_opts = sp.make_options()
    r = _finish(scene, plan_opts, [0.5], status=Status.COLLIDED, iterations=0)
    assert status_name(r.status) == "start_in_collision" and bool(r.collided) and not bool(r.reached)
    r = _finish(scene, plan_opts, [0.5, 0.4], status=Status.COLLIDED)
    assert status_name(r.status) == "collided"


def test_status_codes_and_labels():
    assert Status.START_COLLIDED.label == "start_in_collision" and Status.HELD.label == "held"
    assert len(set(s.label for s in Status)) == len(Status)
    assert np.all([status_name(int(s)) == s.label for s in Status])


@pytest.mark.slow  # a tracking program of its own (~1 min of compilation)
def test_wire_sweep_ends_held_not_lost(capsys):
    """The preset that ended "lost" with a final tip error of 0.001: back on the goal at the end."""
    import json

    from softplan_jax.cli import main

    code = main(["run", "wire_sweep", "--json", "--require-reached"])
    s = json.loads(capsys.readouterr().out)
    assert s["final_error"] <= s["hold_tolerance"]
    assert s["status"] in ("reached", "held") and code == 0, s
