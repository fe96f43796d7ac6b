"""What each task scores, as one ``torch.nn.Module`` of streaming metrics per split.

The metrics and how a model's output is scored belong to the task objects
(``bsp_fast.training.tasks``); :class:`TaskMetrics` holds a task's torchmetrics states,
the loss and the reduction. Every value is a global sum over the split divided by a
global count (torchmetrics states, reduced over DDP processes), never a mean of batch
means; classification's AUROC and AP, which are not sums, are computed once from every
clip's score kept over the split (``RankingMetrics``, gathered over processes), so they
too are the same for any batch size. ``loss`` is the model's loss averaged over clips; ``normaliser_fallback`` (2D-input
tasks) the share of input frames normalised by their joint bbox. See docs/training.md,
Metrics.
"""
from __future__ import annotations

import torch

from .tasks import TASKS, get_task
from .tasks.lifting import hips_neck_lengths

__all__ = ["TaskMetrics", "hips_neck_lengths", "UNITS"]

#: ``{metric key: unit}`` of every task's metrics.
UNITS = {k: v for t in TASKS.values() for k, v in t.units.items()}


class TaskMetrics(torch.nn.Module):
    """``update_loss(loss, n)``, ``update(output, batch, model)``, ``compute() -> dict``
    of floats, ``reset()``. ``model`` is the one that produced ``output`` (its
    ``frame_slice`` says which frames the output stands for)."""

    def __init__(self, task: str):
        super().__init__()
        from torchmetrics import MeanMetric

        self.spec = get_task(task)
        self.task = task
        self.loss = MeanMetric()
        modules = self.spec.metric_modules()
        # ModuleDict keys cannot hold "."; keep the metric keys beside them
        self._keys = {k.replace(".", "_"): k for k in modules}
        self.scores = torch.nn.ModuleDict({k.replace(".", "_"): m for k, m in modules.items()})
        #: share of input frames normalised by the bbox fallback (2D-input tasks)
        self.fallback = None if self.spec.image_inputs else MeanMetric()

    def update_loss(self, loss: torch.Tensor, n: int) -> None:
        loss = loss.detach().float()
        if torch.isfinite(loss):
            self.loss.update(loss, n)

    @torch.no_grad()
    def update(self, output: torch.Tensor, batch: dict, model) -> None:
        by_key = {self._keys[k]: m for k, m in self.scores.items()}
        self.spec.update_metrics(by_key, output.detach().float(), batch, model)
        if self.fallback is not None and "normaliser_fallback" in batch:
            self.fallback.update(batch["normaliser_fallback"].reshape(-1).float())

    def compute(self) -> dict:
        out = {"loss": float(self.loss.compute()) if self.loss.update_count else float("nan")}
        for name, metric in self.scores.items():
            if not metric.update_count:
                continue
            value = metric.compute()
            if isinstance(value, dict):
                out.update({k: float(v) for k, v in value.items()})
            else:
                out[self._keys[name]] = float(value)
        if self.fallback is not None and self.fallback.update_count:
            out["normaliser_fallback"] = float(self.fallback.compute())
        return out

    def reset(self) -> None:
        self.loss.reset()
        for metric in self.scores.values():
            metric.reset()
        if self.fallback is not None:
            self.fallback.reset()


#: per-clip strings :func:`prediction_step` returns besides the arrays
PREDICTION_STRINGS = ("video_id", "pedestrian_id", "age", "gender")


def eval_step(spec, net, batch: dict, metrics: TaskMetrics) -> torch.Tensor:
    """One val/test batch: the net's output, its loss and metrics added to ``metrics``
    (the step of ``TaskModule``'s validation and test and of the plain scorer alike, so
    the two cannot drift)."""
    spec.check_batch(batch)
    output = net.forward_batch(batch)
    metrics.update_loss(net.loss(output, batch), spec.batch_size(batch))
    metrics.update(output, batch, net)
    return output


def prediction_step(spec, net, batch: dict) -> dict:
    """The de-normalised outputs of one batch (tensors; the datasets of ``bsp-predict``):
    the task's arrays, ``frames``, ``clip_id``, ``row``, ``start_frame``, ``label``, and
    lists of the clips' ``video_id``, ``pedestrian_id``, ``age``, ``gender``."""
    spec.check_batch(batch)
    output = net.forward_batch(batch).detach().float()
    out = spec.predictions(output, batch, net)
    meta = batch["meta"]
    out.update(clip_id=meta["clip_id"], row=meta["row"], start_frame=meta["start_frame"],
               label=batch["label"])
    out.update({k: list(meta[k]) for k in PREDICTION_STRINGS})
    return out
