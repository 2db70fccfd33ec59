"""pytest configuration: float64 everywhere, strict dtype promotion,
jax's persistent compilation cache (``session.py``), and the scheduling of
test files over the xdist workers (below).

x64 must be switched on before any array is created, i.e. at import time of
this conftest (pytest imports it before the test modules). Tests marked
``slow`` are deselected by default (pyproject.toml); ``pytest -m slow`` runs
them.
"""

import os
import sys

# The oracle calls scipy.optimize thousands of times on tiny problems;
# multi-threaded BLAS only adds overhead there (4x slower measured on 2
# cores).  Must be set before numpy is imported.  XLA does not read it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
# XLA flags for the test processes (compilation is 80 % of the suite's time):
# - XLA's Eigen kernels single-threaded in each process: the suite runs 2 xdist workers on
#   2 cores, busy throughout (user + sys = 1.95 x wall), where each worker's Eigen thread pool
#   only made them contend (cold suite, 4 runs each: 339-352 s without, 328-334 s with).
# - for the ~2,000 small programs the suite compiles (eager ops, test helpers), XLA's elemental
#   emitter instead of its MLIR fusion emitters and LLVM's optimisation level 0 instead of 3:
#   a tiny program compiles in about a third of the time (19 -> 7 ms). Every program the package
#   jits names both options per program (compilation_cache: rollout_compiler_options and
#   package_jit), so the programs tested here compile as in a user's process; the baselines
#   (benchmarks/baselines.py: paper scenes, random batches, moving scenes, the fallback) are
#   bit-identical with and without these flags
#   (test_compilation_cache::test_package_programs_do_not_depend_on_the_suites_xla_flags).
# The user's own XLA_FLAGS are kept, and their setting of any of these flags wins (XLA_FLAGS
# naming a file of flags, i.e. not starting with "--", is left alone).
_XLA_FLAGS = os.environ.get("XLA_FLAGS", "").strip()
if not _XLA_FLAGS or _XLA_FLAGS.startswith("--"):
    for _flag, _value in (("xla_cpu_multi_thread_eigen", "false"), ("xla_cpu_use_fusion_emitters", "false"),
                          ("xla_backend_optimization_level", "0")):
        if _flag not in _XLA_FLAGS:
            _XLA_FLAGS = f"{_XLA_FLAGS} --{_flag}={_value}".strip()
    os.environ["XLA_FLAGS"] = _XLA_FLAGS

import jax  # noqa: E402
import pytest  # noqa: E402

TESTS = os.path.dirname(os.path.abspath(__file__))

jax.config.update("jax_enable_x64", True)
# Strict promotion: any silent float32/float64 (or int/float) mixing in the
# library is an error under test.  SOFTPLAN_TEST_STRICT=0 turns it off (to
# tell a promotion error from another failure).
if os.environ.get("SOFTPLAN_TEST_STRICT", "1") != "0":
    jax.config.update("jax_numpy_dtype_promotion", "strict")

# `import helpers` / `import session` from tests/, and the benchmark scripts from
# benchmarks/ (the independent reference is softplan_jax.testing).
sys.path.insert(0, os.path.join(os.path.dirname(TESTS), "benchmarks"))
sys.path.insert(0, TESTS)

import session  # noqa: E402

session.enable()


# ----------------------------------------------------------------------------
# Scheduling over the xdist workers (pyproject.toml: -n 2 --dist loadfile
# --no-loadscope-reorder). A work unit is one test file, as with loadfile (its
# module-scoped compiled functions are built once), except that files compiling
# the same programs form one unit: run one after the other in one worker, the later
# ones find the earlier ones' programs in the persistent compilation cache (same
# padded shapes, options and max_steps), where two workers would both compile them.
# test_planner first: its programs (the paper scenes padded to 5 curve slots, 200
# steps, default and paper step, 10 points; the loss-and-gradient of tune_gains)
# are the ones test_engine, test_safe_step, test_smoothing (the tree's planner_step),
# test_goal_gains (the constant gains' plan of the tree) and the notebooks use
# (test_moving's tracking rollout, the tree shape at 200 steps, is the quickstart
# notebook's section 7; test_trajectories times the tree's plan and tracks tree_sway as they do);
# test_warm_start's plan_batch is
# the program of test_cli's batch command; test_gains_file plans with test_cli's and
# test_presets' programs.
SHARED = {
    "planner": ["test_planner", "test_engine", "test_safe_step", "test_smoothing", "test_goal_gains", "test_moving",
                "test_trajectories", "test_notebooks"],
    "cli": ["test_warm_start", "test_cli", "test_cli_actuators", "test_presets", "test_gains_file"],
    # test_sweep's fallback runs test_reach's search programs (same padded shape and options).
    "reach": ["test_reach", "test_sweep"],
}
# Units in this order (largest first, so that the other worker's smaller units fill
# the time the largest takes); units not listed follow in collection order.
FIRST = ["planner", "cli", "reach", "test_benchmarks", "test_closest", "test_batch", "test_fitting", "test_kinematics"]
# The slow tier's order (``-m slow``): the loaded arm's files first, the largest of that tier
# (compiling the loaded rollouts and the loaded fallback); started last, they ran alone at its end.
SLOW_FIRST = ["test_rod_planning", "planner", "test_rod", "test_batch", "cli", "reach"]


def _unit(module: str) -> str:
    return next((unit for unit, modules in SHARED.items() if module in modules), module)


def _module(nodeid: str) -> str:
    return os.path.splitext(os.path.basename(nodeid.split("::", 1)[0]))[0]


@pytest.hookimpl(trylast=True)  # after pytest's own reordering by fixtures: files stay contiguous
def pytest_collection_modifyitems(config, items):
    order = SLOW_FIRST if (config.getoption("markexpr", "") or "").strip() == "slow" else FIRST

    def rank(item):
        module = _module(item.nodeid)
        unit = _unit(module)
        first = order.index(unit) if unit in order else len(order)
        return first, SHARED[unit].index(module) if unit in SHARED else 0

    items.sort(key=rank)  # stable: pytest's order within a file


def pytest_xdist_make_scheduler(config, log):
    """loadfile's scheduler with the units above (xdist's own ``xdist_group`` marks are
    not used: pytest-xdist 3.8 renames nodeids in a way pytest >= 9 ignores)."""
    from xdist.scheduler import LoadScopeScheduling

    class UnitScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return _unit(_module(nodeid))

    return UnitScheduling(config, log)
