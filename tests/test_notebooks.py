"""The notebooks run top to bottom in a fresh Jupyter kernel. Their first cell
is the title; the next is the Colab install cell, harmless anywhere else: on
Colab it installs from ``REPO_URL``, the repository that pyproject.toml names
(``[project.urls] Repository``, written into the notebooks, with an "Open in
Colab" link, by ``notebooks/colab_links.py``), or, since the repository is not
published and pyproject.toml names none, from the location the user writes there.

The kernel is this interpreter (``sys.executable -m ipykernel_launcher``),
described by a kernel spec written to a temporary directory, so that a user's
own ``python3`` kernel spec (which may point to another Python) is never used.
If no kernel can be started the tests FAIL: a notebook that was not run is not
a notebook that works.

The notebooks are executed in the default run, at small sizes: each has one
code cell tagged ``parameters`` (the sizes a Colab user can enlarge), and the
test executes a copy whose parameter cell is replaced by ``SMALL[name]`` (the
same names, smaller values). The committed notebooks keep their full-size
outputs. Nearly all of the time is XLA compilation inside the kernel, which
shares the suite's persistent compilation cache (``session.py``), so a rerun
is much faster than the first run (minutes on a 2-core CPU, most of it compilation).
"""

import ast
import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import nbformat
import pytest
from session import subprocess_env

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = ["quickstart.ipynb", "tuning.ipynb", "point_clouds.ipynb"]
CELL_TIMEOUT = 900  # seconds per cell; a compilation takes 15-150 s on a 2-core CPU
KERNEL_START_TIMEOUT = 120

# The parameter cells' small values for the test run (same names as the notebooks' own).
SMALL = {
    # MAX_STEPS = 200 and N = 10 on the padded tree: the rollouts test_planner.py compiles.
    "quickstart.ipynb": "MAX_STEPS = 200\nN_POINTS = (10,)\n",
    # Small shapes; the notebook's two GainSpaces (d0 and dt with stable_dt; the recipe's gain
    # function) compile their own programs of rollout scores, which TPE's trials share
    # (2 x PAIRS = N_TRAIN).
    "tuning.ipynb": ("N_TRAIN = 8\nUPDATES = 2\nPAIRS = 4\nSTEPS = 20\nSIGMA = (0.3, 0.7)\nN_EVAL = 16\n"
                     "EVAL_STEPS = 40\n"),
    "point_clouds.ipynb": "MAX_STEPS = 150\n",
}


def _read(name):
    path = NOTEBOOK_DIR / name
    assert path.is_file(), f"missing notebook {path}"
    return nbformat.read(path, as_version=4)


def _kernel_manager(spec_dir: Path):
    """An AsyncKernelManager for a kernel spec running THIS interpreter."""
    if importlib.util.find_spec("ipykernel") is None:
        pytest.fail(f"ipykernel is not installed for {sys.executable}: pip install -e '.[dev]'")
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import AsyncKernelManager

    kernel = spec_dir / "softplan-test-python"
    kernel.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "softplan test kernel",
        "language": "python",
        # this checkout's softplan_jax and the suite's persistent compilation cache
        "env": {k: v for k, v in subprocess_env().items() if k == "PYTHONPATH" or k.startswith("JAX_")},
    }
    (kernel / "kernel.json").write_text(json.dumps(spec))
    ksm = KernelSpecManager(kernel_dirs=[str(spec_dir)])
    return AsyncKernelManager(kernel_name="softplan-test-python", kernel_spec_manager=ksm)


