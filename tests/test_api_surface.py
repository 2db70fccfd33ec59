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
    # scenes
    "Scenario", "make_scenario", "paper_scenario", "random_scenarios", "load_scenario", "save_scenario",
    # obstacles and the arm
    "PolynomialCurve", "ParametricCurve", "line_segment", "segment_point", "tip_position", "point_jacobian",
    "closest_point", "closest_point_to_points",
    # the loaded arm
    "RodModel", "loaded_backbone",
    # planning (paper eq. 9)
    "Gains", "GainFunction", "default_gains", "PAPER_STEP", "PlanOptions", "make_options", "PlanResult", "Status",
    "plan", "plan_batch", "plan_fallback",
    # moving goals and obstacles
    "moving_scenario", "make_moving_scenario", "track", "track_batch", "track_fallback",
    # actuators over time
    "Trajectory", "time_parametrize", "save_trajectory", "load_trajectory",
    # gains
    "apply_preset", "save_gains", "load_gains",
    # the interactive view in the browser
    "view",
    "enable_compilation_cache", "disable_compilation_cache", "__version__",
]

# The sub-namespaces (one per layer) and a name each that must be found there.
NAMESPACES = {
    "geometry": "motion_bound", "scenarios": "stack_scenarios", "clouds": "fit_curves", "planning": "rollout_jit",
    "search": "reachability", "sweeps": "sweep", "tuning": "tune_smoothed", "moving": "MovingScenario",
    "plotting": "plot_snapshots", "cli": "main", "actuators": "tendon_lengths", "trajectories": "time_parametrize",
    "rod": "loaded_pieces",
    "viewer": "view",
}

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


def _is_module(where, node, name) -> bool:
    """``from <node's package> import name`` imports a module (a namespace's private ``_module``
    file), not a private name of another module."""
    if node.level > 0:
        base = os.path.dirname(os.path.abspath(where))
        for _ in range(node.level - 1):
            base = os.path.dirname(base)
    elif (node.module or "").startswith("softplan_jax"):
        base = os.path.dirname(PACKAGE_DIR)
    else:
        return False
    parts = (node.module or "").split(".") if node.module else []
    return os.path.isfile(os.path.join(base, *parts, name + ".py"))


def _private_imports_src(src, where):
    out = []
    tree = ast.parse(src, where)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            from_softplan = node.level > 0 or (node.module or "").startswith("softplan_jax")
            for alias in node.names:
                if from_softplan and alias.name.startswith("_") and alias.name != "__version__" \
                        and not _is_module(where, node, alias.name):
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
    src = ("from .kinematics import _frames\nfrom softplan_jax.geometry._closest import _x as y\n"
           "import softplan_jax as sp\nsp.planner._f()\n")
    assert [ln for ln, _ in _private_imports_src(src, "x")] == [1, 2, 4]
    assert _private_imports_src("from .kinematics import frames\nsp.planner.f()\n", "x") == []


def test_import_is_light():
    """`import softplan_jax` pulls in neither matplotlib, the notebook stack, the viewer's viser nor
    SciPy (the point-cloud fitting's; ``sp.clouds`` imports on first use: about 0.2 s of every
    process that plans)."""
    code = ("import sys, softplan_jax; print(sorted(m for m in ('matplotlib', 'IPython', 'nbformat', 'viser', "
            "'playwright', 'scipy') if m in sys.modules))")
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


@pytest.mark.parametrize("space", sorted(NAMESPACES))
def test_sub_namespaces(space):
    """Each layer is a sub-namespace of the top level, with an ``__all__`` of its own."""
    mod = getattr(sp, space)
    assert NAMESPACES[space] in mod.__all__
    assert callable(getattr(mod, NAMESPACES[space])) or isinstance(getattr(mod, NAMESPACES[space]), type)


def test_import_adds_no_import_hook_and_dir_is_the_face():
    """Importing the package installs no import finder, and ``dir(sp)`` lists its public names,
    its sub-namespaces and nothing moved or deprecated."""
    code = ("import sys, jax, numpy, scipy, optax; before = list(sys.meta_path)\n"
            "import softplan_jax as sp\n"
            "assert sys.meta_path == before, sys.meta_path\n"
            "extra = [n for n in dir(sp) if not n.startswith('_') and n not in sp.__all__]\n"
            "print(sorted(extra))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=subprocess_env(),
                         cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    extra = set(ast.literal_eval(out.stdout.strip().splitlines()[-1]))
    assert extra <= set(NAMESPACES) | {"moving", "plotting", "cli", "base", "testing"}, extra


# ---------------------------------------------------------------------------------------------
# The house: folders by layer, every import pointing down, no loops, no module much over 500 lines.

# Layers from the top floor down; a module may import from its own layer or any layer below.
LAYERS = ["cli", "viewer", "plotting", "tuning", "sweeps", "trajectories", "search", "planning", "clouds", "scenarios",
          "actuators", "rod", "geometry", "base", "testing"]
TOP_LEVEL = {"softplan_jax", "softplan_jax.moving"}  # the faces, above every layer
MAX_LINES = 500


def _import_graph():
    """module -> the package modules it imports (read from the source, every import, lazy ones too)."""
    modules = {}
    for dirpath, _, files in os.walk(PACKAGE_DIR):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(dirpath, f)
                rel = os.path.relpath(path, os.path.dirname(PACKAGE_DIR))[:-3].replace(os.sep, ".")
                modules[rel.removesuffix(".__init__")] = path
    graph = {}
    for name, path in modules.items():
        is_pkg = path.endswith("__init__.py")
        with open(path, encoding="utf-8") as fh:
            tree = ast.parse(fh.read(), path)
        out = set()
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                # `from pkg import name`: the module pkg.name where it is one, else pkg itself
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            out |= {t for t in targets if t in modules and t != name}
        graph[name] = out
    return modules, graph


def _layer(module):
    parts = module.split(".")
    return None if module in TOP_LEVEL or len(parts) < 2 else parts[1]


def _cycles(graph):
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_loops():
    _, graph = _import_graph()
    assert _cycles(graph) == []


def test_the_loop_finder_finds_loops():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_every_import_points_down_a_layer():
    modules, graph = _import_graph()
    assert {_layer(m) for m in modules} - {None} == set(LAYERS), "a folder of the package is not in LAYERS"
    up = []
    for m, targets in graph.items():
        if _layer(m) is None:
            continue
        for t in targets:
            lt = _layer(t)
            if lt is None or LAYERS.index(lt) < LAYERS.index(_layer(m)):
                up.append(f"{m} -> {t}")
    assert up == [], "imports that point up a layer:\n" + "\n".join(sorted(up))


def test_no_module_is_much_over_500_lines():
    modules, _ = _import_graph()
    sizes = {m: sum(1 for _ in open(p, encoding="utf-8")) for m, p in modules.items()}
    big = {m: n for m, n in sizes.items() if n > MAX_LINES}
    assert big == {}, f"modules over {MAX_LINES} lines: {big}"


def test_the_oracle_stands_apart():
    """softplan_jax.testing (the independent reference of the tests and benchmarks) imports nothing
    of the package and not jax, and nothing of the package imports it."""
    modules, graph = _import_graph()
    for m, targets in graph.items():
        if _layer(m) == "testing":
            assert all(_layer(t) == "testing" for t in targets), f"{m} imports {targets}"
            with open(modules[m], encoding="utf-8") as fh:
                tree = ast.parse(fh.read())
            names = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            names |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
            assert "jax" not in names, f"{m} imports jax"
        else:
            assert not any(_layer(t) == "testing" for t in targets), f"{m} imports the oracle"
