"""The declared public surface: ``softplan_jax.__all__`` is exactly the list
below (a change to the public API must change this test too), every public
name is documented, every module declares ``__all__``, and no module imports
another module's private (underscore) names.

Pure Python and AST checks: no compilation, well under a second.
"""

import ast
import importlib
import json
import os
import pkgutil
import subprocess
import sys

import pytest
from session import REPO, subprocess_env

import softplan_jax as sp

PUBLIC = [
    # kinematics (paper section 2.1)
    "segment_transform", "segment_frames", "segment_point", "tip_position", "point_jacobian",
    "tip_jacobian", "backbone_points", "motion_bound",
    # obstacle curves and point clouds
    "PolynomialCurve", "ParametricCurve", "line_segment", "stack_curves", "curve_points",
    "fit_polynomial_curve", "CurveFit", "CloudFit", "FitWarning", "fit_curve", "fit_curves",
    "curve_distance", "load_cloud", "save_fit_scenario",
    # closest points (paper section 2.3)
    "ClosestPoint", "SolverOptions", "GridSolverOptions", "closest_point", "closest_point_to_points", "point_distance",
    # scenarios
    "Scenario", "default_start", "make_scenario", "stack_scenarios", "scenario_warnings",
    "paper_scenario", "random_scenarios", "load_scenario", "save_scenario", "scenario_from_dict",
    "scenario_to_dict",
    # planner (paper eq. 9)
    "Gains", "GainFunction", "default_gains", "attraction", "repulsion", "PlanOptions", "make_options", "PAPER_STEP",
    "planner_step", "Status", "STATUS_NAMES", "status_name", "Rollout", "rollout", "rollout_jit",
    "rollout_batch", "PlanResult", "result_from_rollout", "plan", "plan_batch",
    # reachability and the global fallback
    "ReachOptions", "Reachability", "REACH_REASONS", "reachability", "plan_fallback",
    # moving obstacles and moving goals
    "CurveMotion", "GoalPath", "MovingScenario", "curve_motion", "goal_path", "make_moving_scenario",
    "stack_moving_scenarios", "scenario_at", "goal_at", "speed_bounds", "MOVING_SCENARIOS", "moving_scenario",
    "random_moving_scenarios", "TrackOptions", "Track", "TrackResult", "track", "track_batch",
    # gain presets
    "Preset", "PRESETS", "preset", "apply_preset",
    # gains files
    "save_gains", "load_gains", "gains_to_dict", "gains_from_dict",
    # metrics
    "true_closest", "dense_trajectory_clearance", "apply_collision_checks",
    # tuning
    "LossWeights", "TuningResult", "rollout_loss", "batch_loss", "tune_gains",
    # tuning on the smoothed objective
    "GainSpace", "ScoreWeights", "rollout_score", "score_batch", "SmoothingSample", "smoothing_sample",
    "smoothed_objective", "ObjectiveEstimate", "estimate_objective", "TuneResult", "tune_smoothed",
    "enable_compilation_cache", "compilation_cache_dir",
    "__version__",
]

# The DESIGN.md contract: these names must never disappear.
CONTRACT = ["segment_point", "tip_position", "point_jacobian", "PolynomialCurve", "ParametricCurve",
            "closest_point", "closest_point_to_points", "make_scenario", "paper_scenario", "plan"]

PACKAGE_DIR = os.path.dirname(sp.__file__)


def _modules():
    """Every module of the package, by dotted name."""
    names = ["softplan_jax"]
    for info in pkgutil.walk_packages([PACKAGE_DIR], prefix="softplan_jax."):
        names.append(info.name)
    return names


def test_all_is_the_declared_list():
    assert len(set(sp.__all__)) == len(sp.__all__), "duplicate names in softplan_jax.__all__"
    missing = sorted(set(PUBLIC) - set(sp.__all__))
    extra = sorted(set(sp.__all__) - set(PUBLIC))
    assert not missing and not extra, f"__all__ changed: missing {missing}, new {extra} (update this test)"
    assert set(CONTRACT) <= set(sp.__all__)


