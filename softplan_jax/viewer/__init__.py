"""The interactive 3-D view in the browser (viser, the optional extra ``viewer``: ``pip install
"softplan_jax[viewer]"``): :func:`view` serves a scene, replans warm as its goal is dragged, and
plays the plan with its closest points and clearance. Nothing here imports viser until a view
starts.

* :mod:`._launch` -- :func:`view`, the entry point (``sp.view``; ``softplan view SCENE``);
* :mod:`._app` -- :class:`Viewer`: the server, the replanning worker, the time slider and play;
* :mod:`._panel` -- the control panel; :mod:`._drawing` -- the scene's nodes;
* :mod:`._live` -- :class:`LivePlanner`, the model without a browser: the scene, its warm planner,
  the fallback, and what is drawn at each step;
* :mod:`._meshes` -- tubes along polylines and spheres (NumPy).
"""

from ._app import Viewer
from ._launch import view
from ._live import LivePlanner, ShownPlan, shown_plan
from ._meshes import sphere_mesh, tube_mesh

__all__ = ["view", "Viewer", "LivePlanner", "ShownPlan", "shown_plan", "tube_mesh", "sphere_mesh"]
