"""The per-task LightningModules: :class:`ClassificationTask`, :class:`AutoencoderTask`,
:class:`LiftingTask`, :class:`PoseEstimationTask` (public API, docs/training.md).

Each takes any model registered for its task (``bsp_fast.models.create(task, name,
**hparams)``), trains it with the model's own loss and optimiser defaults, and scores
val/test with :class:`~bsp_fast.training.scoring.TaskMetrics` the way its task object
(``get_task(task)``) says: e.g. lifting de-normalises with the reference hips-neck length
and scores only the frames the model predicts. ``predict_step`` returns the de-normalised
outputs ``bsp-predict`` writes. Everything needed to rebuild a module is saved in the
checkpoint (``save_hyperparameters``): ``load_module(ckpt)`` gives back the same module
whatever task it was.
"""
from __future__ import annotations

import time
from pathlib import Path

import lightning.pytorch as pl
import torch

from .checkpoint_file import checkpoint_info
from .scoring import TaskMetrics, eval_step, prediction_step
from .tasks import TASKS, get_task

__all__ = ["TaskModule", "ClassificationTask", "AutoencoderTask", "LiftingTask",
           "PoseEstimationTask", "TASK_MODULES", "load_module"]


class TaskModule(pl.LightningModule):
    """Base class: training/validation/test/predict steps, metric logging, optimiser.

    ``TaskModule(model, hparams=None, lr=None, config=None)``: ``model`` a registered
    model name of the subclass's task, ``hparams`` its hyper-parameters, ``lr`` the
    learning rate (``None``: the model's default), ``config`` free settings saved with the
    checkpoint. After ``trainer.validate``/``test``, ``results["val"]``/``["test"]`` hold
    the metrics (floats, mm for 3D), as logged under ``val/...`` and ``test/...``.
    """

    task: str = ""

    def __init__(self, model: str, hparams: dict | None = None, lr: float | None = None,
                 config: dict | None = None, task: str | None = None):
        super().__init__()
        if task is not None and task != self.task:
            raise ValueError(f"{type(self).__name__} trains task {self.task!r}, not {task!r}")
        from .. import models

        self.spec = get_task(self.task)
        self.net = models.create(self.task, model, **dict(hparams or {}))
        # the model's complete hyper-parameters (defaults filled in) go in the checkpoint
        self.save_hyperparameters({"task": self.task, "model": model,
                                   "hparams": dict(getattr(self.net, "hparams", hparams) or {}),
                                   "lr": lr, "config": dict(config or {})})
        from torchmetrics import MeanMetric

        self.train_loss = MeanMetric()
        self.train_fallback = MeanMetric()  # share of bbox-normalised input frames
        self.val_metrics = TaskMetrics(self.task)
        self.test_metrics = TaskMetrics(self.task)
        self.results: dict = {}  # the last computed {"val": {...}, "test": {...}}
        from .per_recording import RecordingBreakdown

        self.test_recordings = RecordingBreakdown(self.task)  # -> test_per_recording.json

    def forward(self, batch: dict) -> torch.Tensor:
        return self.net.forward_batch(batch)

    def transfer_batch_to_device(self, batch, device, dataloader_idx: int):
        # our loaders give CPU tensors: on a CPU run there is nothing to move, and Lightning's
        # generic walk over the batch (every string of its meta lists) cost ~12 % of a
        # small model's training time (benchmarks/bench_train_loop.py, docs/performance.md)
        if device.type == "cpu":
            return batch
        return super().transfer_batch_to_device(batch, device, dataloader_idx)

    def scored_frames(self, L: int) -> slice:
        """The frames of an ``L``-frame clip that are scored and predicted."""
        return self.spec.scored_frames(self.net, L)

    # ------------------------------------------------------------------ steps
    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        self.spec.check_batch(batch)
        output = self.net.forward_batch(batch)
        loss = self.net.loss(output, batch)
        n = self.spec.batch_size(batch)
        self.train_loss.update(loss.detach().float(), n)
        if "normaliser_fallback" in batch:
            self.train_fallback.update(batch["normaliser_fallback"].reshape(-1).float())
        if self._bar_loss:  # a Lightning log call costs ~1 ms: only for an interactive bar
            self.log("loss", loss.detach(), prog_bar=True, logger=False, on_step=True,
                     on_epoch=False, batch_size=n)
        return loss

    def validation_step(self, batch: dict, batch_idx: int) -> None:
        eval_step(self.spec, self.net, batch, self.val_metrics)

    def test_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        """Scores one test batch; returns the model's output (callbacks such as
        ``bsp-eval --breakdown``'s receive it in ``on_test_batch_end``)."""
        output = eval_step(self.spec, self.net, batch, self.test_metrics)
        self.test_recordings.update(output.detach().float(), batch, self.net)
        return output.detach()

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        """The de-normalised outputs of one batch (:func:`.scoring.prediction_step`)."""
        return prediction_step(self.spec, self.net, batch)

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

    #: whether training steps log their loss for Lightning's interactive progress bar
    _bar_loss = True

    def on_fit_start(self) -> None:
        self._clock0 = (time.process_time(), time.perf_counter())
        from lightning.pytorch.callbacks import TQDMProgressBar

        self._bar_loss = isinstance(self.trainer.progress_bar_callback, TQDMProgressBar)

    def on_train_epoch_end(self) -> None:
        # cost so far, this epoch's validation included (it runs before this hook): the
        # optimiser updates, CPU seconds of this process (all its threads) and wall seconds
        # since fit started (a resumed run counts its seconds from its resume)
        self.log("cost/updates", float(self.global_step), sync_dist=True)
        cpu0, wall0 = getattr(self, "_clock0", (None, None))
        if cpu0 is not None:
            self.log("cost/cpu_s", time.process_time() - cpu0, sync_dist=True)
            self.log("cost/wall_s", time.perf_counter() - wall0, sync_dist=True)
        if self.train_loss.update_count:
            self.log("train/loss", float(self.train_loss.compute()), sync_dist=True)
        self.train_loss.reset()
        if self.train_fallback.update_count:
            self.log("train/normaliser_fallback", float(self.train_fallback.compute()),
                     sync_dist=True)
        self.train_fallback.reset()

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
        """The model's report defaults (AdamW, its scheduler) in Lightning's format."""
        try:  # the run's updates (max_steps or epochs x batches), for budget-long schedules
            total = int(self.trainer.estimated_stepping_batches)
        except (RuntimeError, ValueError, OverflowError):  # no trainer, or an endless run
            total = None
        return self.net.configure_optimizers(lr=self.hparams.lr, total_steps=total)


