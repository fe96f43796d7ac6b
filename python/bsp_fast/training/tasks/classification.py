"""Crossing vs not crossing from a 2D clip: F1 of the crossing class, precision, recall,
accuracy (argmax of two logits, or sigmoid >= 0.5 of one), and the PIE/JAAD crossing
benchmark's threshold-free AUROC and average precision (``ap``) of the model's
P(crossing), computed exactly over the split (:mod:`bsp_fast.metrics.ranking`)."""
from __future__ import annotations

from ...metrics.spec import Metric
from .base import Task

__all__ = ["Classification", "constant_f1"]


def constant_f1(initial: dict):
    """F1 of the better constant classifier on a split, from the majority-class baseline's
    metrics there: always "crossing" scores 2p / (1 + p) with p the crossing share, which
    is at least the majority class's F1 (0 when the majority does not cross). A classifier
    that only learnt to say "crossing" reaches this without looking at the poses."""
    acc, f1 = initial.get("accuracy"), initial.get("f1")
    if acc is None or f1 is None:
        return None
    p = acc if f1 > 0 else 1.0 - acc
    return 2 * p / (1 + p)


class Classification(Task):
    name = "classification"
    description = "crossing vs not crossing from a 2D clip"
    batch_keys = ("inputs", "visible", "targets", "label", "meta")
    baseline = "majority class"
    prediction_units = None  # logits, probabilities and 0/1 predictions
    metrics = (Metric("f1", "F1", "fraction", "higher", ".3f"),
               Metric("precision", "precision", "fraction", "higher", ".3f"),
               Metric("recall", "recall", "fraction", "higher", ".3f"),
               Metric("accuracy", "accuracy", "fraction", "higher", ".3f"),
               Metric("auroc", "AUROC", "fraction", "higher", ".3f"),
               Metric("ap", "AP", "fraction", "higher", ".3f"))
    curves = ("f1", "precision", "recall")
    deformed_inputs = True
    augments = True
    finding_baselines = {"constant": ("best constant", constant_f1)}
    breakdown_scores = "logits"

    def metric_modules(self) -> dict:
        from ... import metrics as M

        return {"cls": M.ClassificationMetrics(), "ranking": M.RankingMetrics()}

    def update_metrics(self, scores, output, batch, model) -> None:
        from ...metrics.ranking import crossing_probability

        scores["cls"].update(output, batch["label"])
        meta = batch.get("meta") or {}  # a hand-built batch may have none: -1 for both
        # every clip's P(crossing) with its time to event (-1: none) and row: AUROC and AP
        # are not sums, and the per-recording file keeps the clips themselves
        scores["ranking"].update(crossing_probability(output), batch["label"],
                                 tte=meta.get("tte"), row=meta.get("row"))

    def predictions(self, output, batch, model) -> dict:
        import torch

        prob = torch.sigmoid(output) if output.ndim == 1 else torch.softmax(output, -1)[:, 1]
        sl = self.scored_frames(model, batch["inputs"].shape[1])
        return {"logits": output, "probability": prob,
                "prediction": (prob >= 0.5).to(torch.int8),
                "frames": batch["meta"]["frames"][:, sl]}
