"""The interactive 3-D view in the browser (viser, the optional extra ``viewer``: ``pip install
"softplan_jax[viewer]"``): :func:`view` serves a scene, replans warm as its goal is dragged, and
plays the plan with its closest points and clearance. Nothing here imports viser until a view
starts.

* :mod:`.launch` -- :func:`view`, the entry point (``sp.view``; ``softplan view SCENE``);
* :mod:`.app` -- :class:`Viewer`: the server, the replanning worker, the time slider and play;
* :mod:`.panel` -- the control panel; :mod:`.drawing` -- the scene's nodes;
* :mod:`.live` -- :class:`LivePlanner`, the model without a browser: the scene, its warm planner,
  the fallback, and what is drawn at each step;
* :mod:`.meshes` -- tubes along polylines and spheres (NumPy).
"""

from .app import Viewer
from .launch import view
from .live import LivePlanner, ShownPlan, shown_plan
from .meshes import sphere_mesh, tube_mesh

__all__ = ["view", "Viewer", "LivePlanner", "ShownPlan", "shown_plan", "tube_mesh", "sphere_mesh"]
