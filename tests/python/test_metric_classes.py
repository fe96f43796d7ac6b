"""bsp_fast.metrics' classification metrics in torchmetrics' style: each a Metric of its own,
the four as one MetricCollection sharing its confusion counts, against counts by hand."""
from __future__ import annotations

import pytest


def test_single_metric_classes_and_collection_match_hand_counts():
    import torch
    from torchmetrics import Metric, MetricCollection

    from bsp_fast.metrics import (BinaryAccuracy, BinaryF1Score, BinaryPrecision,
                                  BinaryRecall, ClassificationMetrics,
                                  classification_collection)

    # batch 1 (labels): tp 2, fp 1, fn 1, tn 1; batch 2 (logits, threshold 0 -> 1, 0, 1
    # against 1, 1, 0): tp 1, fn 1, fp 1. In all: tp 3, fp 2, fn 2, tn 1 (by hand).
    batches = [(torch.tensor([1, 1, 0, 0, 1]), torch.tensor([1, 0, 0, 1, 1])),
               (torch.tensor([0.9, -2.0, 3.0]), torch.tensor([1, 1, 0]))]
    want_first = {"precision": 2 / 3, "recall": 2 / 3}
    singles = {"f1": BinaryF1Score(), "precision": BinaryPrecision(),
               "recall": BinaryRecall(), "accuracy": BinaryAccuracy()}
    coll = classification_collection(prefix="val/")
    both = ClassificationMetrics()
    assert isinstance(coll, MetricCollection)
    for m in singles.values():
        assert isinstance(m, Metric)
    for k, (p, t) in enumerate(batches):
        for m in list(singles.values()) + [coll, both]:
            m.update(p, t)
        if k == 0:
            assert float(singles["precision"].compute()) == pytest.approx(want_first["precision"])
            assert float(singles["recall"].compute()) == pytest.approx(want_first["recall"])
    want = {"f1": 6 / (6 + 2 + 2), "precision": 3 / 5, "recall": 3 / 5, "accuracy": 4 / 8}
    for name, m in singles.items():
        value = m.compute()
        assert value.ndim == 0 and value.dtype == torch.float64
        assert float(value) == pytest.approx(want[name]), name
    got = coll.compute()
    assert sorted(got) == ["val/accuracy", "val/f1", "val/precision", "val/recall"]
    for name in want:
        assert float(got[f"val/{name}"]) == pytest.approx(want[name])
        assert float(both.compute()[name]) == pytest.approx(want[name])
    # one set of confusion counts for the four (torchmetrics' compute groups)
    assert len(coll.compute_groups) == 1
    assert singles["f1"].confusion_matrix().tolist() == [[1, 2], [2, 3]]
