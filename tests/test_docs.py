"""What a library user expects besides the code: an API reference rendered from
the docstrings (the documentation site, mkdocs.yml) that covers every public
name, a LICENSE matching pyproject.toml, a CITATION.cff citing the paper and the
library, and file formats documented by examples that load.

Pure Python: nothing here needs mkdocs (CI builds the site with
``mkdocs build --strict``, where a broken link or reference fails)."""

from __future__ import annotations

import importlib
import inspect
import json
import pkgutil
import re
from pathlib import Path

import numpy as np
import pytest

import softplan_jax as sp

ROOT = Path(__file__).resolve().parent.parent
API_DIR = ROOT / "docs" / "api"
FORMATS_PAGE = ROOT / "docs" / "file-formats.md"  # the scenario and gains file formats, with one example each


def _pyproject_field(name):
    m = re.search(rf'^{name}\s*=\s*(.+)$', (ROOT / "pyproject.toml").read_text(), re.M)
    assert m, name
    return m.group(1).strip()


def _public_units():
    """The modules whose ``__all__`` make up the public API, by dotted name: the top level,
    ``softplan_jax.moving``, and every sub-package with an ``__all__`` of its own names; a
    sub-package whose ``__all__`` is empty or lists only modules (``base``, ``testing``)
    stands for its public modules instead."""
    units = ["softplan_jax", "softplan_jax.moving"]

    def walk(name):
        mod = importlib.import_module(name)
        names = getattr(mod, "__all__", None)
        if names and not all(inspect.ismodule(getattr(mod, n)) for n in names):
            units.append(name)
        elif hasattr(mod, "__path__"):
            for info in pkgutil.iter_modules(mod.__path__):
                if not info.name.startswith("_"):
                    walk(f"{name}.{info.name}")
        elif names is not None:
            units.append(name)

    for info in pkgutil.iter_modules(sp.__path__):
        if info.ispkg:
            walk(f"softplan_jax.{info.name}")
    return units


def _own_doc(obj):
    """The object's own docstring, or None: a NamedTuple's generated ``Name(a, b)`` does not count."""
    if inspect.isclass(obj):
        doc = obj.__dict__.get("__doc__")
        if doc and getattr(obj, "_fields", None) is not None and doc.startswith(f"{obj.__name__}("):
            doc = None
    else:
        doc = getattr(obj, "__doc__", None)
    return doc if doc and doc.strip() else None


# Every public function and class has a docstring of its own, except in the two internal layers,
# where some helpers are described by their module's docstring only (the reference shows that).
DOCSTRING_EXEMPT = ("base.", "testing.")


def test_every_public_name_has_a_docstring():
    missing = []
    for unit in _public_units():
        if unit.removeprefix("softplan_jax.").startswith(DOCSTRING_EXEMPT):
            continue
        mod = importlib.import_module(unit)
        assert (mod.__doc__ or "").strip(), f"{unit} has no module docstring"
        for name in mod.__all__:
            obj = getattr(mod, name)
            if (inspect.isclass(obj) or callable(obj)) and not inspect.ismodule(obj) and _own_doc(obj) is None:
                missing.append(f"{unit}.{name}")
    assert missing == [], f"public names without a docstring of their own: {missing}"


def _directives():
    """``{target: options text}`` of every ``::: target`` directive of the API pages."""
    found = {}
    for page in sorted(API_DIR.glob("*.md")):
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"^::: (\S+)\n((?:[ \t]+\S.*\n)*)", text + "\n", re.M):
            found[m.group(1)] = m.group(2)
    return found


def test_api_reference_covers_every_public_name():
    """Every public name is rendered by an API page: the page has a directive for its module
    (which renders the module's ``__all__``, unless its options restrict ``members``) or for
    the name itself; and every API page is in the site's navigation."""
    directives = _directives()
    assert "softplan_jax" in directives, "docs/api has no page for the top level"
    uncovered = []
    for unit in _public_units():
        mod = importlib.import_module(unit)
        options = directives.get(unit)
        restricted = options is not None and re.search(r"^\s*members:", options, re.M)
        for name in mod.__all__:
            if name == "__version__":
                continue
            if f"{unit}.{name}" in directives:
                continue
            if options is None or (restricted and not re.search(rf"^\s*- {re.escape(name)}$", options, re.M)):
                uncovered.append(f"{unit}.{name}")
    assert uncovered == [], f"public names missing from the API pages (docs/api/*.md): {uncovered}"
    for target in directives:  # a directive names something that exists
        module, _, attr = target.rpartition(".")
        try:
            importlib.import_module(target)
        except ModuleNotFoundError:
            assert hasattr(importlib.import_module(module), attr), f"docs/api: ::: {target} does not exist"
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in API_DIR.glob("*.md"):
        assert f"api/{page.name}" in nav, f"docs/api/{page.name} is not in mkdocs.yml's nav"


# Where the repository and the documentation site would be published: not yet, so no page,
# metadata or notebook may send a reader there.
UNPUBLISHED = ("softplan-jax.github.io", "github.com/softplan-jax", "colab.research.google.com/github")