def _parameter_cell(nb, name):
    """Index of the one code cell tagged ``parameters``."""
    tagged = [k for k, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", [])]
    assert len(tagged) == 1, f"{name}: need exactly one cell tagged 'parameters', found {len(tagged)}"
    assert nb.cells[tagged[0]].cell_type == "code", f"{name}: the parameter cell must be a code cell"
    return tagged[0]


def _assigned_names(src):
    return {t.id for node in ast.parse(src).body if isinstance(node, ast.Assign) for t in node.targets}


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_parameter_cell_matches_the_small_values(name):
    """The test's small values set exactly the names the notebook's parameter cell sets."""
    nb = _read(name)
    cell = nb.cells[_parameter_cell(nb, name)]
    assert _assigned_names(cell.source) == _assigned_names(SMALL[name]), (cell.source, SMALL[name])


@pytest.mark.slow  # a kernel per notebook (about 2.5 min of the default suite's time); CI's slow step runs them
@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs_top_to_bottom(name, tmp_path):
    """Executed top to bottom at small sizes (the parameter cell replaced by SMALL[name])."""
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError

    nb = _read(name)
    nb.cells[_parameter_cell(nb, name)].source = SMALL[name]
    work = tmp_path / "cwd"
    work.mkdir()
    km = _kernel_manager(tmp_path / "kernels")
    client = NotebookClient(
        nb,
        km=km,
        timeout=CELL_TIMEOUT,
        startup_timeout=KERNEL_START_TIMEOUT,
        allow_errors=False,
        record_timing=False,
        resources={"metadata": {"path": str(work)}},
    )
    t0 = time.perf_counter()
    try:
        client.execute(cleanup_kc=True)  # shut the kernel down even though we own km
    except CellExecutionError as err:
        pytest.fail(f"{name}: a cell raised:\n{err}")
    elapsed = time.perf_counter() - t0
    print(f"\n{name}: executed in {elapsed:.0f} s")
    for k, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        assert cell.execution_count is not None, f"{name}: cell {k} was not executed"
        errors = [o for o in cell.outputs if o.output_type == "error"]
        assert not errors, f"{name}: cell {k} produced an error output: {errors[0].get('ename')}"
    # The notebooks write only to temporary directories, never to the cwd.
    assert not any(work.iterdir()), f"{name} left files in its working directory: {sorted(work.iterdir())}"


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_committed_notebook_has_outputs(name):
    """Notebooks are committed executed (they read on GitHub), without errors."""
    nb = _read(name)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, f"{name} has no code cells"
    for k, cell in enumerate(code):
        assert cell.execution_count is not None, f"{name}: committed code cell {k} is not executed"
        errors = [o for o in cell.outputs if o.output_type == "error"]
        assert not errors, f"{name}: committed code cell {k} has an error output"
    assert any(o.output_type in ("stream", "display_data", "execute_result") for c in code for o in c.outputs)


def _install_cell(name):
    nb = _read(name)
    assert nb.cells[0].cell_type == "markdown", f"{name}: the first cell must be the title (with the Colab link)"
    first = next(c for c in nb.cells if c.cell_type == "code")  # the install cell, right below the title
    assert nb.cells.index(first) == 1, f"{name}: the install cell must follow the title cell"
    src = first.source
    lines = [line for line in src.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    assert lines[0].startswith("REPO_URL = "), f"{name}: the install cell must start by defining REPO_URL"
    for needle in ('"google.colab" in sys.modules', "pip", "install", "jax_enable_x64"):
        assert needle in src, f"{name}: the install cell does not contain {needle!r}"
    return src


# Runs a cell's source in a fresh interpreter. An audit hook records every
# process the cell starts; a pip command is refused (raises) so nothing is
# ever installed by the test.
_HARNESS = r"""
import json, sys, types
src, mode, out = sys.argv[1], sys.argv[2], sys.argv[3]
launched = []

class Refused(Exception):
    pass

def hook(event, args):
    if event in ("subprocess.Popen", "os.system", "os.exec", "os.posix_spawn", "os.spawn"):
        text = " ".join(map(str, args[1] if event == "subprocess.Popen" else args))
        launched.append(text)
        if "pip" in text:
            raise Refused(text)

if mode == "colab":
    sys.modules["google.colab"] = types.ModuleType("google.colab")
sys.addaudithook(hook)
result = {"launched": launched, "error": None}
try:
    ns = {}
    exec(compile(open(src).read(), "install-cell", "exec"), ns)
    import jax.numpy as jnp
    result["x64"] = str(jnp.zeros(()).dtype) == "float64"
except BaseException as err:
    result["error"] = f"{type(err).__name__}: {err}"
with open(out, "w") as fh:
    json.dump(result, fh)
"""


def _run_cell(src, mode, tmp_path):
    tmp_path.mkdir(parents=True, exist_ok=True)
    cell = tmp_path / "cell.py"
    cell.write_text(src)
    harness = tmp_path / "harness.py"
    harness.write_text(_HARNESS)
    out = tmp_path / "result.json"
    cwd = tmp_path / "cwd"
    cwd.mkdir(exist_ok=True)
    proc = subprocess.run(
        [sys.executable, str(harness), str(cell), mode, str(out)],
        cwd=cwd,
        env=subprocess_env(),  # this checkout's softplan_jax
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0 and out.exists(), f"harness failed:\n{proc.stdout}\n{proc.stderr}"
    assert not any(cwd.iterdir()), f"the install cell wrote files: {sorted(cwd.iterdir())}"
    return json.loads(out.read_text())


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_install_cell_is_harmless_outside_colab(name, tmp_path):
    src = _install_cell(name)
    result = _run_cell(src, "local", tmp_path)
    assert result["error"] is None, f"{name}: the install cell failed outside Colab: {result['error']}"
    launched = result["launched"]
    assert launched == [], f"{name}: the install cell started processes outside Colab: {launched}"
    assert result["x64"], f"{name}: the install cell did not enable float64"


def _pyproject_repository():
    """``[project.urls] Repository`` of pyproject.toml, "" when it names none (read here
    independently of notebooks/colab_links.py)."""
    import tomllib

    with open(NOTEBOOK_DIR.parent / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)["project"].get("urls", {}).get("Repository", "")


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_install_source_and_colab_link_follow_pyproject(name):
    """REPO_URL is the project's Repository URL, and the title cell links to the notebook on Colab
    when that is a GitHub repository; with none (not published), REPO_URL is empty and no link
    leads to a repository that does not exist."""
    repo = _pyproject_repository()
    src = _install_cell(name)
    assert src.splitlines()[0].startswith(f'REPO_URL = "{repo}"'), (
        f"{name}: REPO_URL is not pyproject.toml's Repository {repo!r}: run python notebooks/colab_links.py")
    title = _read(name).cells[0]
    assert title.cell_type == "markdown" and title.source.startswith("# "), f"{name}: cell 0 must be the title"
    if not repo:
        assert "colab.research.google.com" not in title.source, f"{name}: a Colab link to an unpublished repository"
        return
    owner_repo = repo.removeprefix("https://github.com/").removesuffix(".git").strip("/")
    link = f"https://colab.research.google.com/github/{owner_repo}/blob/main/notebooks/{name}"
    assert f"[![Open In Colab](https://colab.research.google.com/assets/colab-badge.svg)]({link})" in title.source, (
        f"{name}: no Open in Colab link to {link}: run python notebooks/colab_links.py")


def test_colab_links_tool_agrees():
    """notebooks/colab_links.py --check finds the notebooks in step (the tool and the test above agree)."""
    proc = subprocess.run([sys.executable, str(NOTEBOOK_DIR / "colab_links.py"), "--check"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_install_cell_installs_from_repo_url_on_colab(name, tmp_path):
    src = _install_cell(name)
    repo = _pyproject_repository()
    # As committed, no edit: pip install of exactly the project's repository, with this interpreter;
    # with none in the metadata (REPO_URL empty, not published), a clear error, nothing installed.
    result = _run_cell(src, "colab", tmp_path / "committed")
    if repo:
        assert len(result["launched"]) == 1, result
        assert result["launched"][0].endswith(f"git+{repo}"), result
    else:
        assert result["launched"] == [], result
        assert result["error"] and "REPO_URL" in result["error"] and "not published" in result["error"], result
    # A location written in: pip install of exactly that location (git for a URL, as it is for an upload).
    for k, (where, installed) in enumerate([("https://example.org/someone/softplan_jax",
                                             "git+https://example.org/someone/softplan_jax"),
                                            ("/content/softplan_jax-0.1.0-py3-none-any.whl",
                                             "/content/softplan_jax-0.1.0-py3-none-any.whl")]):
        edited = src.replace(src.splitlines()[0], f'REPO_URL = "{where}"', 1)
        result = _run_cell(edited, "colab", tmp_path / f"edited{k}")
        assert len(result["launched"]) == 1, result
        cmd = result["launched"][0]
        assert cmd.startswith(f"{sys.executable} -m pip install"), cmd
        assert cmd.endswith(f" {installed}"), cmd
        assert result["error"] and result["error"].startswith("Refused"), result
