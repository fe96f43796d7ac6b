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

from ...metrics.spec import NORMALISER_FALLBACK
from .autoencoder import Autoencoder
from .base import Task
from .classification import Classification
from .lifting import Lifting
from .pose_estimation import PoseEstimation

__all__ = ["Task", "TASKS", "get_task", "BASELINES", "TABLE_COLUMNS", "metric_formats"]

#: ``{name: task object}`` in the report's order.
TASKS = {t.name: t for t in (Classification(), Autoencoder(), Lifting(), PoseEstimation())}

#: What the trivial baseline of each task predicts (the "initial metrics" row).
BASELINES = {name: t.baseline for name, t in TASKS.items()}

#: ``{task: ((header, where, key, format), ...)}`` of ``bsp-eval --table``: where "m" a
#: metric, "c" a config value (each task object's ``table_columns()``)
TABLE_COLUMNS = {name: task.table_columns() for name, task in TASKS.items()}


def get_task(name: str) -> Task:
    """The task object of ``name``; ValueError listing the tasks otherwise."""
    try:
        return TASKS[name]
    except (KeyError, TypeError):
        raise ValueError(f"task must be one of {list(TASKS)}, got {name!r}") from None


def metric_formats() -> dict:
    """``{key: table format}`` of every metric any task declares (its metrics, extra
    metrics and the normaliser fallback share): what the renderers
    (``bsp_fast.reporting``) format a breakdown's columns with; a key no task declares (a
    count) is not in it."""
    out: dict = {}
    for task in TASKS.values():
        for m in (*task.metrics, *task.extra_metrics):
            out.setdefault(m.key, m.fmt)
    out.setdefault(NORMALISER_FALLBACK.key, NORMALISER_FALLBACK.fmt)
    return out


def __dir__():
    return sorted(globals())