def test_docs_extra_and_no_link_to_an_unpublished_location():
    """`pip install -e ".[docs]"` brings the site's tools; pyproject.toml, mkdocs.yml, the README,
    the docs pages and the notebooks name no repository or site that is not published (the
    README says how to build the site instead)."""
    import tomllib

    with open(ROOT / "pyproject.toml", "rb") as fh:
        project = tomllib.load(fh)["project"]
    docs = " ".join(project["optional-dependencies"]["docs"])
    for tool in ("mkdocs>=", "mkdocs-material>=", "mkdocstrings[python]>=", "mkdocs-jupyter>="):
        assert tool in docs, tool
    assert "urls" not in project, "pyproject.toml names [project.urls]: are they published?"
    mkdocs_yml = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert not re.search(r"^(site_url|repo_url):", mkdocs_yml, re.M)
    files = [ROOT / "README.md", ROOT / "CITATION.cff", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "notebooks").glob("*.ipynb"))]
    for path in files:
        text = path.read_text(encoding="utf-8")
        for where in UNPUBLISHED:
            assert where not in text, f"{path.name} links to {where}, which is not published"
    assert "mkdocs serve" in (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_is_a_front_door():
    """The README stays short, keeps the two commands for a fresh machine, and cites the paper
    by its reference, not by a path the user does not have."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    assert 'pip install -e ".[dev]" && python -m pytest -q' in text
    assert "softplan run tree" in text
    assert "Efficient Path Planning of Soft Robotic Arms in the Presence of Obstacles" in text
    assert "../shared" not in text and "paper.md" not in text


def test_license_matches_pyproject():
    assert '"MIT"' in _pyproject_field("license")
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License")
    assert "Copyright (c) 2026 softplan_jax developers" in text


def test_citation_cites_the_paper_and_the_library():
    cff = (ROOT / "CITATION.cff").read_text()
    assert re.search(r"^cff-version: 1\.2\.0$", cff, re.M)
    version = _pyproject_field("version").strip('"')
    assert re.search(rf"^version: {re.escape(version)}$", cff, re.M), "CITATION.cff version != pyproject.toml"
    assert re.search(r"^license: MIT$", cff, re.M)
    assert "preferred-citation:" in cff
    assert 'title: "Efficient Path Planning of Soft Robotic Arms in the Presence of Obstacles"' in cff


def _docs_json(fmt):
    """The JSON blocks of one file format (``softplan-scenario/1``, ``softplan-gains/1``) on the
    documentation's file-format page."""
    text = FORMATS_PAGE.read_text(encoding="utf-8")
    return [b for b in re.findall(r"```json\n(.*?)```", text, re.S) if f'"format": "{fmt}"' in b]


def _docs_scenario(tmp_path):
    blocks = _docs_json("softplan-scenario/1")
    assert len(blocks) == 1, f"expected one JSON scenario in {FORMATS_PAGE.name}"
    path = tmp_path / "docs_scene.json"
    path.write_text(blocks[0])
    return path


def test_docs_scenario_loads(tmp_path):
    scenario = sp.load_scenario(_docs_scenario(tmp_path))
    assert int(scenario.curve_mask.sum()) == 2 and bool(scenario.point_mask.any())  # 2 curves, 1 point set


def test_docs_gains_file_loads(tmp_path):
    blocks = _docs_json("softplan-gains/1")
    assert len(blocks) == 1, f"expected one JSON gains file in {FORMATS_PAGE.name}"
    path = tmp_path / "docs_gains.json"
    path.write_text(blocks[0])
    gains = sp.load_gains(path, method="points", n_points=10)
    assert isinstance(gains, sp.Gains) and float(gains.d0) == 0.3


def test_docs_timed_trajectory_loads(tmp_path):
    """The timed trajectory example (JSON) loads; its samples are within its limits."""
    blocks = _docs_json("softplan-timed-trajectory/1")
    assert len(blocks) == 1, f"expected one timed trajectory in {FORMATS_PAGE.name}"
    path = tmp_path / "docs_timed.json"
    path.write_text(blocks[0])
    traj = sp.load_trajectory(path)
    assert traj.layout.kind == "tendon" and traj.t.shape == (3,) and traj.lengths.shape == (3, 1, 3)
    assert traj.report.ok and traj.path == "linear" and traj.duration == 1.500002
    # The example's lengths are those of its configurations.
    lengths = np.stack([np.asarray(sp.actuators.actuator_lengths(q, traj.layout)) for q in traj.q])
    np.testing.assert_allclose(lengths, traj.lengths, atol=1e-5)


@pytest.mark.slow  # compiles a rollout for the documented scene's own shape (~30 s)
def test_docs_scenario_reaches_its_goal_with_the_defaults(tmp_path, capsys):
    from softplan_jax.cli import main

    code = main(["run", str(_docs_scenario(tmp_path)), "--json", "--require-reached"])
    out = capsys.readouterr().out
    assert code == 0, out
    summary = json.loads(out)
    assert summary["status"] == "reached" and not summary["collided"], summary


@pytest.mark.slow  # compiles the quick start's rollouts (the curve and N-point plans, the fallback)
def test_readme_python_block_runs_as_a_script(tmp_path):
    """The README's Python quick start, copied into a file and run by this interpreter as a
    new user would (this checkout's package), ends without error and prints its last line."""
    import subprocess
    import sys

    from session import subprocess_env

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1, "expected one Python block in the README"
    script = tmp_path / "quickstart.py"
    script.write_text(blocks[0], encoding="utf-8")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=subprocess_env(), capture_output=True,
                          text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    status, iterations, clearance, planner = proc.stdout.split()[-4:]
    assert status in sp.planning.STATUS_NAMES.values() and int(iterations) > 0 and float(clearance) > 0
    assert planner in ("local", "global")
