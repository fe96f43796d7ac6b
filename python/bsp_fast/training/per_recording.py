"""Test metrics per recording: the sums and counts behind every metric, kept apart for
each recording of the split, so that intervals can resample whole recordings
(:mod:`bsp_fast.metrics.uncertainty`).

A recording is ``video_id/pedestrian_id`` (one pedestrian seen by one camera); its clips
overlap (sliding windows), so they are not independent test units, the recordings are.
Every metric of :class:`~bsp_fast.training.scoring.TaskMetrics` but two is a ratio of
global sums, ``value = sum(num) / sum(den)``; this module keeps ``num`` and ``den`` per
recording. The two are classification's AUROC and AP (``auroc``, ``ap``), functions of
the clips' ranks, not of sums: for them each recording keeps its clips, ``[score, label,
tte]`` each (:data:`CLIP_FIELDS`: the model's P(crossing) as a float64 number, the label
0/1, the frames from the clip's last frame to the event, -1 where the clip file has none),
in the split's stored order. A run directory stores all of it as
``test_per_recording.json`` (:data:`FILE`)::

    {"unit": "recording (video_id/pedestrian_id)", "task": ...,
     "test":    {"recordings": [...], "metrics": {name: {"num": [...], "den": [...]}},
                 "clips": [[[score, label, tte], ...], ...]},   # classification only
     "initial": {...the trivial baseline's, same layout...},
     "empty":   {name: value of a metric with den = 0 (null: undefined)},
     "clip_fields": ["score", "label", "tte"]}                  # classification only

``clips[i]`` belongs to ``recordings[i]``. A bootstrap over recordings recomputes AUROC
and AP of a resample from its recordings' clips pooled (:func:`pooled_clips`, then
:func:`bsp_fast.metrics.ranking.auroc` / ``average_precision``); files written before
the clips were kept have no ``clips``.
"""
from __future__ import annotations

import torch

from .runs import PER_RECORDING_FILE
from .scoring import TaskMetrics

__all__ = ["FILE", "RecordingBreakdown", "recording_ids", "ratio_terms", "write_breakdown",
           "EMPTY", "CLIP_FIELDS", "pooled_clips"]

FILE = PER_RECORDING_FILE
#: what each clip of a section's ``clips`` holds, in order
CLIP_FIELDS = ("score", "label", "tte")
#: value of a classification score with nothing to count (as ``scores_from_counts``)
EMPTY = {"f1": 0.0, "precision": 0.0, "recall": 0.0, "accuracy": 0.0, "f1_constant": 0.0}


def recording_ids(meta: dict) -> list:
    """``video_id/pedestrian_id`` of each clip of a batch's ``meta``."""
    return [f"{v}/{p}" for v, p in zip(meta["video_id"], meta["pedestrian_id"])]


def ratio_terms(metrics: TaskMetrics) -> dict:
    """``{metric: (num, den)}`` (floats) of every metric a :class:`TaskMetrics` has
    counted, such that its value is ``num / den``. Classification adds ``f1_constant``:
    the F1 of always answering "crossing" on the same clips, ``2P / (2P + N)``."""
    out = {}
    for name, m in metrics.scores.items():
        if not m.update_count:
            continue
        if any(isinstance(v, list) for v in m.metric_state.values()):
            continue  # AUROC / AP: clips kept, not sums (RecordingBreakdown.clips)
        if any(torch.is_tensor(v) and v.numel() != 1 for v in m.metric_state.values()):
            continue  # per-joint PCK: not a ratio per recording
        st = {k: float(v) for k, v in m.metric_state.items()}
        if set(st) == {"count"}:  # a plain count (fully occluded frames)
            continue
        key = name.replace("_0_", "_0.")
        if name == "cls":
            tp, fp, fn, tn = st["tp"], st["fp"], st["fn"], st["tn"]
            out.update({"f1": (2 * tp, 2 * tp + fp + fn), "precision": (tp, tp + fp),
                        "recall": (tp, tp + fn), "accuracy": (tp + tn, tp + fp + fn + tn),
                        "f1_constant": (2 * (tp + fn), 2 * (tp + fn) + fp + tn)})
        elif "correct" in st:  # PCK
            out[key] = (st["correct"], st["joints"])
        elif "mean_value" in st:  # MeanMetric: weighted sum and total weight
            out[key] = (st["mean_value"], st["weight"])
        else:
            out[key] = (st["total"], st["count"])
    return out


def _take(value, idx: list, n: int):
    """The clips ``idx`` of one batch entry (tensors and lists of length ``n``)."""
    if isinstance(value, dict):
        return {k: _take(v, idx, n) for k, v in value.items()}
    if torch.is_tensor(value) and value.ndim and value.shape[0] == n:
        return value[torch.as_tensor(idx, device=value.device)]
    if isinstance(value, list) and len(value) == n:
        return [value[i] for i in idx]
    return value


