"""Keep the notebooks' Colab install source and "Open in Colab" links in step with pyproject.toml.

The location the notebooks install softplan_jax from on Colab is the project's own
metadata, ``[project.urls] Repository`` in pyproject.toml; today it names none (the
repository is not published), so the notebooks ask the user for one. This script writes
it into each notebook:

* the install cell (the first code cell) starts with ``REPO_URL = "<Repository>"``, or
  ``REPO_URL = ""`` when pyproject.toml names none (the cell then stops on Colab with
  a message asking for a location pip can install from, and installs nothing);
* the title cell (the first cell, markdown) has an "Open in Colab" badge linking to
  ``https://colab.research.google.com/github/<owner>/<repo>/blob/main/notebooks/<name>``
  when the Repository is on GitHub (Colab opens notebooks from GitHub), and none otherwise.

Only those two lines change; outputs are kept. Needs nbformat (the ``dev`` extra)::

    python notebooks/colab_links.py            # rewrite them in every notebook
    python notebooks/colab_links.py --check    # exit 1 if a notebook is out of step
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
PYPROJECT = HERE.parent / "pyproject.toml"
NOTEBOOKS = ("quickstart.ipynb", "tuning.ipynb", "point_clouds.ipynb")
BRANCH = "main"
BADGE_IMAGE = "https://colab.research.google.com/assets/colab-badge.svg"
REPO_LINE = re.compile(r'^REPO_URL = "[^"\n]*"(?P<comment>[^\n]*)$', re.M)
BADGE_LINE = re.compile(r"^\[!\[Open In Colab\]\([^)]*\)\]\([^)]*\)\n\n?", re.M)
REPO_COMMENT = "  # pyproject.toml [project.urls] Repository"


def repository_url(pyproject: Path = PYPROJECT) -> str:
    """``[project.urls] Repository`` of pyproject.toml, or "" if it names none."""
    text = pyproject.read_text(encoding="utf-8")
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10: the one line this needs
        section = re.search(r"^\[project\.urls\]\n(.*?)(?=^\[|\Z)", text, re.M | re.S)
        match = section and re.search(r'^Repository\s*=\s*"([^"]*)"', section.group(1), re.M)
        return match.group(1).strip() if match else ""
    return str(tomllib.loads(text).get("project", {}).get("urls", {}).get("Repository", "")).strip()


def colab_url(repo_url: str, notebook: str) -> str | None:
    """The Colab link of ``notebooks/<notebook>`` in a GitHub repository, else None."""
    match = re.fullmatch(r"(?:git\+)?https://github\.com/([^/]+)/([^/]+?)(?:\.git)?/?", repo_url)
    if not match:
        return None
    owner, repo = match.groups()
    return f"https://colab.research.google.com/github/{owner}/{repo}/blob/{BRANCH}/notebooks/{notebook}"


def _synced(nb, name: str, repo_url: str) -> bool:
    """Write REPO_URL and the badge into the notebook (in memory); True if anything changed."""
    title, install = nb.cells[0], next(c for c in nb.cells if c.cell_type == "code")
    if not REPO_LINE.search(install.source):
        raise ValueError(f"{name}: the first code cell must be the install cell, starting with REPO_URL = ...")
    if title.cell_type != "markdown" or not title.source.startswith("# "):
        raise ValueError(f"{name}: the first cell must be the notebook's title (markdown, '# ...')")
    old = (install.source, title.source)
    install.source = REPO_LINE.sub(f'REPO_URL = "{repo_url}"{REPO_COMMENT}', install.source, count=1)
    source = BADGE_LINE.sub("", title.source)
    link = colab_url(repo_url, name)
    if link is not None:
        head, _, rest = source.partition("\n")  # the "# title" line, then the badge
        source = f"{head}\n\n[![Open In Colab]({BADGE_IMAGE})]({link})\n{rest}"
    title.source = source
    return (install.source, title.source) != old


def main(argv=None) -> int:
    import nbformat

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if a notebook is out of step")
    args = ap.parse_args(argv)
    repo_url = repository_url()
    if not repo_url:
        print("colab_links: pyproject.toml has no [project.urls] Repository: the notebooks' REPO_URL is left "
              "empty (on Colab their install cell asks for a location to install softplan_jax from) and they "
              "have no Open in Colab link", file=sys.stderr)
    stale = []
    for name in NOTEBOOKS:
        path = HERE / name
        nb = nbformat.read(path, as_version=4)
        if _synced(nb, name, repo_url):
            stale.append(name)
            if not args.check:
                nbformat.write(nb, path)
    if args.check and stale:
        print(f"colab_links: out of step with pyproject.toml: {', '.join(stale)} "
              "(run python notebooks/colab_links.py)", file=sys.stderr)
        return 1
    print(f"colab_links: {'checked' if args.check else 'updated'} {len(NOTEBOOKS)} notebooks; "
          f"{'changed ' + ', '.join(stale) if stale and not args.check else 'in step'}; REPO_URL {repo_url!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
