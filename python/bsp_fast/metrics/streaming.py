"""Streaming forms of the metrics: ``torchmetrics.Metric`` subclasses.

Each keeps global sums and counts (float64 sums, int64 counts) over every ``update`` and
gives the split's value in ``compute()``: the ratio of the sums, never a mean of batch
means. States are reduced with ``dist_reduce_fx="sum"``, so under DDP ``compute()`` returns
the value over all processes' data (Lightning's ``self.log(name, metric)`` or
``metric.compute()``). Updates take tensors or NumPy arrays; the sums are those of the
functional forms (``*_sums`` in :mod:`~bsp_fast.metrics.pose3d` and
:mod:`~bsp_fast.metrics.pose2d`), so a split cut into any batches gives the one-shot value.
"""
from __future__ import annotations

import numpy as np
import torch
from torchmetrics import Metric

from . import classification as _cls
from . import pose2d as _p2
from . import pose3d as _p3
from . import ranking as _rank

__all__ = ["ClassificationMetrics", "RankingMetrics", "BinaryF1Score", "BinaryPrecision",
           "BinaryRecall", "BinaryAccuracy", "classification_collection", "PCK", "MPJPE", "NMPJPE", "PAMPJPE", "MPJVE",
           "MaskedMSE", "MissingJointRatio", "PCKPerJoint", "FrameCount"]


def _accumulate(metric: Metric, name: str, value) -> None:
    """``metric.<name> += value`` without a device round trip for tensors."""
    state = getattr(metric, name)
    setattr(metric, name, state + torch.as_tensor(value, device=state.device).to(state.dtype))


