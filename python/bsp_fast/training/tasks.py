"""One LightningModule per task, each taking any model registered for that task.

The module owns the model (``bsp_fast.models.create(task, name, **hparams)``), uses the
model's own loss and optimiser defaults, and scores val/test with the streaming metrics of
:class:`~bsp_fast.training.scoring.TaskMetrics`. Everything needed to rebuild it is saved
in the checkpoint (``save_hyperparameters``): ``load_module(ckpt)`` gives back the same
module whatever task it was.
"""
from __future__ import annotations

from pathlib import Path

import lightning.pytorch as pl
import torch

from .scoring import TaskMetrics

__all__ = ["TaskModule", "ClassificationTask", "AutoencoderTask", "LiftingTask",
           "PoseEstimationTask", "TASK_MODULES", "load_module", "checkpoint_info",
           "initial_metrics", "BASELINES"]

#: What the trivial baseline of each task predicts (the "initial metrics" row).
BASELINES = {"classification": "majority class", "autoencoder": "identity (noisy input)",
             "lifting": "mean training pose", "pose_estimation": "mean crop skeleton"}


def _batch_size(batch: dict) -> int:
    return int(batch["label"].shape[0])


class TaskModule(pl.LightningModule):
    """Base class: training/validation/test steps, metric logging and the optimiser."""

    task: str = ""

    def __init__(self, model: str, hparams: dict | None = None, lr: float | None = None,
                 config: dict | None = None, task: str | None = None):
        super().__init__()
        if task is not None and task != self.task:
            raise ValueError(f"{type(self).__name__} trains task {self.task!r}, not {task!r}")
        from .. import models

        self.net = models.create(self.task, model, **dict(hparams or {}))
        # the model's complete hyper-parameters (defaults filled in) go in the checkpoint
        self.save_hyperparameters({"task": self.task, "model": model,
                                   "hparams": dict(getattr(self.net, "hparams", hparams) or {}),
                                   "lr": lr, "config": dict(config or {})})
        from torchmetrics import MeanMetric

        self.train_loss = MeanMetric()
        self.val_metrics = TaskMetrics(self.task)
        self.test_metrics = TaskMetrics(self.task)
        self.results: dict = {}  # the last computed {"val": {...}, "test": {...}}
        from .breakdown import RecordingBreakdown

        self.test_recordings = RecordingBreakdown(self.task)  # -> test_per_recording.json

    def forward(self, batch: dict) -> torch.Tensor:
        return self.net.forward_batch(batch)

    # ------------------------------------------------------------------ steps
    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        output = self.net.forward_batch(batch)
        loss = self.net.loss(output, batch)
        n = _batch_size(batch)
        self.train_loss.update(loss.detach().float(), n)
        self.log("loss", loss.detach(), prog_bar=True, logger=False, on_step=True,
                 on_epoch=False, batch_size=n)
        return loss

    def _eval_step(self, batch: dict, metrics: TaskMetrics) -> torch.Tensor:
        output = self.net.forward_batch(batch)
        metrics.update_loss(self.net.loss(output, batch), _batch_size(batch))
        metrics.update(output, batch, self.net)
        return output

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        self._eval_step(batch, self.val_metrics)

    def test_step(self, batch: dict, batch_idx: int) -> None:
        output = self._eval_step(batch, self.test_metrics)
        self.test_recordings.update(output.detach().float(), batch, self.net)

    def predict_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        return self.net.forward_batch(batch)

    # ------------------------------------------------------------------ epoch ends
    def _log_metrics(self, prefix: str, metrics: TaskMetrics) -> None:
        values = metrics.compute()  # already reduced over processes by torchmetrics
        metrics.reset()
        self.results[prefix] = values  # float64 sums / counts, unrounded
        # identical on every process: sync_dist averages equal values (exact)
        self.log_dict({f"{prefix}/{k}": float(v) for k, v in values.items()},
                      sync_dist=True, prog_bar=False)
        if prefix == "val":
            self.log("val_loss", float(values["loss"]), prog_bar=True, logger=False,
                     sync_dist=True)

    def on_train_epoch_end(self) -> None:
        if self.train_loss.update_count:
            self.log("train/loss", float(self.train_loss.compute()), sync_dist=True)
        self.train_loss.reset()

    def on_validation_epoch_end(self) -> None:
        if not self.trainer.sanity_checking:
            self._log_metrics("val", self.val_metrics)
        self.val_metrics.reset()

    def on_test_epoch_end(self) -> None:
        self._log_metrics("test", self.test_metrics)
        self.results["test_per_recording"] = self.test_recordings.compute()
        self.test_recordings.reset()

    # ------------------------------------------------------------------ optimiser
    def configure_optimizers(self):
        optimizer, scheduler, interval = self.net.configure_optimizers(lr=self.hparams.lr)
        if scheduler is None:
            return optimizer
        return {"optimizer": optimizer,
                "lr_scheduler": {"scheduler": scheduler, "interval": interval or "epoch"}}


