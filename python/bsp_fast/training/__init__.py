"""Training, evaluation and prediction of the report's baselines (``bsp-train``,
``bsp-eval``, ``bsp-predict``); see docs/training.md.

``train``, ``evaluate`` and ``predict`` are imported on first access: they pull in torch
and Lightning, which take seconds to import.
"""
from __future__ import annotations

__all__ = ["train", "evaluate", "predict", "TrainResult", "EvalResult", "PredictResult",
           "runs_table", "TASK_MODULES", "load_module"]

_LAZY = {"train": "train", "TrainResult": "train", "evaluate": "evaluate",
         "EvalResult": "evaluate", "predict": "predict", "PredictResult": "predict",
         "runs_table": "tables", "TASK_MODULES": "tasks", "load_module": "tasks"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