def test_every_public_name_exists_and_is_documented():
    for name in sp.__all__:
        obj = getattr(sp, name)  # AttributeError names the culprit
        if callable(obj):
            assert (obj.__doc__ or "").strip(), f"softplan_jax.{name} has no docstring"
    # nothing public is left out of __all__ by accident
    undeclared = [n for n, v in vars(sp).items() if not n.startswith("_") and n not in sp.__all__
                  and not type(v).__name__ == "module"]
    assert undeclared == [], f"public names of softplan_jax outside __all__: {undeclared}"


@pytest.mark.parametrize("modname", _modules())
def test_module_declares_its_surface(modname):
    mod = importlib.import_module(modname)
    assert (mod.__doc__ or "").strip(), f"{modname} has no module docstring"
    if modname in ("softplan_jax.cli", "softplan_jax.__main__"):
        return  # the command: `main` is its interface
    assert hasattr(mod, "__all__"), f"{modname} has no __all__"
    for name in mod.__all__:
        assert hasattr(mod, name), f"{modname}.__all__ lists {name!r}, which does not exist"
        assert not name.startswith("_") or name == "__version__"


def _private_imports(path):
    """(line, text) of every `from <softplan module> import _name` and
    `softplan_jax.<mod>._name` attribute use in one Python source."""
    with open(path, encoding="utf-8") as fh:
        src = fh.read()
    return _private_imports_src(src, path)


def _private_imports_src(src, where):
    out = []
    tree = ast.parse(src, where)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            from_softplan = node.level > 0 or (node.module or "").startswith("softplan_jax")
            for alias in node.names:
                if from_softplan and alias.name.startswith("_") and alias.name != "__version__":
                    out.append((node.lineno, f"from {'.' * node.level}{node.module or ''} import {alias.name}"))
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            base = node.value
            chain = []
            while isinstance(base, ast.Attribute):
                chain.append(base.attr)
                base = base.value
            if isinstance(base, ast.Name) and base.id in ("sp", "softplan_jax") and chain:
                out.append((node.lineno, f"{base.id}.{'.'.join(reversed(chain))}.{node.attr}"))
    return out


def test_no_module_imports_private_names_of_another():
    bad = []
    for root in (PACKAGE_DIR, os.path.join(REPO, "benchmarks")):
        for dirpath, _, files in os.walk(root):
            for f in files:
                if f.endswith(".py"):
                    path = os.path.join(dirpath, f)
                    bad += [f"{os.path.relpath(path, REPO)}:{ln}: {txt}" for ln, txt in _private_imports(path)]
    nb_dir = os.path.join(REPO, "notebooks")
    for f in sorted(os.listdir(nb_dir)):
        if f.endswith(".ipynb"):
            with open(os.path.join(nb_dir, f), encoding="utf-8") as fh:
                cells = json.load(fh)["cells"]
            for k, cell in enumerate(cells):
                if cell["cell_type"] == "code":
                    src = "".join(cell["source"])
                    src = "\n".join(ln for ln in src.splitlines() if not ln.lstrip().startswith(("!", "%")))
                    bad += [f"notebooks/{f} cell {k}: {txt}" for _, txt in _private_imports_src(src, f)]
    assert bad == [], "private names used across modules:\n" + "\n".join(bad)


def test_the_checker_finds_private_imports():
    src = ("from .kinematics import _frames\nfrom softplan_jax.closest import _x as y\n"
           "import softplan_jax as sp\nsp.planner._f()\n")
    assert [ln for ln, _ in _private_imports_src(src, "x")] == [1, 2, 4]
    assert _private_imports_src("from .kinematics import frames\nsp.planner.f()\n", "x") == []


def test_import_is_light():
    """`import softplan_jax` pulls in neither matplotlib nor the notebook stack."""
    code = "import sys, softplan_jax; print(sorted(m for m in ('matplotlib', 'IPython', 'nbformat') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=subprocess_env(),
                         cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_every_subpackage_is_installed():
    """pyproject's package list names every package of the tree (a subpackage left out
    works in an editable install and is missing from a real one)."""
    import tomllib

    with open(os.path.join(REPO, "pyproject.toml"), "rb") as fh:
        listed = set(tomllib.load(fh)["tool"]["setuptools"]["packages"])
    found = {"softplan_jax"} | {info.name for info in pkgutil.walk_packages([PACKAGE_DIR], prefix="softplan_jax.")
                                if info.ispkg}
    assert listed == found, f"pyproject.toml packages {sorted(listed)} != packages in the tree {sorted(found)}"
