"""Training, evaluation and prediction of the report's baselines (``bsp-train``,
``bsp-eval``, ``bsp-predict``); see docs/training.md.

The functions are ``bsp_fast.train``, ``bsp_fast.evaluate`` and ``bsp_fast.predict`` (the
modules ``bsp_fast.training.train``, ``.evaluate``, ``.predict`` hold them and their
command lines). Nothing here imports torch or Lightning until it is used.
"""
from __future__ import annotations

__all__ = ["TrainResult", "EvalResult", "PredictResult", "runs_table", "TASK_MODULES",
           "load_module"]

_LAZY = {"TrainResult": "train", "EvalResult": "evaluate", "PredictResult": "predict",
         "runs_table": "tables", "TASK_MODULES": "module", "load_module": "module"}


#: modules that moved out of ``bsp_fast.training`` (issue #35): the old import paths keep
#: working for one release, with a DeprecationWarning saying where each went
MOVED = {"reproduce": ("bsp_fast.reproduction",),
         "seeds": ("bsp_fast.reproduction.runner", "bsp_fast.reproduction.figures"),
         "evidence": ("bsp_fast.reproduction.evidence", "bsp_fast.reproduction.report"),
         "findings": ("bsp_fast.reproduction.findings",),
         "table_files": ("bsp_fast.reproduction.table_files",),
         "figures": ("bsp_fast.reproduction.figures",),
         "table_breakdown": ("bsp_fast.reproduction.table_breakdown",),
         "cost_columns": ("bsp_fast.reproduction.cost_columns",),
         "noisy_boxes": ("bsp_fast.reproduction.noisy_boxes",),
         "breakdown": ("bsp_fast.training.per_recording",),
         "tasks.module": ("bsp_fast.training.module",)}


class _MovedFinder:
    """``import bsp_fast.training.reproduce`` (and the other :data:`MOVED` names) gives a
    module that looks names up in the new modules, with a DeprecationWarning."""

    def find_spec(self, fullname, path=None, target=None):
        prefix = __name__ + "."
        if not fullname.startswith(prefix) or fullname[len(prefix):] not in MOVED:
            return None
        import importlib.util

        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        import importlib
        import types
        import warnings

        targets = MOVED[spec.name[len(__name__) + 1:]]
        warnings.warn(f"{spec.name} moved to {' and '.join(targets)}; the old path goes away "
                      "in the next release", DeprecationWarning, stacklevel=3)
        mods = [importlib.import_module(t) for t in targets]
        module = types.ModuleType(spec.name, f"Moved: see {', '.join(targets)}.")

        def lookup(name):
            for m in mods:
                if hasattr(m, name):
                    return getattr(m, name)
            raise AttributeError(f"module {spec.name!r} (moved to {targets[0]}) has no "
                                 f"attribute {name!r}")
        module.__getattr__ = lookup
        return module

    def exec_module(self, module):
        pass


def _install_finder() -> None:
    import sys

    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())


_install_finder()

#: names that ``bsp_fast.training.tasks`` held before the LightningModules moved to
#: ``bsp_fast.training.module`` (#35); looked up there for one release, with a warning
_TASKS_MOVED = ("TaskModule", "ClassificationTask", "AutoencoderTask", "LiftingTask",
                "PoseEstimationTask", "TASK_MODULES", "load_module", "checkpoint_info")


def _moved_from_tasks(name):
    if name not in _TASKS_MOVED:
        raise AttributeError(f"module 'bsp_fast.training.tasks' has no attribute {name!r}")
    import importlib
    import warnings

    warnings.warn(f"bsp_fast.training.tasks.{name} moved to bsp_fast.training.module.{name}; "
                  "the old path goes away in the next release", DeprecationWarning,
                  stacklevel=2)
    return getattr(importlib.import_module(".module", __name__), name)


def _patch_tasks() -> None:
    from . import tasks

    tasks.__getattr__ = _moved_from_tasks


_patch_tasks()


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
