"""Ranking metrics of the crossing classifier, computed exactly: the area under the ROC
curve (AUROC) and average precision (AP) of the crossing class (label 1), from one score
per clip (the model's P(crossing), :func:`crossing_probability`) and the clips' labels.

Both depend only on the order of the scores, and both are computed on all clips at once
in float64: no threshold grid and no float32 curve (torchmetrics' ``BinaryAUROC`` and
``BinaryAveragePrecision`` with ``thresholds=None`` define the same values, tested, but
build their curves in the scores' float32). So a split's value is the same however it was
cut into batches and in whatever order its clips come, and a bootstrap over recordings
may pool the resampled recordings' clips and call these functions again
(``test_per_recording.json``, :mod:`bsp_fast.training.per_recording`).

* ``auroc``: the chance that a random crossing clip scores above a random non-crossing
  one, ties counting one half (Mann-Whitney U / (n1 n0)), which is the trapezoidal area
  under the ROC curve over the distinct scores. NaN when one class is absent.
* ``average_precision``: ``sum_n (R_n - R_{n-1}) P_n`` over the distinct scores taken as
  thresholds, highest first (the step-wise area under the precision-recall curve, without
  interpolation; sklearn's ``average_precision_score``). NaN without a crossing clip.

This module imports neither torch nor Lightning: tensors are accepted and read as NumPy.
"""
from __future__ import annotations

import numpy as np

from ._arrays import expect

__all__ = ["auroc", "average_precision", "crossing_probability"]

SCORES = "(N,) scores without NaN"
LABELS = "(N,) labels in {0, 1}"
OUTPUT = "(N,) logits of crossing or (N, 2) logits of (not crossing, crossing)"


def _numpy(x) -> np.ndarray:
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def _checked(scores, labels) -> tuple:
    """``(scores float64, labels bool)`` after the shape and value checks."""
    s, y = _numpy(scores), _numpy(labels)
    expect(s.ndim == 1, "scores", SCORES, f"shape {s.shape}")
    expect(y.ndim == 1 and len(y) == len(s), "labels", f"{LABELS} with N = {len(s)} as "
           "the scores", f"shape {y.shape}")
    expect(s.dtype.kind in "biuf", "scores", SCORES, f"dtype {s.dtype}")
    s = s.astype(np.float64)
    expect(not np.isnan(s).any(), "scores", SCORES, f"{int(np.isnan(s).sum())} NaN")
    expect(y.dtype.kind in "biuf" and bool(((y == 0) | (y == 1)).all()), "labels", LABELS,
           "labels outside {0, 1}" if y.dtype.kind in "biuf" else f"dtype {y.dtype}")
    return s, y.astype(bool)


def auroc(scores, labels) -> float:
    """AUROC of the crossing class (see the module docstring): ``scores`` ``(N,)`` (higher
    = more likely crossing), ``labels`` ``(N,)`` in {0, 1}. NaN with one class."""
    from scipy.stats import rankdata

    s, y = _checked(scores, labels)
    n1 = int(y.sum())
    n0 = len(y) - n1
    if n1 == 0 or n0 == 0:
        return float("nan")
    # the crossing clips' rank sum, ties averaged; ranks are halves of integers, so the
    # sum is exact in float64 whatever the order of the clips
    r1 = float(rankdata(s)[y].sum())
    return (r1 - n1 * (n1 + 1) / 2.0) / (n1 * n0)


def average_precision(scores, labels) -> float:
    """AP of the crossing class (see the module docstring): ``scores`` ``(N,)``,
    ``labels`` ``(N,)`` in {0, 1}. NaN without a crossing clip."""
    s, y = _checked(scores, labels)
    if not y.any():
        return float("nan")
    order = np.argsort(-s, kind="stable")
    s, y = s[order], y[order]
    # the last clip of each distinct score: everything up to it is predicted crossing
    last = np.r_[np.flatnonzero(np.diff(s)), len(s) - 1]
    tp = np.cumsum(y, dtype=np.int64)[last]
    precision = tp / (last + 1.0)
    recall_step = np.diff(np.r_[0, tp]) / float(tp[-1])
    return float(np.sum(recall_step * precision))


def crossing_probability(output) -> np.ndarray:
    """The model's P(crossing) per clip, float64 ``(N,)``, from its logits ``output``:
    ``sigmoid(x)`` of one logit per clip, ``softmax(x)[:, 1] = sigmoid(x1 - x0)`` of two
    (as ``Classification.predictions`` gives it). In float64, so that scores differing in
    float32 logits stay apart: their order is what AUROC and AP measure."""
    from scipy.special import expit

    x = _numpy(output)
    expect((x.ndim == 1 or (x.ndim == 2 and x.shape[1] == 2)) and x.dtype.kind == "f",
           "output", OUTPUT, f"shape {x.shape}, dtype {x.dtype}")
    x = x.astype(np.float64)
    expect(not np.isnan(x).any(), "output", f"{OUTPUT} without NaN", "NaN logits")
    return expit(x[:, 1] - x[:, 0] if x.ndim == 2 else x)
