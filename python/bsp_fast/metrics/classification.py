"""Binary classification metrics for the positive class 1 = crossing.

``pred`` is either labels ``(N,)`` (bool or integers 0/1), two-class logits ``(N, 2)``
(the class is the argmax; a tie goes to class 0) or one logit per sample ``(N,)`` float
(positive when ``sigmoid(logit) >= 0.5``, i.e. ``logit >= 0``). Logits that are NaN raise
``ValueError``: no class can be read from them. ``target`` is labels ``(N,)`` in {0, 1}.
All counts are over the whole input, so a split's value comes from summed counts
(:class:`~bsp_fast.metrics.streaming.ClassificationMetrics`), never from averaged batches.
Ratios whose denominator is 0 (e.g. precision with no positive prediction) are 0.
"""
from __future__ import annotations

import numpy as np

from ._arrays import Kind, expect, shape_of

__all__ = ["predicted_labels", "confusion_counts", "confusion_matrix", "f1_score",
           "precision", "recall", "accuracy", "scores_from_counts"]

PRED = "(N,) labels in {0, 1}, (N,) float logits or (N, 2) logits"
TARGET = "(N,) labels in {0, 1}"


def _is_float(kind, x) -> bool:
    return x.is_floating_point() if kind.torch else np.issubdtype(x.dtype, np.floating)


def _labels01(kind, x, name: str, expected: str):
    integer = (not x.is_floating_point() and not x.is_complex()) if kind.torch else \
        (x.dtype == bool or np.issubdtype(x.dtype, np.integer))
    expect(integer, name, f"{expected} (integer or bool labels)", f"dtype {x.dtype}")
    x = x.to(kind.xp.int64) if kind.torch else x.astype(np.int64)
    expect(bool(((x == 0) | (x == 1)).all()), name, expected, "labels outside {0, 1}")
    return x


def predicted_labels(pred, kind: Kind | None = None):
    """Predicted labels ``(N,)`` int64 (1 = crossing) from labels or logits."""
    kind = kind or Kind(pred)
    s = shape_of(pred)
    expect((len(s) == 1 or (len(s) == 2 and s[1] == 2)) and s[0] > 0, "pred", PRED,
           f"shape {s}")
    x = kind.native(pred)
    if not _is_float(kind, x):
        expect(len(s) == 1, "pred", PRED, f"shape {s} of integer labels")
        return _labels01(kind, x, "pred", PRED)
    expect(not bool(kind.xp.isnan(x).any()), "pred", f"{PRED} without NaN",
           "NaN logits")
    if len(s) == 2:
        lab = x[:, 1] > x[:, 0]
    else:
        lab = x >= 0
    return lab.to(kind.xp.int64) if kind.torch else lab.astype(np.int64)


def confusion_counts(pred, target):
    """``(tp, fp, fn, tn)`` as int64 0-d arrays/tensors of the inputs' kind."""
    st = shape_of(target)
    expect(len(st) == 1 and st[0] > 0, "target", TARGET, f"shape {st}")
    expect(shape_of(pred)[:1] == st, "pred and target", f"the same N: pred {PRED}, "
           f"target {TARGET}", f"pred {shape_of(pred)} and target {st}")
    kind = Kind(pred, target)
    p = predicted_labels(pred, kind)
    t = _labels01(kind, kind.native(target), "target", TARGET)
    tp = (p * t).sum()
    fp = (p * (1 - t)).sum()
    fn = ((1 - p) * t).sum()
    return tp, fp, fn, (p.shape[0] - tp - fp - fn)


def confusion_matrix(pred, target):
    """2x2 int64 counts, rows = true class, columns = predicted class:
    ``[[tn, fp], [fn, tp]]``."""
    kind = Kind(pred, target)
    tp, fp, fn, tn = confusion_counts(pred, target)
    return kind.xp.stack([kind.xp.stack([tn, fp]), kind.xp.stack([fn, tp])])


def _div(a, b):
    return a / b if b else 0.0


def scores_from_counts(tp, fp, fn, tn) -> dict:
    """``{"f1", "precision", "recall", "accuracy"}`` (Python floats) from counts."""
    tp, fp, fn, tn = (int(v) for v in (tp, fp, fn, tn))
    return {"f1": _div(2 * tp, 2 * tp + fp + fn), "precision": _div(tp, tp + fp),
            "recall": _div(tp, tp + fn), "accuracy": _div(tp + tn, tp + fp + fn + tn)}


def _score(name, pred, target):
    return Kind(pred, target).scalar(scores_from_counts(*confusion_counts(pred, target))[name])


def f1_score(pred, target):
    """F1 of the crossing class, ``2 TP / (2 TP + FP + FN)`` (0 when nothing is positive
    in either ``pred`` or ``target``)."""
    return _score("f1", pred, target)


def precision(pred, target):
    """``TP / (TP + FP)`` (0 without positive predictions)."""
    return _score("precision", pred, target)


def recall(pred, target):
    """``TP / (TP + FN)`` (0 without positive targets)."""
    return _score("recall", pred, target)


def accuracy(pred, target):
    """Share of samples whose predicted class equals the target."""
    return _score("accuracy", pred, target)
