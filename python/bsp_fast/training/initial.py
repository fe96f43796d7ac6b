"""The "initial metrics": the trivial baseline of a task (``bsp_fast.models.trivial_baseline``)
fitted on the train split and scored like a trained model before training starts (the
first row of every results table), optionally per test recording."""
from __future__ import annotations

import torch

from .per_recording import RecordingBreakdown
from .scoring import TaskMetrics
from .tasks import get_task

__all__ = ["initial_metrics", "log_initial"]


@torch.no_grad()
def initial_metrics(task: str, train_loader, eval_loaders: dict, limit: int = 0,
                    model=None, per_recording: bool = False) -> dict:
    """Fits ``bsp_fast.models.trivial_baseline(task)`` on the train batches and scores it
    like a trained model on each of ``eval_loaders`` (``{split: loader}``):
    ``{"baseline": name, split: {metric: value}}``. ``limit`` > 0 caps the batches read.
    ``model`` (the model about to be trained) gets ``init_from_baseline(baseline)``.
    ``per_recording`` adds ``"test_per_recording"`` (:mod:`.per_recording`) for the test split."""
    import itertools

    from .. import models

    spec = get_task(task)
    base = models.trivial_baseline(task)
    base.eval()
    cap = (lambda it: itertools.islice(it, limit)) if limit else (lambda it: it)
    base.fit(cap(iter(train_loader)))
    if model is not None:
        model.init_from_baseline(base)
    out = {"baseline": spec.baseline}
    for split, loader in eval_loaders.items():
        metrics = TaskMetrics(task)
        recordings = RecordingBreakdown(task) if per_recording and split == "test" else None
        for batch in cap(iter(loader)):
            output = base.forward_batch(batch)
            metrics.update_loss(base.loss(output, batch), spec.batch_size(batch))
            metrics.update(output, batch, base)
            if recordings is not None:
                recordings.update(output.float(), batch, base)
        out[split] = metrics.compute()
        if recordings is not None:
            out["test_per_recording"] = recordings.compute()
    return out


def log_initial(trainer, initial: dict, quiet: bool) -> None:
    """Logs :func:`initial_metrics` (``initial/SPLIT/METRIC`` at step 0) to the trainer's
    loggers and prints them unless ``quiet``."""
    values = {f"initial/{split}/{k}": v for split in ("val", "test")
              for k, v in initial.get(split, {}).items() if v is not None}
    for logger in trainer.loggers:
        logger.log_metrics(values, step=0)
        logger.save()
    if not quiet:
        from ..reporting.run_tables import initial_text

        print(initial_text(initial))
