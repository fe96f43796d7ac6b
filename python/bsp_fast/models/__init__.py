"""The report's baseline models as plain ``torch.nn.Module`` s, by task and name.

>>> from bsp_fast import models
>>> models.available("lifting")            # {name: description}
>>> model = models.create("lifting", "poseformer", receptive_field=9)
>>> out = model.forward_batch(batch)       # a ClipDataset batch dict
>>> loss = model.loss(out, batch)
>>> model.configure_optimizers()  # {"optimizer": AdamW, "lr_scheduler": {...}}

See docs/models.md for architectures, defaults, parameter counts and speed.
"""
from __future__ import annotations

from .base import (AutoencoderModel, BaseModel, ClassificationModel, LiftingModel,
                   PoseEstimationModel)
from .registry import TASKS, available, create, hparams_of, model_class, register
from . import (graph, lstm, martinez, pose_cnn, pose_temporal,  # noqa: F401  (register)
               poseformer, transformer)
from .kinematics import ForwardKinematics, rotation_6d_to_matrix
from .trivial import trivial_baseline

__all__ = [
    "TASKS", "available", "create", "hparams_of", "model_class", "register", "BaseModel",
    "ClassificationModel", "AutoencoderModel", "LiftingModel", "PoseEstimationModel",
    "trivial_baseline", "ForwardKinematics", "rotation_6d_to_matrix",
]
