"""Scenarios: planning problems as pytrees, one job per module.

* :mod:`.scenario` -- the :class:`Scenario` type and its constructors
  (:func:`make_scenario`, :func:`stack_scenarios`, :func:`default_start`);
* :mod:`.paper` -- the paper's three simulations (section 3, Tables 2-4);
* :mod:`.json_format` -- the JSON scenario format (:func:`load_scenario`,
  :func:`save_scenario`);
* :mod:`.random_suite` -- seeded random scenario suites for the benchmarks.
"""

from .json_format import (
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
from .paper import PAPER_RESULTS, PAPER_SCENARIOS, paper_scenario
from .random_suite import random_scenarios
from .scenario import Scenario, default_start, make_scenario, obstacle_count, scenario_warnings, stack_scenarios

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
