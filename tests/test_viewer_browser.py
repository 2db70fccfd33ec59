"""The view in a real browser: a headless Chromium (the system's, Debian's ``chromium``, driven
by Playwright; never a downloaded one) opens ``sp.view("tree")``, the test waits for the scene,
moves the goal through the server's API, and checks that the browser received the new arm (the
mesh updates the page's websocket worker handed to the page, vertex for vertex the server's
meshes of the new plan's last step), that its panel shows the new plan, that a drag sent over a
websocket as the page sends it replans, and that screenshots are not blank and change.

Skipped, with the reason, where Playwright or Chromium cannot be had (.ci/run installs both
where it can).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("viser", reason="the viewer extra (viser) is not installed: pip install '.[viewer]'")
pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (the dev extra: pip install '.[dev]')")

from softplan_jax.viewer import view  # noqa: E402
from softplan_jax.viewer._capture import HeadlessBrowser, find_chromium  # noqa: E402

pytestmark = pytest.mark.slow  # a browser, a page and a plan: tens of seconds

if find_chromium() is None:
    pytest.skip("no Chromium on this machine (Debian: apt-get install chromium; .ci/run installs it where it can)",
                allow_module_level=True)


def _arm(browser, n_segments, since=0):
    """The last vertices each arm segment received in the page from batch ``since`` on: {i: (V, 3)}."""
    out = {}
    for i in range(n_segments):
        got = browser.received(f"/arm/segment_{i}", "vertices", since)
        if got:
            out[i] = np.asarray(got[-1], np.float32).reshape(-1, 3)
    return out


def _wait(predicate, timeout, what):
    deadline = time.time() + timeout
    while not predicate():
        if time.time() > deadline:
            raise AssertionError(f"{what}: not within {timeout} s")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def served():
    v = view("tree", port=0, max_steps=200)
    assert v.wait_idle(600), "the first plan did not finish"
    yield v
    v.stop()


@pytest.fixture(scope="module")
def browser(served):
    try:
        b = HeadlessBrowser(width=960, height=640).__enter__()
    except RuntimeError as err:
        pytest.skip(f"Chromium does not start here: {err}")
    yield b
    b.__exit__(None, None, None)


def test_the_browser_gets_the_scene_and_then_the_new_arm(served, browser):
    n = served.planner.scene.n_segments
    browser.open(served.url)
    _wait(lambda: len(_arm(browser, n)) == n, 60, "the arm's meshes in the page")
    _wait(lambda: "plan 1" in browser.page.text_content("body"), 60, "the panel in the page")
    for i, verts in _arm(browser, n).items():  # the first plan's last step
        np.testing.assert_array_equal(verts, served.arm_vertices[i])
    time.sleep(2.0)  # a few frames drawn
    before = browser.screenshot()
    assert before.std() > 10 and len(np.unique(before.reshape(-1, 3), axis=0)) > 100, "a blank page"

    seen = browser.batches()
    goal = served.planner.goal + np.array([0.0, 0.05, 0.0])
    served.set_goal(goal)  # the server's API: as a drag does
    assert served.wait_idle(120) and served.shown.status == "reached"
    _wait(lambda: f"plan {served.plans}" in browser.page.text_content("body"), 60, "the new plan in the panel")
    received = _arm(browser, n, seen)
    assert len(received) == n, "the new arm's meshes did not reach the page"
    for i in range(n):
        np.testing.assert_array_equal(received[i], served.arm_vertices[i])  # what the server drew, to the bit
    tip = received[n - 1][-1]  # the last segment's end cap centre: the new tip, at the new goal
    assert np.linalg.norm(tip - goal) < 0.011
    assert f"iterations: {served.shown.iterations}" in browser.page.text_content("body")
    time.sleep(2.0)
    after = browser.screenshot()
    assert after.std() > 10
    assert np.mean(np.any(after != before, axis=-1)) > 1e-3, "the picture did not change"


def test_a_drag_from_the_page_replans(served, browser):
    """The goal handle's update sent over a websocket as the page sends it: the server replans
    and the page shows each new plan."""
    plans = served.plans
    goals = served.planner.goal + np.array([[0.0, 0.01, 0.0], [0.0, 0.02, 0.0]])
    times = browser.drag(served.url, goals)
    assert times.shape == (2, 4) and np.all(np.diff(times[:, 1:], axis=1) >= 0) and np.all(times > 0)
    assert served.wait_idle(60) and served.plans == plans + 2
    np.testing.assert_allclose(served.shown.goal[-1], goals[-1])


def test_served_from_a_jupyter_kernel(browser, tmp_path):
    """In Jupyter: ``sp.view`` in a kernel serves and returns; the page (here the headless
    browser, as a tab or the notebook's IFrame would) gets the scene and the panel, and the
    IFrame cell's HTML points at the view."""
    import json
    import sys

    pytest.importorskip("ipykernel", reason="ipykernel is not installed (the dev extra)")
    from jupyter_client import KernelManager
    from jupyter_client.kernelspec import KernelSpecManager
    from session import subprocess_env

    spec = tmp_path / "softplan-viewer-kernel"
    spec.mkdir()
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"], "language": "python",
        "display_name": "softplan viewer test", "env": {k: v for k, v in subprocess_env().items()
                                                        if k == "PYTHONPATH" or k.startswith("JAX_")}}))
    km = KernelManager(kernel_name="softplan-viewer-kernel", kernel_spec_manager=KernelSpecManager(
        kernel_dirs=[str(tmp_path)]))
    km.start_kernel()
    kc = km.client()
    try:
        kc.start_channels()
        kc.wait_for_ready(timeout=120)
        outputs = []

        def run(code):
            reply = kc.execute_interactive(code, timeout=600, output_hook=lambda m: outputs.append(m["content"]))
            assert reply["content"]["status"] == "ok", reply["content"]

        run("import softplan_jax as sp\nv = sp.view('tree', port=0, max_steps=200)\nassert v.wait_idle(600)")
        run("print('URL', v.url)")
        url = next(o["text"].split("URL ", 1)[1].split()[0] for o in outputs if "URL " in o.get("text", ""))
        run(f"from IPython.display import IFrame\nIFrame({url!r}, width='100%', height=600)")
        assert any(url in str(o.get("data", {}).get("text/html", "")) for o in outputs)
        browser.open(url)  # the module's browser (one Playwright per thread), on the kernel's view now
        _wait(lambda: len(_arm(browser, 3)) == 3 and "plan 1" in browser.page.text_content("body"), 60,
              "the kernel's view")
        run("v.stop()")
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)
