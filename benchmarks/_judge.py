"""The held-out part of ``baselines.py``: the suites ``save --suite N`` adds, with the
brute-force collision audits of the curve model, and ``judge BEFORE AFTER``, the statistical
comparison of two saves for a change that may alter results at rounding level.

The suites are held out: ``random_scenarios(HELD_OUT_SEED, N)`` and
``random_moving_scenarios(HELD_OUT_SEED, N)``, the seed of the held-out evaluations of
``science.py``, ``safe_step.py``, ``reach.py`` and ``evasion.py``; the default gains and the
tuning recipe were chosen on seeds 0 (training) and 2 (validation). The audits recompute the
clearance by brute force, independently of the planner's checks: the runs of each suite with
the smallest recorded clearance (``AUDITED``, ``AUDITED_MOVING``), the curve model's paper
runs and the moving presets (static scenes:
:func:`~softplan_jax.geometry._clearance.dense_trajectory_clearance`; moving scenes: the
oracle's ``moving_min_clearance``, the curves moved by SciPy).
"""

from __future__ import annotations

import os

import numpy as np
from _stats import paired_bootstrap, paired_table, pct_interval

HELD_OUT_SEED = 1
SUITE_STEPS = 600  # plan_batch's default
MOVING_STEPS = 300  # the moving suites of evasion.py and the documentation
CHUNK = 256  # scenes per plan_batch / track_batch call
AUDITED = 32  # runs of the static suite audited by brute force (quick: 2)
AUDITED_MOVING = 8  # runs of the moving suite (quick: 1), as evasion.py: SciPy's expm per curve and instant is slow
STATIC_BRUTE = dict(substeps=2, arm_samples=40, curve_samples=300)  # reach.py's audit of global paths
SUITE_FIELDS = ("status", "iterations", "reached", "collided", "min_clearance")
MODELS = (("curve10", "curve"), ("points10", "points"))

# The criteria a change of results is judged by (benchmarks/README.md, the judge's section).
MIN_SCENES = 1024  # held-out scenes of a judged suite
SUCCESS_POINTS = 0.5  # |success after - success before| in percentage points
ALPHA = 0.05  # McNemar's exact test: not significant at this level
ITERATIONS_RATIO = 0.02  # |mean iterations after / before - 1| on the scenes both reached
TREE = ("paper/tree/curve10/default", 53, 3)  # the tree, curve model, default gains: within 3 steps of 53


# ----------------------------------------------------------------------------
# save --suite N


def save_suite(out: dict, n: int, quick: bool, log) -> None:
    """Plan the held-out suites (both static models, the tracked moving suite) and audit the
    curve model's runs; their arrays into ``out``. ``log(message)`` reports progress."""
    import softplan_jax as sp

    out.update({"suite/seed": np.int64(HELD_OUT_SEED), "suite/max_steps": np.int64(SUITE_STEPS),
                "suite/moving_steps": np.int64(MOVING_STEPS)})
    suite = sp.random_scenarios(HELD_OUT_SEED, n)
    for label, method in MODELS:
        r = sp.plan_batch(suite, method, 10, max_steps=SUITE_STEPS, chunk=CHUNK, progress=True)
        _put(out, f"suite/{label}", r, SUITE_FIELDS)
        log(f"held-out suite, {label}: {int(np.sum(r.reached))} of {n} reached")
        if method == "curve":
            k = 2 if quick else AUDITED
            _audit(out, "audit/suite/curve10", r, k, lambda b, q: _static_brute(q, _take(suite, b)))
            log(f"held-out suite, {label}: the {k} closest runs audited")
    moving = sp.moving.random_moving_scenarios(HELD_OUT_SEED, n)
    t = sp.track_batch(moving, max_steps=MOVING_STEPS, chunk=CHUNK, progress=True)
    _put(out, "suite/moving", t, SUITE_FIELDS + ("held_to_end",))
    log(f"held-out moving suite: {int(np.sum(t.status == sp.Status.REACHED))} of {n} reached and held")
    k = 1 if quick else AUDITED_MOVING
    _audit(out, "audit/suite/moving", t, k, lambda b, q: _moving_brute(_take(moving, b), q, t.time[b], t.iterations[b]))
    log(f"held-out moving suite: the {k} closest runs audited")
    audit_recorded(out)
    log("paper runs and moving presets audited")


