"""The task registry: one object per task (``bsp_fast.training.tasks.<task>``) that owns
its batch keys, metrics, scoring, trivial baseline, table columns, curves, predictions and
the baselines ``bsp-reproduce`` findings compare with; and the per-task LightningModules.

>>> from bsp_fast.training.tasks import get_task, LiftingTask
>>> get_task("lifting").metric("mpjpe_mm").header        # 'MPJPE (mm)'
>>> module = LiftingTask("poseformer", hparams={"receptive_field": 9})  # a LightningModule

The task objects import neither torch nor Lightning; the LightningModules (``TaskModule``
and its subclasses, ``load_module``, ``checkpoint_info``) load Lightning when first used.
See docs/training.md ("The task modules in your own Lightning script").
"""
from __future__ import annotations

from .autoencoder import Autoencoder
from .base import Metric, Task
from .classification import Classification
from .lifting import Lifting
from .pose_estimation import PoseEstimation

__all__ = ["Task", "Metric", "TASKS", "get_task", "BASELINES", "TaskModule",
           "ClassificationTask", "AutoencoderTask", "LiftingTask", "PoseEstimationTask",
           "TASK_MODULES", "load_module", "checkpoint_info"]

#: ``{name: task object}`` in the report's order.
TASKS = {t.name: t for t in (Classification(), Autoencoder(), Lifting(), PoseEstimation())}

#: What the trivial baseline of each task predicts (the "initial metrics" row).
BASELINES = {name: t.baseline for name, t in TASKS.items()}


def get_task(name: str) -> Task:
    """The task object of ``name``; ValueError listing the tasks otherwise."""
    try:
        return TASKS[name]
    except (KeyError, TypeError):
        raise ValueError(f"task must be one of {list(TASKS)}, got {name!r}") from None


_LAZY = {"TaskModule": "module", "ClassificationTask": "module", "AutoencoderTask": "module",
         "LiftingTask": "module", "PoseEstimationTask": "module", "TASK_MODULES": "module",
         "load_module": "module", "checkpoint_info": "module"}


def __getattr__(name):
    if name in _LAZY:  # Lightning is imported only by those who use the modules
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