class ClassificationTask(TaskModule):
    """Crossing vs not crossing from a 2D clip: F1, precision, recall, accuracy."""
    task = "classification"


class AutoencoderTask(TaskModule):
    """Denoise/complete normalised 2D: PCK@0.05 and PCKhn@0.1 on de-normalised pixels."""
    task = "autoencoder"


class LiftingTask(TaskModule):
    """2D -> 3D: MPJPE, N-MPJPE, PA-MPJPE, MPJVE in mm (reference hips-neck length)."""
    task = "lifting"


class PoseEstimationTask(TaskModule):
    """Crops -> 2D joints in crop pixels: PCK@0.05 and PCKhn@0.1 over visible joints."""
    task = "pose_estimation"


TASK_MODULES = {cls.task: cls for cls in (ClassificationTask, AutoencoderTask, LiftingTask,
                                          PoseEstimationTask)}


def checkpoint_info(ckpt_path) -> dict:
    """The saved hyper-parameters of a bsp-train checkpoint (task, model, hparams, lr,
    config), read without building the model."""
    path = Path(ckpt_path)
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") \
            from None
    hp = ckpt.get("hyper_parameters") if isinstance(ckpt, dict) else None
    if not isinstance(hp, dict) or hp.get("task") not in TASK_MODULES or "model" not in hp:
        raise ValueError(f"{path}: not a bsp-train checkpoint (no task/model hyper-parameters)")
    info = dict(hp)
    info["epoch"] = ckpt.get("epoch")
    info["global_step"] = ckpt.get("global_step")
    return info


def load_module(ckpt_path, task: str | None = None, map_location="cpu") -> TaskModule:
    """Rebuilds the module of a checkpoint; ``task`` (optional) must match the saved one."""
    info = checkpoint_info(ckpt_path)
    if task is not None and info["task"] != task:
        raise ValueError(f"{ckpt_path} is a {info['task']!r} checkpoint "
                         f"({info['model']}), not {task!r}")
    cls = TASK_MODULES[info["task"]]
    return cls.load_from_checkpoint(str(ckpt_path), map_location=map_location,
                                    weights_only=True)


@torch.no_grad()
def initial_metrics(task: str, train_loader, eval_loaders: dict, limit: int = 0,
                    model=None, per_recording: bool = False) -> dict:
    """Fits ``bsp_fast.models.trivial_baseline(task)`` on the train batches and scores it
    like a trained model on each of ``eval_loaders`` (``{split: loader}``):
    ``{"baseline": name, split: {metric: value}}``. ``limit`` > 0 caps the batches read.
    ``model`` (the model about to be trained) gets ``init_from_baseline(baseline)``.
    ``per_recording`` adds ``"test_per_recording"`` (:mod:`.breakdown`) for the test split."""
    import itertools

    from .. import models
    from .breakdown import RecordingBreakdown

    base = models.trivial_baseline(task)
    base.eval()
    cap = (lambda it: itertools.islice(it, limit)) if limit else (lambda it: it)
    base.fit(cap(iter(train_loader)))
    if model is not None:
        model.init_from_baseline(base)
    out = {"baseline": BASELINES[task]}
    for split, loader in eval_loaders.items():
        metrics = TaskMetrics(task)
        recordings = RecordingBreakdown(task) if per_recording and split == "test" else None
        for batch in cap(iter(loader)):
            output = base.forward_batch(batch)
            metrics.update_loss(base.loss(output, batch), _batch_size(batch))
            metrics.update(output, batch, base)
            if recordings is not None:
                recordings.update(output.float(), batch, base)
        out[split] = metrics.compute()
        if recordings is not None:
            out["test_per_recording"] = recordings.compute()
    return out
