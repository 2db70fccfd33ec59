"""``softplan scenarios``: list the paper's scenarios (the names for ``softplan run``)
with their goals and obstacle curves (the paper's Tables 2-4)."""

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
    """``softplan scenarios``: print the paper scenarios (text or JSON); the exit code."""
    from ..scenarios import PAPER_SCENARIOS

    rows = []
    for name in sorted(PAPER_SCENARIOS):
        spec = PAPER_SCENARIOS[name]
        rows.append(
            {
                "name": name,
                "goal": list(spec["goal"]),
                "obstacles": len(spec["curves"]),
                "description": PAPER_DESCRIPTIONS.get(name, ""),
            }
        )
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"{r['name']:<6} {r['obstacles']} obstacle curve(s)  {r['description']}")
    return EXIT_OK