class _Summed(Metric):
    """``compute() = total / count`` over every update (NaN before any data)."""

    is_differentiable = False
    higher_is_better = False
    full_state_update = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_state("total", torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum")
        self.add_state("count", torch.tensor(0, dtype=torch.int64), dist_reduce_fx="sum")

    def _add(self, total, count) -> None:
        _accumulate(self, "total", total)
        _accumulate(self, "count", count)

    def compute(self) -> torch.Tensor:
        if int(self.count) == 0:
            return torch.tensor(float("nan"), dtype=torch.float64, device=self.total.device)
        return self.total / self.count


class MPJPE(_Summed):
    """Streaming :func:`~bsp_fast.metrics.mpjpe`: ``update(pred, gt)`` on ``(..., J, 3)``."""

    def update(self, pred, gt) -> None:
        self._add(*_p3.mpjpe_sums(pred, gt))


class NMPJPE(_Summed):
    """Streaming :func:`~bsp_fast.metrics.n_mpjpe`: ``update(pred, gt)``."""

    def update(self, pred, gt) -> None:
        self._add(*_p3.n_mpjpe_sums(pred, gt))


class PAMPJPE(_Summed):
    """Streaming :func:`~bsp_fast.metrics.pa_mpjpe`: ``update(pred, gt)``."""

    def update(self, pred, gt) -> None:
        self._add(*_p3.pa_mpjpe_sums(pred, gt))


class MPJVE(_Summed):
    """Streaming :func:`~bsp_fast.metrics.mpjve`: ``update(pred, gt)`` on clips
    ``(B, L, J, 3)`` (differences inside each clip; clips of a batch never touch)."""

    def update(self, pred, gt) -> None:
        self._add(*_p3.mpjve_sums(pred, gt))


class MaskedMSE(_Summed):
    """Streaming :func:`~bsp_fast.metrics.masked_mse`: ``update(pred, target, mask=None)``."""

    def update(self, pred, target, mask=None) -> None:
        self._add(*_p2.masked_mse_sums(pred, target, mask))


class MissingJointRatio(_Summed):
    """Streaming :func:`~bsp_fast.metrics.missing_joint_ratio`: ``update(visible)``."""

    def update(self, visible) -> None:
        self._add(*_p2.missing_joint_ratio_sums(visible))


class PCK(Metric):
    """Streaming :func:`~bsp_fast.metrics.pck`: ``update(pred, gt, visible=None)`` on
    ``(..., 26, 2)`` pixels; ``compute()`` -> fraction correct. ``skipped_frames`` /
    ``scored_frames`` count the frames left out (degenerate normaliser) and kept."""

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(self, alpha: float = 0.05, norm: str = "bbox", align=None, **kwargs):
        _p2._check_options(alpha, norm, align)
        super().__init__(**kwargs)
        self.alpha, self.norm, self.align = float(alpha), norm, align
        for name in ("correct", "joints", "frames", "skipped"):
            self.add_state(name, torch.tensor(0, dtype=torch.int64), dist_reduce_fx="sum")

    def update(self, pred, gt, visible=None, select=None) -> None:
        terms = _p2._pck_terms(pred, gt, self.alpha, self.norm, visible, select, self.align)
        for name, value in zip(("correct", "joints", "frames", "skipped"), terms):
            _accumulate(self, name, value)

    def compute(self) -> torch.Tensor:
        if int(self.joints) == 0:
            return torch.tensor(float("nan"), dtype=torch.float64, device=self.correct.device)
        return self.correct.to(torch.float64) / self.joints

    @property
    def skipped_frames(self) -> int:
        return int(self.skipped)

    @property
    def scored_frames(self) -> int:
        return int(self.frames)


class PCKPerJoint(Metric):
    """Streaming :func:`~bsp_fast.metrics.pck_per_joint`: ``compute()`` -> ``{f"{prefix}
    {joint name}": fraction}`` for the 26 CARLA joints (NaN for a joint never counted)."""

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(self, alpha: float = 0.05, norm: str = "bbox", prefix: str = "pck_0.05/",
                 **kwargs):
        _p2._check_options(alpha, norm)
        super().__init__(**kwargs)
        self.alpha, self.norm, self.prefix = float(alpha), norm, prefix
        for name in ("correct", "joints"):
            self.add_state(name, torch.zeros(26, dtype=torch.int64), dist_reduce_fx="sum")

    def update(self, pred, gt, visible=None, select=None) -> None:
        c, t, _, _ = _p2._pck_terms(pred, gt, self.alpha, self.norm, visible, select,
                                    per_joint=True)
        self.correct += c.to(self.correct.device)
        self.joints += t.to(self.joints.device)

    def compute(self) -> dict:
        from ..skeleton import JOINT_NAMES

        value = self.correct.to(torch.float64) / self.joints.clamp_min(1)
        value = torch.where(self.joints > 0, value, torch.nan)
        return {f"{self.prefix}{n}": value[j] for j, n in enumerate(JOINT_NAMES)}


class FrameCount(Metric):
    """A count of frames: ``update(mask)`` adds ``mask.sum()``; ``compute()`` -> float."""

    is_differentiable = False
    full_state_update = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_state("count", torch.tensor(0, dtype=torch.int64), dist_reduce_fx="sum")

    def update(self, mask) -> None:
        self.count += mask.sum().to(self.count.device)

    def compute(self) -> torch.Tensor:
        return self.count.to(torch.float64)


class _Confusion(Metric):
    """Summed confusion counts ``tp, fp, fn, tn`` of the crossing class (shared state of
    the classification metrics: a ``MetricCollection`` of them updates it once)."""

    is_differentiable = False
    higher_is_better = True
    full_state_update = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for name in ("tp", "fp", "fn", "tn"):
            self.add_state(name, torch.tensor(0, dtype=torch.int64), dist_reduce_fx="sum")

    def update(self, pred, target) -> None:
        for name, value in zip(("tp", "fp", "fn", "tn"), _cls.confusion_counts(pred, target)):
            _accumulate(self, name, value)

    def _scores(self) -> dict:
        return _cls.scores_from_counts(self.tp, self.fp, self.fn, self.tn)

    def confusion_matrix(self) -> torch.Tensor:
        """``[[tn, fp], [fn, tp]]`` (rows = true class) of everything seen so far (this
        process's counts; after ``compute()`` under DDP, while synced, the global ones)."""
        return torch.stack([torch.stack([self.tn, self.fp]), torch.stack([self.fn, self.tp])])


class ClassificationMetrics(_Confusion):
    """Streaming F1 / precision / recall / accuracy of the crossing class from summed
    confusion counts: ``update(pred, target)`` (labels or logits, see
    :mod:`~bsp_fast.metrics.classification`); ``compute()`` -> dict of float64 tensors
    ``{"f1", "precision", "recall", "accuracy"}``; ``confusion_matrix()`` -> 2x2.
    The torchmetrics-style single metrics are :class:`BinaryF1Score`,
    :class:`BinaryPrecision`, :class:`BinaryRecall`, :class:`BinaryAccuracy`, and
    :func:`classification_collection` groups them."""

    def compute(self) -> dict:
        return {k: torch.tensor(v, dtype=torch.float64, device=self.tp.device)
                for k, v in self._scores().items()}


class RankingMetrics(Metric):
    """Streaming AUROC and AP of the crossing class (:mod:`~bsp_fast.metrics.ranking`,
    exact): ``update(scores, labels, tte=None, row=None)`` keeps every clip's score (the
    model's P(crossing)), label, time to event (-1: none) and dataset row as ``cat``
    states (gathered over DDP processes); ``compute()`` -> ``{"auroc", "ap"}`` float64
    tensors of everything kept, the same for any batching. ``clips()`` gives the kept
    clips as NumPy arrays ordered by row (the per-recording file stores them)."""

    is_differentiable = False
    higher_is_better = True
    full_state_update = False
    FIELDS = ("score", "label", "tte", "row")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for name in self.FIELDS:
            self.add_state(name, [], dist_reduce_fx="cat")

    def update(self, scores, labels, tte=None, row=None) -> None:
        n = len(scores)
        if n == 0:
            return
        values = {"score": (scores, torch.float64), "label": (labels, torch.int64),
                  "tte": (tte if tte is not None else torch.full((n,), -1), torch.int64),
                  "row": (row if row is not None else torch.full((n,), -1), torch.int64)}
        for name, (v, dtype) in values.items():
            t = torch.as_tensor(v).reshape(-1).to(device=self.device, dtype=dtype)
            if len(t) != n:
                raise ValueError(f"RankingMetrics.update: {name} has {len(t)} values for "
                                 f"{n} scores")
            getattr(self, name).append(t)

    def clips(self) -> dict:
        """``{"score", "label", "tte", "row"}`` NumPy arrays of the clips kept by this
        process (all processes' after ``compute()``'s sync), ordered by row (stable)."""
        from torchmetrics.utilities import dim_zero_cat

        out = {}
        for name in self.FIELDS:
            state = getattr(self, name)
            out[name] = (dim_zero_cat(state).cpu().numpy() if len(state) else
                         np.zeros(0, np.float64 if name == "score" else np.int64))
        order = np.argsort(out["row"], kind="stable")
        return {k: v[order] for k, v in out.items()}

    def compute(self) -> dict:
        c = self.clips()
        return {"auroc": torch.tensor(_rank.auroc(c["score"], c["label"]), dtype=torch.float64),
                "ap": torch.tensor(_rank.average_precision(c["score"], c["label"]),
                                   dtype=torch.float64)}


class _OneScore(_Confusion):
    score = ""

    def compute(self) -> torch.Tensor:
        return torch.tensor(self._scores()[self.score], dtype=torch.float64,
                            device=self.tp.device)


class BinaryF1Score(_OneScore):
    """Streaming F1 of the crossing class (one tensor, as ``torchmetrics``'s
    ``BinaryF1Score``): ``update(pred, target)`` with labels or logits (threshold and
    argmax rules of :mod:`~bsp_fast.metrics.classification`); 0 when nothing is
    predicted or true (no NaN)."""

    score = "f1"


class BinaryPrecision(_OneScore):
    """Streaming precision of the crossing class (see :class:`BinaryF1Score`)."""

    score = "precision"


class BinaryRecall(_OneScore):
    """Streaming recall of the crossing class (see :class:`BinaryF1Score`)."""

    score = "recall"


class BinaryAccuracy(_OneScore):
    """Streaming accuracy (see :class:`BinaryF1Score`)."""

    score = "accuracy"


def classification_collection(prefix: str | None = None, postfix: str | None = None):
    """A ``torchmetrics.MetricCollection`` of :class:`BinaryF1Score`,
    :class:`BinaryPrecision`, :class:`BinaryRecall` and :class:`BinaryAccuracy` under the
    keys ``f1``, ``precision``, ``recall``, ``accuracy`` (with ``prefix``/``postfix``, e.g.
    ``prefix="val/"``). Their states are the same confusion counts, so the collection
    updates one set of counts per batch (torchmetrics' compute groups)."""
    from torchmetrics import MetricCollection

    return MetricCollection({"f1": BinaryF1Score(), "precision": BinaryPrecision(),
                             "recall": BinaryRecall(), "accuracy": BinaryAccuracy()},
                            prefix=prefix, postfix=postfix, compute_groups=True)
