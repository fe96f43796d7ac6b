"""Metrics of the report's four tasks (see docs/metrics.md).

Functional forms take NumPy arrays or torch tensors and return the same kind (a NumPy
float64 scalar, or a 0-d float64 tensor on the input's device), accumulating in float64.
Streaming forms (``torchmetrics.Metric`` subclasses: ``ClassificationMetrics`` (a dict),
``RankingMetrics`` (exact AUROC and AP, :mod:`.ranking`, from the clips it keeps) or,
torchmetrics-style, ``BinaryF1Score``, ``BinaryPrecision``, ``BinaryRecall``,
``BinaryAccuracy`` and their ``classification_collection()``; ``PCK``,
``MPJPE``, ``NMPJPE``, ``PAMPJPE``, ``MPJVE``, ``MaskedMSE``, ``MissingJointRatio``) sum
errors and counts over batches and processes; they are imported on first access because
importing torch takes seconds.
"""
from __future__ import annotations

from .classification import (
    accuracy,
    confusion_counts,
    confusion_matrix,
    f1_score,
    precision,
    predicted_labels,
    recall,
)
from .pose2d import PCKCounts, masked_mse, missing_joint_ratio, pck, pck_counts, pck_per_joint
from .pose3d import denormalise_lifting, mpjpe, mpjve, n_mpjpe, pa_mpjpe, root_align
from .threshold_free import auroc, average_precision, pck_auc, pck_curve

_STREAMING = ("ClassificationMetrics", "RankingMetrics", "BinaryF1Score", "BinaryPrecision",
              "BinaryRecall", "BinaryAccuracy", "classification_collection", "PCK", "MPJPE", "NMPJPE", "PAMPJPE", "MPJVE",
              "MaskedMSE", "MissingJointRatio", "PCKPerJoint", "FrameCount")

__all__ = [
    "f1_score", "precision", "recall", "accuracy", "confusion_matrix", "confusion_counts",
    "predicted_labels", "pck", "pck_counts", "pck_per_joint", "PCKCounts", "missing_joint_ratio",
    "masked_mse", "mpjpe", "n_mpjpe", "pa_mpjpe", "mpjve", "root_align",
    "denormalise_lifting", "auroc", "average_precision", "pck_curve", "pck_auc", *_STREAMING,
]


def __getattr__(name: str):
    if name in _STREAMING:
        from . import streaming

        return getattr(streaming, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
