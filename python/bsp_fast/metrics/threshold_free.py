"""Threshold-free metrics beside the report's: AUROC and average precision for the crossing
classifier, and the area under the PCK curve (PCK-AUC) for 2D poses.

The report's F1 and PCK@α each depend on one threshold (0.5 on the probability, α on the
normalised distance); these summarise every threshold at once, so two models can be
compared without the choice of threshold deciding the order.
"""
from __future__ import annotations

import numpy as np

from . import ranking
from ._arrays import Kind, expect, shape_of
from .pose2d import NORMS, pck_counts

__all__ = ["positive_scores", "auroc", "average_precision", "pck_curve", "pck_auc",
           "PCK_AUC_ALPHAS"]

SCORES = "(N,) float logits/probabilities or (N, 2) logits"
#: α grid of :func:`pck_auc`: 0 to 0.2 in steps of 0.01 (21 points).
PCK_AUC_ALPHAS = tuple(round(0.01 * i, 2) for i in range(21))


def positive_scores(pred):
    """One score per sample that increases with the crossing class's probability:
    ``logit_1 - logit_0`` for ``(N, 2)`` logits, the input itself for ``(N,)``. Ranking
    metrics depend only on this order, so the scores need not be probabilities."""
    s = shape_of(pred)
    expect((len(s) == 1 or (len(s) == 2 and s[1] == 2)) and s[0] > 0, "pred", SCORES,
           f"shape {s}")
    kind = Kind(pred)
    x = kind.f64(pred)
    expect(not bool(kind.xp.isnan(x).any()), "pred", f"{SCORES} without NaN", "NaN scores")
    return x[:, 1] - x[:, 0] if len(s) == 2 else x


def _np(x):
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def auroc(pred, target) -> float:
    """Area under the ROC curve of the crossing class (ties count one half): the chance
    that a random crossing sample scores above a random non-crossing one. NaN when the
    target has a single class. ``pred``: scores or logits (:func:`positive_scores`);
    computed exactly by :func:`bsp_fast.metrics.ranking.auroc`."""
    return ranking.auroc(np.asarray(positive_scores(_np(pred))), _np(target))


def average_precision(pred, target) -> float:
    """Average precision of the crossing class: ``Σ_n (R_n − R_{n−1}) P_n`` over the
    distinct score thresholds, highest first (the step-wise area under the
    precision-recall curve, without interpolation). NaN when no sample is positive.
    Computed exactly by :func:`bsp_fast.metrics.ranking.average_precision`."""
    return ranking.average_precision(np.asarray(positive_scores(_np(pred))), _np(target))


def pck_curve(pred, gt, *, alphas=PCK_AUC_ALPHAS, norm: str = "bbox", visible=None):
    """PCK at each α of ``alphas`` (a fraction each; α = 0 counts exact hits only), with
    :func:`bsp_fast.metrics.pck`'s joints, frames and normalisers. Returns a float64
    NumPy array like ``alphas``."""
    if norm not in NORMS:
        raise ValueError(f"norm must be one of {NORMS}, got {norm!r}")
    a = np.asarray(alphas, dtype=np.float64)
    if a.ndim != 1 or a.size == 0 or not np.isfinite(a).all() or (a < 0).any():
        raise ValueError(f"alphas must be a non-empty 1-D sequence of finite numbers >= 0, "
                         f"got {alphas!r}")
    out = np.empty_like(a)
    for i, alpha in enumerate(a):
        # pck_counts needs α > 0; α = 0 is the limit from above (distance exactly 0)
        c = pck_counts(pred, gt, alpha=float(alpha) if alpha > 0 else 1e-300, norm=norm,
                       visible=visible)
        out[i] = c.value
    return out


def pck_auc(pred, gt, *, alphas=PCK_AUC_ALPHAS, norm: str = "bbox", visible=None) -> float:
    """Area under the PCK(α) curve divided by the α range (trapezoids over ``alphas``,
    default 0 to 0.2): 1 when every counted joint is exact, 0 when none is within
    0.2 · S. A fraction in [0, 1]."""
    a = np.asarray(alphas, dtype=np.float64)
    curve = pck_curve(pred, gt, alphas=alphas, norm=norm, visible=visible)
    if a.size < 2 or a[-1] <= a[0] or (np.diff(a) <= 0).any():
        raise ValueError("alphas must be increasing, with at least two values")
    return float(np.trapezoid(curve, a) / (a[-1] - a[0]))
