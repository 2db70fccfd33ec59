"""What a library user expects besides the code: an API reference generated
from the docstrings and up to date, a LICENSE matching pyproject.toml, a
CITATION.cff citing the paper and the library."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

import softplan_jax as sp

ROOT = Path(__file__).resolve().parent.parent


def _build_api():
    spec = importlib.util.spec_from_file_location("build_api", ROOT / "docs" / "build_api.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _pyproject_field(name):
    m = re.search(rf'^{name}\s*=\s*(.+)$', (ROOT / "pyproject.toml").read_text(), re.M)
    assert m, name
    return m.group(1).strip()


def test_every_public_name_has_a_docstring():
    assert _build_api().missing_docstrings(sp) == []


def test_api_reference_is_up_to_date():
    build_api = _build_api()
    committed = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    assert build_api.render(sp) == committed, "docs/api.md is out of date: run `python docs/build_api.py`"
    for name in build_api.public_names(sp):
        assert f"`{name}" in committed, name


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


def _readme_json(fmt):
    """The README's JSON blocks of one file format (``softplan-scenario/1``, ``softplan-gains/1``)."""
    text = (ROOT / "README.md").read_text()
    return [b for b in re.findall(r"```json\n(.*?)```", text, re.S) if f'"format": "{fmt}"' in b]


def _readme_scenario(tmp_path):
    blocks = _readme_json("softplan-scenario/1")
    assert len(blocks) == 1, "expected one JSON scenario in the README"
    path = tmp_path / "readme_scene.json"
    path.write_text(blocks[0])
    return path


def test_readme_scenario_loads(tmp_path):
    scenario = sp.load_scenario(_readme_scenario(tmp_path))
    assert int(scenario.curve_mask.sum()) == 2 and bool(scenario.point_mask.any())  # 2 curves, 1 point set


def test_readme_gains_file_loads(tmp_path):
    blocks = _readme_json("softplan-gains/1")
    assert len(blocks) == 1, "expected one JSON gains file in the README"
    path = tmp_path / "readme_gains.json"
    path.write_text(blocks[0])
    gains = sp.load_gains(path, method="points", n_points=10)
    assert isinstance(gains, sp.Gains) and float(gains.d0) == 0.3


@pytest.mark.slow  # compiles a rollout for the README scene's own shape (~30 s)
def test_readme_scenario_reaches_its_goal_with_the_defaults(tmp_path, capsys):
    from softplan_jax.cli import main

    code = main(["run", str(_readme_scenario(tmp_path)), "--json", "--require-reached"])
    out = capsys.readouterr().out
    assert code == 0, out
    summary = json.loads(out)
    assert summary["status"] == "reached" and not summary["collided"], summary
