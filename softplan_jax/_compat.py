"""Old module paths, kept working with a ``DeprecationWarning``.

Before the package had one folder per layer, every module sat at the top
(``softplan_jax.planner``, ``softplan_jax.closest``, ...). Importing one of
those paths now gives a module that forwards every attribute to the module or
modules that hold the code today, and warns once that the path moved.
"""

from __future__ import annotations

__all__ = ["OLD_MODULES", "install"]

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

# old module -> the modules that hold its names now (searched in order)
OLD_MODULES = {
    "numerics": ("base.numerics",),
    "validation": ("base.validation",),
    "status": ("base.status",),
    "compilation_cache": ("base.compilation_cache",),
    "kinematics": ("geometry.kinematics",),
    "curves": ("geometry.curves", "clouds"),
    "closest": ("geometry.closest", "geometry.point_sets", "geometry.closest_newton"),
    "closest_grid": ("geometry.closest_grid",),
    "warm_start": ("geometry.warm_start",),
    "obstacles": ("geometry.obstacles",),
    "metrics": ("geometry.clearance",),
    "motion": ("scenarios.motion",),
    "step": ("planning.step",),
    "engine": ("planning.engine", "planning.records"),
    "planner": ("planning.planner", "planning.programs", "planning", "planning.step"),
    "tracking": ("planning.tracking",),
    "batching": ("planning.batching",),
    "presets": ("planning.presets",),
    "reach": ("search.reach",),
    "global_planner": ("search.tree",),
    "fallback": ("search.fallback",),
    "smoothing": ("tuning.objective", "tuning.tuner"),
    "gains_file": ("tuning.gains_file",),
    "fitting": ("clouds",),
}

_PACKAGE = __name__.rpartition(".")[0]


class _Forward(types.ModuleType):
    """A module at an old path: its attributes are those of the modules that hold the code now."""

    def __init__(self, name: str, targets: tuple):
        super().__init__(name)
        self.__targets = tuple(f"{_PACKAGE}.{t}" for t in targets)

    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        for target in self.__targets:
            module = importlib.import_module(target)
            if hasattr(module, attr):
                return getattr(module, attr)
        raise AttributeError(f"module {self.__name__!r} (moved to {self.__targets[0]}) has no attribute {attr!r}")

    def __dir__(self):
        names = set()
        for target in self.__targets:
            names |= set(dir(importlib.import_module(target)))
        return sorted(names)


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path=None, target=None):
        package, _, leaf = fullname.rpartition(".")
        if package != _PACKAGE or leaf not in OLD_MODULES:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        leaf = spec.name.rpartition(".")[2]
        targets = OLD_MODULES[leaf]
        warnings.warn(f"the module {spec.name} moved to {_PACKAGE}.{targets[0]}; the old path is deprecated",
                      DeprecationWarning, stacklevel=2)
        return _Forward(spec.name, targets)

    def exec_module(self, module):
        pass


def install() -> None:
    """Put the finder of the old paths on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())