def audit_recorded(out: dict) -> None:
    """Brute-force audits of the curve model's paper runs and of the moving presets in ``out``
    (the PCC arm's: a loaded arm's shape is not q's arcs; its brute force is the slow tests')."""
    import softplan_jax as sp

    for k in sorted(out):
        group, field = k.rsplit("/", 1)
        parts = group.split("/")
        if field != "q" or parts[-1] == "loaded":
            continue
        if parts[0] == "paper" and parts[2].startswith("curve"):
            out[f"audit/{group}/brute_clearance"] = np.float64(_static_brute(out[k], sp.paper_scenario(parts[1])))
        elif parts[0] == "moving" and f"{group}/time" in out and out[k].ndim == 3:  # a preset, not the batch
            out[f"audit/{group}/brute_clearance"] = np.float64(_moving_brute(
                sp.moving_scenario(parts[1]), out[k], out[f"{group}/time"], out[f"{group}/iterations"]))


def _put(out, prefix, r, fields):
    for f in fields:
        out[f"{prefix}/{f}"] = np.asarray(getattr(r, f))


def _take(tree, b):
    import jax

    return jax.tree_util.tree_map(lambda x: x[b], tree)


def _audit(out, prefix, r, k, brute) -> None:
    """The brute force ``brute(b, q_b)`` of the ``k`` runs with the smallest recorded clearance."""
    order = np.argsort(np.asarray(r.min_clearance), kind="stable")[:k]
    out[f"{prefix}/scene"] = order.astype(np.int32)
    out[f"{prefix}/brute_clearance"] = np.array([brute(int(b), np.asarray(r.q[b])) for b in order], np.float64)


def _static_brute(q, scene) -> float:
    """The smallest clearance of a static scene's trajectory, sampled densely in space and time."""
    from softplan_jax.geometry._clearance import dense_trajectory_clearance

    return float(np.min(np.asarray(dense_trajectory_clearance(q, scene, **STATIC_BRUTE))))


def _moving_brute(moving, q, times, iterations) -> float:
    """The oracle's smallest clearance of a tracked run over its steps taken (the curves moved in time)."""
    from softplan_jax.testing import oracle

    scene = moving.scene
    real = np.flatnonzero(np.asarray(scene.curve_mask))
    motions = [{f: np.asarray(v[j]) for f, v in moving.motion._asdict().items()} for j in real]
    k = int(iterations) + 1
    return oracle.moving_min_clearance(
        np.asarray(q)[:k], np.asarray(times)[:k], np.asarray(scene.curves.coeffs)[real],
        np.asarray(scene.curves.u_range)[real], np.asarray(scene.curves.radius)[real], motions,
        float(scene.arm_radius))


# ----------------------------------------------------------------------------
# judge BEFORE AFTER


def verdict(a, b, min_scenes: int = MIN_SCENES) -> tuple[list, list]:
    """The judgement of save ``b`` (after) against save ``a`` (before), both ``np.load``-ed:
    ``(Markdown lines, checks)``, a check being ``(criterion, passed, detail)``."""
    checks, lines = [], []
    for section in (_success, _iterations, _collisions, _recorded, _fallback):
        lines += section(a, b, checks, min_scenes) + [""]
    return lines, checks


def verdict_table(checks) -> list:
    """The criteria and their results, as a Markdown table."""
    return ["| criterion | result | measured |", "|---|---|---|"] + [
        f"| {name} | {'PASS' if ok else '**FAIL**'} | {detail} |" for name, ok, detail in checks]


def _reached(d, key):
    from softplan_jax.base._status import Status

    return np.asarray(d[key]) == Status.REACHED


def _paired(a, b, key) -> str:
    """Why the suites of ``key`` in a and b are not the same scenes ("" if they are)."""
    if key not in a.files or key not in b.files:
        return "not recorded (save --suite 1024)"
    if a[key].shape != b[key].shape or any(k in a.files and k in b.files and a[k] != b[k]
                                           for k in ("suite/seed", "suite/max_steps", "suite/moving_steps")):
        return "not paired: the two saves planned different suites"
    return ""


