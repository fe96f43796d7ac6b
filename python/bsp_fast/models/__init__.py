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

__all__ = [
    "TASKS", "available", "create", "hparams_of", "model_class", "register", "BaseModel",
    "ClassificationModel", "AutoencoderModel", "LiftingModel", "PoseEstimationModel",
    "trivial_baseline", "ForwardKinematics", "rotation_6d_to_matrix",
]

#: where each public name lives; imported on first use, so that ``models.catalogue`` (the
#: model list the commands check names against) does not import torch
_LAZY = {"BaseModel": "base", "ClassificationModel": "base", "AutoencoderModel": "base",
         "LiftingModel": "base", "PoseEstimationModel": "base",
         "TASKS": "registry", "available": "registry", "create": "registry",
         "hparams_of": "registry", "model_class": "registry", "register": "registry",
         "ForwardKinematics": "kinematics", "rotation_6d_to_matrix": "kinematics",
         "trivial_baseline": "trivial"}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    from .catalogue import MODULES

    for module in MODULES:  # the registry is complete once every model module ran
        importlib.import_module(f".{module}", __name__)
    return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