class ClassificationTask(TaskModule):
    """Crossing vs not crossing from a 2D clip: ``f1`` (crossing = positive class),
    ``precision``, ``recall``, ``accuracy``."""
    task = "classification"


class AutoencoderTask(TaskModule):
    """Denoise/complete normalised 2D: ``pck_0.05`` and ``pckhn_0.1`` on pixels (output
    and clean target de-normalised with the target's shift and scale), ``mjr``."""
    task = "autoencoder"


class LiftingTask(TaskModule):
    """2D -> 3D: ``mpjpe_mm``, ``n_mpjpe_mm``, ``pa_mpjpe_mm``, ``mpjve_mm`` of the output
    scaled by the reference skeleton's hips-neck length of each clip's (age, gender) and
    root-aligned on the target (``bsp_fast.metrics.denormalise_lifting``), on the frames
    the model predicts (:meth:`scored_frames`; PoseFormer: the central ones)."""
    task = "lifting"


class PoseEstimationTask(TaskModule):
    """Crops -> 2D joints in crop pixels: ``pck_0.05`` and ``pckhn_0.1`` over the
    visible joints."""
    task = "pose_estimation"


TASK_MODULES = {cls.task: cls for cls in (ClassificationTask, AutoencoderTask, LiftingTask,
                                          PoseEstimationTask)}


def load_module(ckpt_path, task: str | None = None, map_location="cpu") -> TaskModule:
    """Rebuilds the module of a checkpoint; ``task`` (optional) must match the saved one."""
    info = checkpoint_info(ckpt_path)
    if task is not None and info["task"] != task:
        raise ValueError(f"{ckpt_path} is a {info['task']!r} checkpoint "
                         f"({info['model']}), not {task!r}")
    cls = TASK_MODULES[info["task"]]
    return cls.load_from_checkpoint(str(ckpt_path), map_location=map_location,
                                    weights_only=True)