class RecordingBreakdown:
    """``update(output, batch, model)`` like :class:`TaskMetrics`, but one set of metric
    states per recording; ``compute()`` -> ``{"recordings", "metrics"}`` (the layout of
    :data:`FILE`), gathered over DDP processes; ``reset()``."""

    def __init__(self, task: str):
        TaskMetrics(task)  # validates the task
        self.task = task
        self.by_recording: dict = {}

    @torch.no_grad()
    def update(self, output: torch.Tensor, batch: dict, model) -> None:
        ids = recording_ids(batch["meta"])
        groups: dict = {}
        for i, r in enumerate(ids):
            groups.setdefault(r, []).append(i)
        n = len(ids)
        for rec, idx in groups.items():
            metrics = self.by_recording.get(rec)
            if metrics is None:
                metrics = self.by_recording[rec] = TaskMetrics(self.task).to(output.device)
            metrics.update(_take(output, idx, n), _take(batch, idx, n), model)

    def terms(self) -> dict:
        """``{recording: {metric: (num, den)}}`` of this process."""
        return {rec: ratio_terms(m) for rec, m in self.by_recording.items()}

    def clips(self) -> dict:
        """``{recording: [(row, score, label, tte), ...]}`` of this process, for the tasks
        whose metrics keep clips (classification's ``ranking``); empty otherwise."""
        out = {}
        for rec, m in self.by_recording.items():
            ranking = m.scores["ranking"] if "ranking" in m.scores else None
            if ranking is None or not ranking.update_count:
                continue
            c = ranking.clips()
            out[rec] = [(int(r), float(s), int(y), int(t))
                        for r, s, y, t in zip(c["row"], c["score"], c["label"], c["tte"])]
        return out

    def compute(self) -> dict:
        terms, clips = self.terms(), self.clips()
        if torch.distributed.is_available() and torch.distributed.is_initialized() \
                and torch.distributed.get_world_size() > 1:
            parts = [None] * torch.distributed.get_world_size()
            torch.distributed.all_gather_object(parts, (terms, clips))
            terms, clips = {}, {}
            for part_terms, part_clips in parts:  # a recording may be spread over processes
                for rec, values in part_terms.items():
                    mine = terms.setdefault(rec, {})
                    for k, (a, b) in values.items():
                        a0, b0 = mine.get(k, (0.0, 0.0))
                        mine[k] = (a0 + a, b0 + b)
                for rec, values in part_clips.items():
                    clips.setdefault(rec, []).extend(values)
        recordings = sorted(terms)
        names = sorted({k for v in terms.values() for k in v})
        out = {"recordings": recordings,
               "metrics": {k: {"num": [terms[r].get(k, (0.0, 0.0))[0] for r in recordings],
                               "den": [terms[r].get(k, (0.0, 0.0))[1] for r in recordings]}
                           for k in names}}
        if clips:  # in stored (row) order, whichever process scored a clip
            out["clips"] = [[[s, y, t] for _, s, y, t in sorted(clips.get(r, []))]
                            for r in recordings]
        return out

    def reset(self) -> None:
        self.by_recording = {}


def write_breakdown(run_dir, task: str, test: dict | None, initial: dict | None) -> None:
    """Writes :data:`FILE` into ``run_dir`` (nothing when ``test`` is None). A resumed
    run keeps the trivial baseline's section of the file it was copied from."""
    import json
    from pathlib import Path

    from ..atomic import write_text

    if test is None:
        return
    path = Path(run_dir) / FILE
    if initial is None and path.is_file():
        initial = json.loads(path.read_text(encoding="utf-8")).get("initial")
    doc = {"unit": "recording (video_id/pedestrian_id)", "task": task, "test": test,
           "initial": initial,
           "empty": {k: EMPTY.get(k) for k in test["metrics"]}}
    if "clips" in test:
        doc["clip_fields"] = list(CLIP_FIELDS)
    write_text(path, json.dumps(doc))


def pooled_clips(section: dict, recordings=None) -> dict:
    """The clips of ``recordings`` (indices into ``section["recordings"]``, repeats
    allowed, as a bootstrap draws them; default: all) of a ``test`` or ``initial``
    section of :data:`FILE`, pooled: ``{"score": float64, "label": int64, "tte": int64}``
    NumPy arrays. ValueError for a section without clips (a file written before they were
    kept, or a task without AUROC/AP)."""
    import numpy as np

    if "clips" not in section:
        raise ValueError(f"{FILE}: this section keeps no clips (a file bsp-train wrote "
                         "before AUROC/AP kept them, or not a classification run); train "
                         "the run again to write them")
    per = section["clips"]
    idx = range(len(per)) if recordings is None else recordings
    flat = [c for i in idx for c in per[int(i)]]
    a = np.asarray(flat, np.float64).reshape(-1, len(CLIP_FIELDS))
    return {"score": a[:, 0], "label": a[:, 1].astype(np.int64),
            "tte": a[:, 2].astype(np.int64)}
