"""How long from dragging the goal in the browser view to the new plan drawn (``softplan view tree``)?

The view of the paper's tree (``sp.view("tree")``, 600 steps, the curve method, float64) is
opened in a headless Chromium (the system's, through Playwright; software WebGL: no GPU). The
goal is then dragged along an arc around branch 4 (radius 0.22 about its point (1, 0.7, 1.53),
in front of it, from below to above and back: every plan reaches), one drag after the last one's
plan was drawn, each sent over a websocket as the page sends a drag of the goal handle. For each
drag, after a few unmeasured ones (warm: nothing compiles):

* **server**: from the goal handle's callback to the new arm's meshes handed to viser and
  flushed (the plan's own time apart);
* **browser**: from the page sending the drag to (a) the batch of messages with the new arm
  arriving in the page, (b) the panel showing the new plan, (c) the second animation frame
  after it (the frame with the new arm drawn).

Medians and ranges per window size (the time to draw a frame depends on it: software WebGL),
with the drags back to back (a continuous drag: the page is still drawing the last plan when
the next drag goes out) and ``--pause`` seconds apart (separate drags); with ``--lighting``,
also lit as the view is not by default (shadows; viser's image-based environment map).

    python benchmarks/viewer_latency.py --lighting shadows,envmap  # ~6 min: 25 drags x 2 sizes x 2 pauses, + 2 lightings
    python benchmarks/viewer_latency.py --quick                  # 6 drags at one size
    python benchmarks/viewer_latency.py --pictures docs/images   # also the documentation's pictures (~5 min more)

Writes ``results/viewer_latency.{md,json}``; with ``--pictures DIR``: ``DIR/viewer_*.png`` and
``DIR/viewer_drag.gif`` (a drag around the branch, frames taken in the browser).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

BRANCH = (1.0, 0.7, 1.53)  # a point of branch 4 (X = 1, Y = 1 - u, Z = 1.5 + 0.1 u) above the tree's goal
RADIUS = 0.22


def arc(n: int, side: float = -1.0):
    """n goals on the arc around the branch, from below it to above it and back (side -1: in front)."""
    import numpy as np

    a = np.concatenate([np.linspace(0.0, np.pi, (n + 1) // 2), np.linspace(np.pi, 0.0, n // 2 + 1)[1:]])[:n]
    return np.asarray(BRANCH) + RADIUS * np.stack([side * np.sin(a), np.zeros_like(a), -np.cos(a)], -1)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--drags", type=int, default=25, help="measured drags per window size (default 25)")
    ap.add_argument("--warmup", type=int, default=3, help="drags before measuring (default 3)")
    ap.add_argument("--sizes", default="960x640,480x320", help="window sizes WxH (default 960x640,480x320)")
    ap.add_argument("--pause", type=float, default=0.5,
                    help="seconds between drags of the second run per size (default 0.5; the first: none)")
    ap.add_argument("--lighting", default="", metavar="V,V",
                    help="also measure the view lit otherwise, in the first window size with the pause: shadows "
                    "(the default lights casting shadows), envmap (viser's default image-based lighting and shadows)")
    ap.add_argument("--pictures", default=None, metavar="DIR", help="also write the documentation's pictures here")
    ap.add_argument("--quick", action="store_true", help="6 drags, one window size")
    ap.add_argument("--out", default=None, help="output prefix (default results/viewer_latency)")
    args = ap.parse_args(argv)
    if args.quick:
        args.drags, args.warmup, args.sizes = 6, 2, args.sizes.split(",")[0]
    try:
        args.sizes = [tuple(int(x) for x in s.lower().split("x")) for s in args.sizes.split(",")]
    except ValueError:
        ap.error(f"--sizes: write WxH[,WxH...], got {args.sizes!r}")
    args.lighting = [x for x in args.lighting.split(",") if x]
    if set(args.lighting) - {"shadows", "envmap"}:
        ap.error(f"--lighting: shadows or envmap, got {args.lighting}")
    if args.drags < 1 or args.warmup < 0 or args.pause <= 0 or any(len(s) != 2 or min(s) < 64 for s in args.sizes):
        ap.error("--drags >= 1, --warmup >= 0, --pause > 0, sizes at least 64x64")
    return args


def measure(viewer, size, drags: int, warmup: int, pause: float) -> dict:
    """One window size and pause: the drags' server and browser times (seconds)."""
    import numpy as np

    from softplan_jax.viewer._capture import HeadlessBrowser

    with HeadlessBrowser(width=size[0], height=size[1]) as browser:
        browser.open(viewer.url)
        deadline = time.time() + 120
        while f"plan {viewer.plans}" not in browser.page.text_content("body") and time.time() < deadline:
            time.sleep(0.1)
        goals = arc(warmup + drags)
        browser.drag(viewer.url, goals[:warmup], pause=pause)
        n0 = len(viewer.latencies)
        times = browser.drag(viewer.url, goals[warmup:], pause=pause)
        viewer.wait_idle(60)
        server = np.asarray(viewer.latencies[n0:])
        plan = np.asarray(viewer.plan_times[n0:])
    return dict(size=list(size), pause=pause, server=server.tolist(), plan=plan.tolist(),
                arm_batch=times[:, 0].tolist(), panel=times[:, 1].tolist(), frame1=times[:, 2].tolist(),
                frame2=times[:, 3].tolist())


def _row(name, xs):
    import numpy as np
    from _common import fmt_s

    xs = np.asarray(xs, float)
    return f"| {name} | {fmt_s(float(np.median(xs)))} | {fmt_s(float(xs.min()))} | {fmt_s(float(xs.max()))} |"