def _success(a, b, checks, min_scenes) -> list:
    lines = ["## Success on the held-out suites (reached; moving: reached and held)", "",
             f"Paired on the same scenes; rates with 95 % Wilson intervals, the difference with a 95 % paired "
             f"bootstrap interval. Criterion: at least {min_scenes:,} scenes, |after - before| <= "
             f"{SUCCESS_POINTS} points and McNemar's exact p >= {ALPHA}.", "",
             "| suite | scenes | before | after | both | only before | only after | neither | "
             "after - before (points) | McNemar p |", "|---|---|---|---|---|---|---|---|---|---|"]
    for model in ("curve10", "points10", "moving"):
        key, name = f"suite/{model}/status", f"success, {model}"
        why = _paired(a, b, key)
        if why:
            checks.append((name, False, why))
            continue
        x, y = _reached(a, key), _reached(b, key)
        n, t = len(x), paired_table(x, y)
        d, lo, hi = paired_bootstrap(y, x)
        lines.append(f"| {model} | {n} | {pct_interval(int(x.sum()), n)} | {pct_interval(int(y.sum()), n)} | "
                     f"{t['both']} | {t['only_x']} | {t['only_y']} | {t['neither']} | "
                     f"{100 * d:+.2f} [{100 * lo:+.2f}, {100 * hi:+.2f}] | {t['mcnemar_p']:.3g} |")
        ok = n >= min_scenes and abs(100 * d) <= SUCCESS_POINTS and t["mcnemar_p"] >= ALPHA
        checks.append((name, ok, f"{n} scenes, {100 * d:+.2f} points, p = {t['mcnemar_p']:.3g}"))
    return lines


def _iterations(a, b, checks, _) -> list:
    lines = ["## Mean iterations on the scenes both reached", "",
             f"Criterion: |after / before - 1| <= {100 * ITERATIONS_RATIO:g} %; the mean paired difference "
             "with a 95 % bootstrap interval.", "",
             "| suite | scenes both reached | before | after | after / before | after - before (steps) |",
             "|---|---|---|---|---|---|"]
    for model, _method in MODELS:
        key, name = f"suite/{model}/status", f"iterations, {model}"
        why = _paired(a, b, key)
        both = None if why else _reached(a, key) & _reached(b, key)
        if both is None or not both.any():
            checks.append((name, False, why or "no scene reached in both"))
            continue
        x, y = (np.asarray(d[f"suite/{model}/iterations"], np.float64)[both] for d in (a, b))
        ratio = y.mean() / x.mean()
        d, lo, hi = paired_bootstrap(y, x)
        lines.append(f"| {model} | {int(both.sum())} | {x.mean():.2f} | {y.mean():.2f} | {ratio:.4f} | "
                     f"{d:+.2f} [{lo:+.2f}, {hi:+.2f}] |")
        checks.append((name, abs(ratio - 1) <= ITERATIONS_RATIO, f"{x.mean():.2f} -> {y.mean():.2f} ({ratio:.4f})"))
    return lines


def _curve_model(group: str) -> bool:
    """Whether a run of the save is the curve model's (the moving runs all are)."""
    parts = group.split("/")
    return parts[0] == "moving" or group == "suite/moving" or any(p.startswith("curve") for p in parts)


def collision_sources(d) -> dict:
    """Per source of a save, ``(contacts, runs checked, smallest brute-force clearance or None)``:
    the curve model's runs that the planner's checks call collided, and the runs whose brute-force
    audit finds a clearance at or below 0 (or NaN)."""
    from softplan_jax.base._status import Status

    rows, fallback = {}, []
    for k in sorted(d.files):
        group, field = k.rsplit("/", 1)
        v = np.asarray(d[k])
        if field == "collided" and _curve_model(group):
            rows[group] = (int(v.sum()), int(v.size), None)
        elif field == "brute_clearance":
            rows[f"{group} (brute force)"] = (int(np.sum(~(v > 0))), int(v.size), float(np.min(v)))
        elif group.startswith("fallback/") and field == "status":
            fallback.append(str(v))
    if fallback:
        hit = sum(s in (Status.COLLIDED.label, Status.START_COLLIDED.label) for s in fallback)
        rows["fallback (statuses)"] = (hit, len(fallback), None)
    return rows


