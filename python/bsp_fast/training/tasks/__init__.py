"""The task registry: one object per task (``bsp_fast.training.tasks.<task>``) that owns
its batch keys, metrics, scoring, trivial baseline, table columns, curves, predictions and
the baselines ``bsp-reproduce`` findings compare with. Declarations only: the per-task
LightningModules live in :mod:`bsp_fast.training.module`.

>>> from bsp_fast.training.tasks import get_task
>>> get_task("lifting").metric("mpjpe_mm").header        # 'MPJPE (mm)'

The task objects import neither torch nor Lightning. See docs/training.md ("The task
modules in your own Lightning script").
"""
from __future__ import annotations

from .autoencoder import Autoencoder
from .base import NORMALISER_FALLBACK, Metric, Task, format_metric
from .classification import Classification
from .lifting import Lifting
from .pose_estimation import PoseEstimation

__all__ = ["Task", "Metric", "TASKS", "get_task", "BASELINES", "metric_spec", "format_metric"]

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


def metric_spec(key: str):
    """The :class:`Metric` any task declares under ``key`` (its metrics, extra metrics and
    the normaliser fallback share); None for a key no task declares (a count)."""
    for task in TASKS.values():
        for m in (*task.metrics, *task.extra_metrics):
            if m.key == key:
                return m
    return NORMALISER_FALLBACK if key == NORMALISER_FALLBACK.key else None


def __dir__():
    return sorted(globals())