def report_md(report: dict, machine_lines) -> str:
    md = ["# Dragging the goal in the browser view: time to the new plan drawn", "",
          f"`python benchmarks/viewer_latency.py {report['argv']}` (the module docstring has the protocol): "
          "`sp.view(\"tree\")`, "
          f"{report['drags']} warm drags along an arc around branch 4, each sent over a websocket as the page "
          "sends a drag, in a headless Chromium with software WebGL (no GPU).", ""]
    md += machine_lines + [f"- chromium: {report['chromium']}; viser {report['viser']}", ""]
    for r in report["runs"]:
        how = "each drag as soon as the last plan was drawn" if not r["pause"] else \
            f"each drag {r['pause']:g} s after the last plan was drawn"
        md += [f"## Window {r['size'][0]} x {r['size'][1]}, {how}; {r['lighting']}", "",
               "| from the drag to | median | min | max |",
               "|---|---|---|---|", _row("server: the new arm's meshes flushed (callback to flush)", r["server"]),
               _row("&nbsp;&nbsp;of which the plan", r["plan"]),
               _row("browser: the batch with the new arm", r["arm_batch"]),
               _row("browser: the panel showing the new plan", r["panel"]),
               _row("browser: the next animation frame", r["frame1"]),
               _row("browser: the frame after it (the new arm drawn)", r["frame2"]), ""]
    return "\n".join(md) + "\n"


def pictures(folder: str) -> None:
    """The documentation's pictures: the tree, the closest points, a plan that stops short and its
    fallback, the N-point model, a moving scene, and a GIF of a drag around the branch."""
    import numpy as np
    from PIL import Image

    import softplan_jax as sp
    from softplan_jax.viewer._capture import HeadlessBrowser

    def closer(viewer):  # the camera of every page nearer the branch
        for client in viewer.server.get_clients().values():
            client.camera.look_at = (0.8, 0.55, 1.25)
            client.camera.position = (2.3, -1.6, 2.0)
        time.sleep(1.5)

    os.makedirs(folder, exist_ok=True)
    v = sp.view("tree", port=0)
    v.wait_idle(600)
    with HeadlessBrowser(width=1200, height=760) as b:
        b.open(v.url)
        time.sleep(3)
        b.screenshot(os.path.join(folder, "viewer_tree.png"))
        closer(v)
        frames = []
        for g in arc(24):
            b.drag(v.url, [g])
            time.sleep(0.3)
            frames.append(Image.fromarray(b.screenshot()).resize((720, 456), Image.LANCZOS))
        frames[0].save(os.path.join(folder, "viewer_drag.gif"), save_all=True, append_images=frames[1:],
                       duration=220, loop=0, optimize=True)
        v.set_goal(np.asarray(BRANCH) + RADIUS * np.array([-0.7, 0.0, -0.7]))
        v.wait_idle(120)
        v.panel.closest.value = True
        v.panel.slider.value = v.shown.iterations // 2
        time.sleep(2)
        b.screenshot(os.path.join(folder, "viewer_closest.png"))
        v.panel.closest.value = False
        v.set_goal(arc(13, side=1.0)[3])  # behind the branch: the local planner stops short
        v.wait_idle(120)
        time.sleep(2)
        b.screenshot(os.path.join(folder, "viewer_stopped.png"))
        v.fall_back()
        v.wait_idle(1800)
        time.sleep(2)
        b.screenshot(os.path.join(folder, "viewer_fallback.png"))
        v.set_goal(sp.paper_scenario("tree").goal)
        v.panel.method.value = "points"  # the N-point model (N = 10): its points on the curves
        v.wait_idle(600)
        time.sleep(2)
        b.screenshot(os.path.join(folder, "viewer_points.png"))
    v.stop()
    m = sp.view("tree_fruit", port=0, max_steps=300)
    m.wait_idle(1800)
    with HeadlessBrowser(width=1200, height=760) as b:
        b.open(m.url)
        m.panel.slider.value = m.shown.iterations // 3
        time.sleep(3)
        b.screenshot(os.path.join(folder, "viewer_moving.png"))
    m.stop()


def main(argv=None) -> dict:
    args = parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import viser
    from _common import finish_machine, log, machine_info, machine_lines, output_paths, write_results

    import softplan_jax as sp
    from softplan_jax.viewer._capture import find_chromium

    machine = machine_info("float64")
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium on this machine (Debian: apt-get install chromium)")
    v = sp.view("tree", port=0)
    v.wait_idle(600)
    runs = []
    for size in args.sizes:
        for pause in (0.0, args.pause):
            log(f"viewer_latency: {args.drags} drags in a {size[0]}x{size[1]} window, {pause:g} s apart ...")
            runs.append(dict(measure(v, size, args.drags, args.warmup, pause), lighting="lights, no shadows"))
    for lighting in args.lighting:
        log(f"viewer_latency: {args.drags} drags lit with {lighting} ...")
        v.server.scene.configure_default_lights(True, cast_shadow=True)
        if lighting == "envmap":
            v.server.scene.configure_environment_map("warehouse")
        label = {"shadows": "lights casting shadows", "envmap": "viser's environment map and shadows"}[lighting]
        runs.append(dict(measure(v, args.sizes[0], args.drags, args.warmup, args.pause), lighting=label))
    v.stop()
    finish_machine(machine)
    report = dict(argv=" ".join(argv if argv is not None else sys.argv[1:]), machine=machine, chromium=chromium,
                  viser=viser.__version__, drags=args.drags,
                  warmup=args.warmup, runs=runs)
    prefix, _ = output_paths("viewer_latency", args.quick, args.out)
    write_results(prefix, report, report_md(report, machine_lines(machine)))
    if args.pictures:
        log(f"viewer_latency: the pictures, into {args.pictures} ...")
        pictures(args.pictures)
    return report


if __name__ == "__main__":
    main()