def _collisions(a, b, checks, _) -> list:
    before, after = collision_sources(a), collision_sources(b)
    lines = ["## Collisions of the curve model", "",
             "The planner's own checks (`collided`) and the independent brute-force audits. Criterion: 0 after.",
             "", "| source | runs | before | after | smallest brute-force clearance after |", "|---|---|---|---|---|"]
    for src in sorted(set(before) | set(after)):
        x, y = before.get(src), after.get(src)
        runs = (y or x)[1]
        low = "" if y is None or y[2] is None else f"{y[2]:.4g}"
        lines.append(f"| {src} | {runs} | {'—' if x is None else x[0]} | {'—' if y is None else y[0]} | {low} |")
    total = sum(v[0] for v in after.values())
    audits = sum(v[1] for s, v in after.items() if s.endswith("(brute force)"))
    checks.append(("collisions, curve model", bool(after) and total == 0,
                   f"{total} in {sum(v[1] for v in after.values())} runs checked ({audits} by brute force)"))
    return lines


def _recorded_runs(d) -> dict:
    """The single runs of a save: ``{group: (status, iterations)}`` of the paper scenes and the moving presets."""
    runs = {}
    for k in d.files:
        group, field = k.rsplit("/", 1)
        if field == "status" and group.split("/")[0] in ("paper", "moving") and np.ndim(d[k]) == 0:
            runs[group] = (int(d[k]), int(d[f"{group}/iterations"]))
    return runs


def _recorded(a, b, checks, _) -> list:
    from softplan_jax.base._status import STATUS_NAMES, Status

    before, after = _recorded_runs(a), _recorded_runs(b)
    show = lambda r: "—" if r is None else f"{STATUS_NAMES.get(r[0], r[0])}, {r[1]}"  # noqa: E731
    lines = ["## The paper scenes and the moving presets", "",
             "Status and iterations (steps taken). Criteria: every run reached before is reached after; the "
             f"tree ({TREE[0]}) within {TREE[2]} steps of {TREE[1]}.", "", "| run | before | after |", "|---|---|---|"]
    lines += [f"| {g} | {show(before.get(g))} | {show(after.get(g))} |" for g in sorted(set(before) | set(after))]
    lost = [g for g, r in before.items() if r[0] == Status.REACHED and after.get(g, (None,))[0] != Status.REACHED]
    checks.append(("paper scenes and moving presets still reached", bool(before) and not lost,
                   f"{len(lost)} of {sum(r[0] == Status.REACHED for r in before.values())} lost"
                   + (f": {', '.join(sorted(lost))}" if lost else "")))
    tree = after.get(TREE[0])
    ok = tree is not None and tree[0] == Status.REACHED and abs(tree[1] - TREE[1]) <= TREE[2]
    checks.append((f"tree within {TREE[2]} steps of {TREE[1]}", ok, "not recorded" if tree is None else show(tree)))
    return lines


def _fallback_statuses(d) -> list:
    idx = sorted(int(k.split("/")[1]) for k in d.files if k.startswith("fallback/") and k.endswith("/status"))
    return [str(d[f"fallback/{i}/status"]) for i in idx]


def _fallback(a, b, checks, _) -> list:
    x, y = _fallback_statuses(a), _fallback_statuses(b)
    lines = ["## The fallback batch (`plan_fallback`)", ""]
    if not x or len(x) != len(y):
        checks.append(("fallback batch", False, "not recorded in both (save --fallback)"))
        return lines
    count = lambda s: ", ".join(f"{v}: {s.count(v)}" for v in sorted(set(s)))  # noqa: E731
    t = paired_table(np.array(x) == "reached", np.array(y) == "reached")
    lines += [f"- before: {count(x)}", f"- after: {count(y)}",
              f"- reached: both {t['both']}, only before {t['only_x']}, only after {t['only_y']}, neither "
              f"{t['neither']}; McNemar's exact p = {t['mcnemar_p']:.3g} (criterion: >= {ALPHA})"]
    checks.append(("fallback batch", t["mcnemar_p"] >= ALPHA,
                   f"{len(y)} scenes, reached {t['both'] + t['only_x']} -> {t['both'] + t['only_y']}"))
    return lines


def write_markdown(path_after: str, lines: list) -> str:
    """Write the judgement next to the AFTER save: ``AFTER.judge.md``; its path."""
    path = path_after.removesuffix(".npz") + ".judge.md"
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    return path

