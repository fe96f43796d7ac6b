"""Training, evaluation and prediction of the report's baselines (``bsp-train``,
``bsp-eval``, ``bsp-predict``); see docs/training.md.

The functions are ``bsp_fast.train``, ``bsp_fast.evaluate`` and ``bsp_fast.predict`` (the
modules ``bsp_fast.training.train``, ``.evaluate``, ``.predict`` hold them and their
command lines). Nothing here imports torch or Lightning until it is used.
"""
from __future__ import annotations

__all__ = ["TrainResult", "EvalResult", "PredictResult", "TASK_MODULES", "load_module"]

_LAZY = {"TrainResult": "train", "EvalResult": "evaluate", "PredictResult": "predict",
         "TASK_MODULES": "module", "load_module": "module"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
