"""Scenarios: planning problems as pytrees, one job per module (:mod:`._scenario`: the
:class:`Scenario` type and its constructors; :mod:`._paper`: the paper's three simulations;
:mod:`._motion` and :mod:`._moving`: moving obstacles and goals, their presets and random
suite; :mod:`._json_format`: the JSON scenario format; :mod:`._random_suite`: seeded random
suites for the benchmarks)."""

from ._json_format import (
    load_moving_scenario,
    load_scenario,
    moving_from_dict,
    moving_to_dict,
    save_moving_scenario,
    save_scenario,
    scenario_from_dict,
    scenario_to_dict,
    write_json_file,
)
from ._paper import PAPER_RESULTS, PAPER_SCENARIOS, paper_scenario
from ._random_suite import random_scenarios
from ._scenario import Scenario, default_start, make_scenario, obstacle_count, scenario_warnings, stack_scenarios

__all__ = [
    "Scenario",
    "default_start",
    "make_scenario",
    "stack_scenarios",
    "obstacle_count",
    "scenario_warnings",
    "PAPER_SCENARIOS",
    "PAPER_RESULTS",
    "paper_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    "load_scenario",
    "save_scenario",
    "write_json_file",
    "random_scenarios",
    "moving_from_dict",
    "moving_to_dict",
    "load_moving_scenario",
    "save_moving_scenario",
]
