"""``softplan scenarios``: list the scenes ``softplan run`` knows by name: the paper's
scenarios with their goals and obstacle curves (the paper's Tables 2-4), and the moving
presets (:func:`~softplan_jax.scenarios._moving.moving_scenario`)."""

from __future__ import annotations

import json

from .common import EXIT_OK

__all__ = ["PAPER_DESCRIPTIONS", "cmd_scenarios"]

PAPER_DESCRIPTIONS = {
    "sim1": "paper Table 2: line X = 1, Y = u, Z = 0.5 - u, u in [-2, 2]; goal [1.1, -0.8, 0.9]",
    "sim2": "paper Table 3: parabola X = 0.5, Y = u, Z = 5u^2, u in [-2, 2]; goal [1, 1, 1]",
    "tree": "paper Table 4: four branches + trunk X = 1, Y = 1, Z = u, u in [0, 3] "
    "(the table is garbled after its 4th row); goal [1, 0.7, 1.45]",
}


def cmd_scenarios(args) -> int:
    """``softplan scenarios``: print the paper scenarios and the moving presets (text or JSON);
    the exit code."""
    import jax

    jax.config.update("jax_enable_x64", True)  # the presets' goals as written
    from ..scenarios import PAPER_SCENARIOS
    from ..scenarios._moving import MOVING_SCENARIOS, moving_scenario

    rows = [{"name": name, "kind": "paper", "goal": list(spec["goal"]), "goal_moves": False,
             "obstacles": len(spec["curves"]), "description": PAPER_DESCRIPTIONS.get(name, "")}
            for name, spec in sorted(PAPER_SCENARIOS.items())]
    for name, text in MOVING_SCENARIOS.items():
        m = moving_scenario(name)
        rows.append({"name": name, "kind": "moving", "goal": [float(g) for g in m.scene.goal],
                     "goal_moves": int(m.goal_path.attach) >= 0 or m.goal_path.times.shape[0] > 1,
                     "obstacles": int(m.scene.curve_mask.sum()), "description": text})
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    for kind, title in (("paper", "The paper's scenarios (planned)"),
                        ("moving", "Moving scenes (tracked)")):
        print(title + ":")
        for r in (r for r in rows if r["kind"] == kind):
            print(f"  {r['name']:<10} {r['obstacles']} obstacle curve(s)  {r['description']}")
    return EXIT_OK
