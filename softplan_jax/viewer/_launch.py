""":func:`view`: serve the interactive 3-D view of a scene in the browser (viser, the optional
extra ``viewer``). This module imports neither viser nor the view's modules until it is called,
so that ``import softplan_jax`` stays light and works without the extra."""

from __future__ import annotations

import sys

__all__ = ["EXTRA_HINT", "require_viser", "check_address", "view"]

EXTRA_HINT = "pip install 'softplan_jax[viewer]'"


def require_viser() -> None:
    """ImportError naming the extra to install when viser cannot be imported."""
    try:
        import viser  # noqa: F401
    except ImportError as err:
        raise ImportError(f"the 3-D view needs viser, the optional extra 'viewer': {EXTRA_HINT} ({err})") from None


def check_address(host, port) -> tuple[str, int]:
    """``(host, port)`` checked: a non-empty host name or address and a port 0..65535 (0: any
    free port). ValueError naming the bad one."""
    if not isinstance(host, str) or not host.strip():
        raise ValueError(f"host must be a host name or address, got {host!r}")
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ValueError(f"port must be an int in 0..65535, got {port!r}")
    return host.strip(), port


def _world(scene, dtype):
    """A Scenario or MovingScenario from a scene object or a preset's name (paper or moving)."""
    from ..scenarios import PAPER_SCENARIOS, Scenario, paper_scenario
    from ..scenarios._motion import MovingScenario
    from ..scenarios._moving import MOVING_OPTIONS, MOVING_SCENARIOS, moving_scenario

    if isinstance(scene, str):
        if scene in PAPER_SCENARIOS:
            return paper_scenario(scene, dtype=dtype), scene, {}
        if scene in MOVING_SCENARIOS:
            return moving_scenario(scene, dtype=dtype), scene, dict(MOVING_OPTIONS[scene])
        raise ValueError(f"unknown scene {scene!r}: give a Scenario, a MovingScenario or a preset "
                         f"({', '.join(sorted(PAPER_SCENARIOS) + sorted(MOVING_SCENARIOS))})")
    if isinstance(scene, (Scenario, MovingScenario)):
        return scene, "scene", {}
    raise ValueError(f"scene must be a Scenario, a MovingScenario or a preset's name, got {type(scene).__name__}")


def view(scene, result=None, *, method: str = "curve", n_points: int = 10, gains=None, max_steps: int = 600,
         seed=0, host: str = "127.0.0.1", port: int = 8080, share: bool = False, label: str | None = None,
         **options):
    """Serve an interactive 3-D view of a scene in the browser and print its address.

    The arm is a tube of its radius with its segment boundaries marked, the obstacles tubes along
    their curves (point sets spheres), the goal a handle to drag: every move of it replans, warm
    (the compiled rollout of :func:`~softplan_jax.plan` or :func:`~softplan_jax.track` is reused
    for a goal of the same shape). The panel shows the status, iterations and minimum clearance,
    offers the global fallback where the plan stopped short, a time slider and a play button, the
    obstacle model (curve or N points), and toggles for the exact closest points with their
    clearance segments and for the tip path. A moving scene's obstacles move with the slider.

    Args:
      scene: a :class:`~softplan_jax.Scenario`, a :class:`~softplan_jax.moving.MovingScenario`, or
        a preset's name ("tree", "sim1", "sim2", "tree_sway", "tree_fruit", "wire_sweep").
      result: a plan to show first: a :class:`~softplan_jax.PlanResult`, a
        :class:`~softplan_jax.planning._tracking.TrackResult` or a saved trajectory's record
        (:func:`softplan_jax.cli.trajectory.read_trajectory`); None: plan the scene's own goal.
      method, n_points, gains, max_steps, seed, **options: the planner's settings, as
        :func:`~softplan_jax.plan` (a moving scene: :func:`~softplan_jax.track`, whose
        TrackOptions ``options`` may also hold).
      host, port: the address served (default ``127.0.0.1:8080``, this machine only; ``0.0.0.0``:
        every interface); a port in use is skipped for the next free one, and the printed address
        says so.
      share: also ask viser's relay for a public URL (``request_share_url``: the way to reach a
        server on a remote kernel such as Colab's; traffic goes through viser's server).
      label: the scene's name in the panel.

    Returns:
      The :class:`~softplan_jax.viewer._app.Viewer`, serving in the background: ``.url``,
      ``.set_goal(goal)``, ``.wait()`` (a script: serve until Ctrl-C), ``.stop()``.

    Raises:
      ImportError: viser is not installed (the extra ``viewer``).
      ValueError: a bad scene, result, planner setting, host or port.
    """
    require_viser()
    host, port = check_address(host, port)
    import jax.numpy as jnp

    from ._app import Viewer
    from ._live import LivePlanner, shown_plan

    world, name, preset = _world(scene, jnp.result_type(float))
    planner = LivePlanner(world, method, n_points, gains, max_steps, seed, **{**preset, **options})
    shown = None
    if result is not None:
        goal = None if (isinstance(result, dict) or hasattr(result, "time")) else planner.goal
        shown = shown_plan(result, goal, source=result.get("path", "a saved trajectory")
                           if isinstance(result, dict) else "the plan given")
        if shown.q.ndim != 3 or shown.q.shape[1:] != (planner.scene.n_segments, 3):
            raise ValueError(f"result.q has shape {shown.q.shape}; this scene's arm needs (T, "
                             f"{planner.scene.n_segments}, 3)")
    viewer = Viewer(planner, shown, host=host, port=port, label=label or name)
    if viewer.port_in_use:
        print(f"softplan: port {port} is in use; serving on port {viewer.port} instead", file=sys.stderr, flush=True)
    print(f"softplan: the view of {label or name} is at {viewer.url}", flush=True)
    if share:
        url = viewer.server.request_share_url(verbose=False)
        print(f"softplan: public URL (viser's relay): {url}" if url else
              "softplan: no public URL: viser's relay could not be reached", flush=True)
    return viewer
