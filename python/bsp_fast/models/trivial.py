"""Do-nothing baselines per task (the training CLI's "initial metrics"): majority class,
identity, mean training pose, mean crop skeleton. Each is a :class:`BaseModel` with
``fit(batches)`` over train-split batch dicts and the task's loss."""
from __future__ import annotations

import torch

from .. import skeleton as _sk
from .base import (AutoencoderModel, ClassificationModel, LiftingModel, PoseEstimationModel,
                   check_choice)
from .registry import TASKS

__all__ = ["trivial_baseline", "MajorityClass", "Identity", "MeanPose", "MeanCropSkeleton"]

J = _sk.NUM_JOINTS


class _Trivial:
    fitted = False

    def fit(self, batches):
        """Consumes an iterable of batch dicts (train split); returns self."""
        for batch in batches:
            self._update(batch)
        self._finish()
        self.fitted = True
        return self

    def _update(self, batch):
        pass

    def _finish(self):
        pass


class MajorityClass(_Trivial, ClassificationModel):
    """Logits = log of the training class frequencies: predicts the majority class, and
    its cross-entropy is the entropy of the labels."""

    task, name = "classification", "majority_class"

    def __init__(self):
        super().__init__({})
        self.use_visible = False
        self.register_buffer("counts", torch.zeros(2, dtype=torch.float64))
        self.register_buffer("logits", torch.zeros(2))

    def _update(self, batch):
        self.counts += torch.bincount(batch["targets"].long().flatten(), minlength=2).double()

    def _finish(self):
        p = (self.counts + 1e-3) / (self.counts + 1e-3).sum()
        self.logits.copy_(p.log().float())

    def compute(self, inputs, visible):
        return self.logits.expand(inputs.shape[0], 2).to(inputs.dtype)

    @property
    def majority(self) -> int:
        return int(self.counts.argmax())


class Identity(_Trivial, AutoencoderModel):
    """The deformed input as the prediction (fit is a no-op)."""

    task, name = "autoencoder", "identity"

    def __init__(self):
        super().__init__({})
        self.use_visible = False

    def compute(self, inputs, visible):
        return inputs.clone()


class MeanPose(_Trivial, LiftingModel):
    """The mean normalised 3D training pose, for every frame."""

    task, name = "lifting", "mean_pose"

    def __init__(self):
        super().__init__({})
        self.use_visible = False
        self.register_buffer("total", torch.zeros(J, 3, dtype=torch.float64))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("pose", torch.zeros(J, 3))

    def _update(self, batch):
        t = batch["targets"].double()
        self.total += t.sum(dim=(0, 1))
        self.count += t.shape[0] * t.shape[1]

    def _finish(self):
        self.pose.copy_((self.total / self.count.clamp_min(1)).float())

    def compute(self, inputs, visible):
        B, L = inputs.shape[:2]
        return self.pose.expand(B, L, J, 3).to(inputs.dtype)


class MeanCropSkeleton(_Trivial, PoseEstimationModel):
    """The mean of each joint's visible training positions in crop pixels."""

    task, name = "pose_estimation", "mean_crop_skeleton"

    def __init__(self):
        super().__init__({})
        self.register_buffer("total", torch.zeros(J, 2, dtype=torch.float64))
        self.register_buffer("count", torch.zeros(J, dtype=torch.float64))
        self.register_buffer("pose", torch.zeros(J, 2))
        self.crop_size = 0

    def _update(self, batch):
        if "inputs" in batch:
            self.crop_size = int(batch["inputs"].shape[-1])
        t = batch["targets"].double()
        vis = batch.get("visible")
        m = torch.ones(t.shape[:-1], dtype=torch.bool) if vis is None else vis.bool()
        m = m & torch.isfinite(t).all(-1)  # a frame without a crop has NaN targets
        self.total += torch.where(m.unsqueeze(-1), t, 0.0).sum(dim=(0, 1))
        self.count += m.double().sum(dim=(0, 1))

    def _finish(self):
        self.pose.copy_((self.total / self.count.clamp_min(1).unsqueeze(-1)).float())

    def compute(self, inputs, visible):
        B, L = inputs.shape[:2]
        return self.pose.expand(B, L, J, 2).clone()


_BASELINES = {"classification": MajorityClass, "autoencoder": Identity,
              "lifting": MeanPose, "pose_estimation": MeanCropSkeleton}


def trivial_baseline(task: str):
    """A fresh do-nothing baseline for ``task``; call ``.fit(train_batches)`` (Identity
    needs no fitting)."""
    check_choice("task", task, TASKS)
    return _BASELINES[task]()
