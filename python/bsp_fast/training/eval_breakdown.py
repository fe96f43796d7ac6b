"""Where a run's test error lies: per joint, per pedestrian size or distance, per profile,
per realised missing-joint count (``bsp-eval RUN --breakdown``, docs/training.md).

:class:`BreakdownCollector` observes the scorer (:mod:`.scorer`): as the test split is scored it keeps, for
every scored frame (clip, for classification), what the task's metric is made of, taken
from the same arrays the task scores (``Lifting.metres``, ``pose_pairs`` of the 2D tasks,
the classifier's logits). :func:`build_breakdown` then reads what the batches do not hold
from the clip file (the 2D joint boxes ``targets/bboxes``, the hips in the world and the
camera transform) and groups. Every table says what its count column counts (clips,
frames or joints); the counts of each table add up to ``totals`` of the split. What is
kept, the size bins and the missing-joint table are the task object's choice
(``Task.breakdown_scores``, ``breakdown_bins``, ``breakdown_missing_joints``).

Bins are fixed (the same rows for every run, so tables compare across runs):

* pedestrian pixel height, 2D tasks: ``max v - min v`` of the frame's ground-truth 2D
  joints (``targets/bboxes``), edges :data:`HEIGHT_EDGES_PX`; classification bins a clip by
  the mean over its frames;
* camera distance, lifting: the hips' depth along the camera's forward axis, from
  ``targets/world_pose_loc`` and ``meta/camera_transform``, edges :data:`DISTANCE_EDGES_M`;
* realised missing joints, 2D-input tasks: joints of the frame missing from the input
  (``~visible``, after ``--mjp``), bins :data:`MISSING_BINS`; classification bins a clip
  by its missing joints per frame, averaged over the clip and rounded;
* profile: ``age/gender`` of the clip's meta;
* time to event, classification on benchmark windows: frames from the clip's last frame
  to its event (``meta/tte``, docs/hdf5-schema.md), bins :data:`TTE_BINS` (the benchmark's
  1 to 2 s before the event, cut in three). A file without event (not benchmark windows,
  or written before ``meta/tte`` was stored) gets a note saying why instead.

Classification scores each clip by the model's P(crossing) in float64
(:func:`bsp_fast.metrics.ranking.crossing_probability`), as the run's metrics do, so the
summary's AUROC and AP are the run's ``auroc`` and ``ap``.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from .. import metrics as M
from ..metrics import ranking
from ..reporting.breakdown import edges_labels, headers, ranges_labels
from ..skeleton import HIPS, JOINT_NAMES, NUM_JOINTS
from .runs import BREAKDOWN_FILE
from .tasks import get_task

__all__ = ["BreakdownCollector", "build_breakdown", "bin_index", "FILE", "HEIGHT_EDGES_PX",
           "DISTANCE_EDGES_M", "MISSING_BINS", "PCK_ALPHA", "TTE_BINS", "CLS_COLUMNS"]

FILE = BREAKDOWN_FILE
HEIGHT_EDGES_PX = (0.0, 50.0, 100.0, 200.0, 400.0, math.inf)
DISTANCE_EDGES_M = (0.0, 10.0, 20.0, 30.0, 50.0, math.inf)
#: inclusive ranges of missing joints per frame
MISSING_BINS = ((0, 0), (1, 2), (3, 5), (6, 10), (11, 18), (19, 25), (26, 26))
PCK_ALPHA = 0.05
#: inclusive ranges of frames to the event; the converter's windows reach 61 frames (it keeps
#: frames from event - L - 60, so the earliest window ends at event - 61: docs/hdf5-schema.md)
TTE_BINS = ((30, 39), (40, 49), (50, 61))
#: classification's summary and time-to-event columns
CLS_COLUMNS = headers("f1", "precision", "recall", "accuracy", "auroc", "ap", "crossing")
#: the values of ``Task.breakdown_scores`` this module collects and groups
SCORES = ("logits", "joint_error_mm", "pose_pairs")


class BreakdownCollector:
    """Keeps each test batch's scored arrays (as NumPy, on the CPU) in ``parts``; the
    model's parameter count and forward FLOPs per clip (first batch) in ``cost``; the
    test split's file in ``h5_path``."""

    def __init__(self):
        self.parts: list = []
        self.cost: dict = {}
        self.h5_path = None

    @torch.no_grad()
    def update(self, spec, net, output, batch) -> None:
        """One scored test batch (:func:`bsp_fast.training.scorer.score`'s observer)."""
        out = output.detach().float()
        if not self.cost:
            from ..models.cost import flops_per_clip, parameter_count

            self.cost = {"parameters": parameter_count(net),
                         "flops_per_clip": flops_per_clip(net, batch)}
        meta = batch["meta"]
        part = {"row": meta["row"].cpu().numpy() if torch.is_tensor(meta["row"])
                else np.asarray(meta["row"]),
                "profile": [f"{a}/{g}" for a, g in zip(meta["age"], meta["gender"])]}
        L = batch["inputs"].shape[1]
        sl = spec.scored_frames(net, L)
        part["frames"] = (sl.start or 0, L if sl.stop is None else sl.stop)
        if spec.breakdown_scores not in SCORES:
            raise ValueError(f"task {spec.name!r} has no breakdown (breakdown_scores "
                             f"{spec.breakdown_scores!r}, not one of {list(SCORES)})")
        if spec.breakdown_scores == "logits":
            part["score"] = ranking.crossing_probability(out)
            part["pred"] = M.predicted_labels(out).cpu().numpy()
            part["label"] = batch["label"].cpu().numpy()
            missing = (~batch["visible"].bool()).sum(-1).double().mean(-1)
            part["missing"] = torch.round(missing).long().cpu().numpy()
            self.parts.append(part)
            return
        if spec.breakdown_scores == "joint_error_mm":
            pred_m, gt_m = spec.metres(out, batch, net)
            d = (pred_m * 1000.0).double() - (gt_m * 1000.0).double()  # as MPJPE scores it
            part["err"] = torch.sqrt((d * d).sum(-1)).cpu().numpy()  # (B, Ls, 26) mm
        else:
            pred, gt, present = spec.pose_pairs(out, batch, net)
            part.update(pred=pred.cpu().numpy(), gt=gt.cpu().numpy(),
                        present=present.bool().cpu().numpy())
        if spec.breakdown_missing_joints:
            vis = batch["visible"][:, sl].bool()
            part["missing"] = (~vis).sum(-1).cpu().numpy()  # (B, Ls)
        self.parts.append(part)


# ---------------------------------------------------------------------- clip-file values
def _per_frame_values(h5_path, rows: np.ndarray, need_distance: bool) -> dict:
    """``{"height": (N, L) px, "distance": (N, L) m, "tte": (N,) frames, "tte_problem":
    why there is no time to event (None: every clip has one)}`` of the stored test
    ``rows``."""
    from ..conversion.vds import open_clip_file
    from ..data.datasets import NO_EVENT, tte_problem
    from ..geometry import rotation_matrix

    uniq, inverse = np.unique(rows, return_inverse=True)
    out = {}
    with open_clip_file(h5_path) as f:
        g = f["test"]
        box = g["targets/bboxes"][uniq].astype(np.float64)  # (n, L, 2, 2)
        out["height"] = (box[:, :, 1, 1] - box[:, :, 0, 1])[inverse]
        has = "meta/tte" in g
        out["tte"] = (g["meta/tte"][uniq].astype(np.int64)[inverse] if has
                      else np.full(len(rows), NO_EVENT, np.int64))
        out["tte_problem"] = tte_problem(h5_path, has, out["tte"], dict(f.attrs))
        if need_distance:
            hips = g["targets/world_pose_loc"][uniq][:, :, HIPS].astype(np.float64)
            cam = g["meta/camera_transform"][uniq].astype(np.float64)
            forward = rotation_matrix(cam[:, 3:])[:, :, 0]  # the camera's x axis in the world
            rel = hips - cam[:, None, :3]
            out["distance"] = np.einsum("nlk,nk->nl", rel, forward)[inverse]
    return out


def bin_index(values: np.ndarray, edges) -> np.ndarray:
    """The bin of each value: half-open ``[lo, hi)`` bins between ``edges``; a value below
    the first edge goes to the first bin (a box of negative height cannot occur)."""
    return np.searchsorted(np.asarray(edges[1:-1]), values, side="right")


def _missing_index(values: np.ndarray) -> np.ndarray:
    idx = np.zeros(len(values), np.int64)
    for i, (lo, hi) in enumerate(MISSING_BINS):
        idx[(values >= lo) & (values <= hi)] = i
    return idx


# ---------------------------------------------------------------------- groups
def _frames(parts: list, key: str) -> np.ndarray:
    """Per-frame array of ``key`` over every clip (clips in test order, frames in order)."""
    return np.concatenate([p[key].reshape((-1,) + p[key].shape[2:]) for p in parts])


def _clip_to_frames(parts: list, values: list) -> np.ndarray:
    """A per-clip list repeated for each of the clip's scored frames."""
    counts = np.concatenate([np.full(len(p["row"]), p["frames"][1] - p["frames"][0])
                             for p in parts])
    return np.repeat(np.asarray(values, dtype=object), counts)


def _table(title: str, by: str, unit: str, columns: dict, rows: list, total: int) -> dict:
    return {"title": title, "by": by, "count": unit, "columns": columns, "rows": rows,
            "total": int(total)}


def _lifting_stats(err: np.ndarray) -> dict:
    n = int(err.shape[0])
    return {"count": n, "joints": n * NUM_JOINTS,
            "mpjpe_mm": float(err.sum() / err.size) if n else math.nan}


def _pck_stats(pred, gt, present, with_auc: bool = True) -> dict:
    n = int(pred.shape[0])
    if n == 0:
        return {"count": 0, "joints": 0, "pck_0.05": math.nan, "pck_auc": math.nan}
    c = M.pck_counts(pred, gt, alpha=PCK_ALPHA, norm="bbox", visible=present)
    out = {"count": n, "joints": c.total, "pck_0.05": c.value}
    if with_auc:
        out["pck_auc"] = M.pck_auc(pred, gt, norm="bbox", visible=present) if c.total \
            else math.nan
    return out


def _cls_stats(score, pred, label) -> dict:
    n = int(len(label))
    out = {"count": n, "crossing": int(label.sum())}
    if n == 0:
        return out | {k: math.nan for k in CLS_COLUMNS if k != "crossing"}
    out.update(f1=float(M.f1_score(pred, label)), precision=float(M.precision(pred, label)),
               recall=float(M.recall(pred, label)), accuracy=float(M.accuracy(pred, label)),
               auroc=ranking.auroc(score, label), ap=ranking.average_precision(score, label))
    return out


def _tte_table(tte: np.ndarray, stats, bins: dict) -> dict:
    """Clips per :data:`TTE_BINS` bin (and ``other``, only if some clip lies outside)."""
    labels = ranges_labels(TTE_BINS)
    index = np.full(len(tte), len(TTE_BINS), np.int64)
    for i, (lo, hi) in enumerate(TTE_BINS):
        index[(tte >= lo) & (tte <= hi)] = i
    if (index == len(TTE_BINS)).any():  # e.g. an importer's wider --tte: counts add up
        labels.append("other")
    bins["time_to_event"] = {"rows": labels, "per": "clip (frames from its last frame to "
                             "the event, meta/tte)"}
    cols = {k: v for k, v in CLS_COLUMNS.items() if k != "crossing"}
    table = _table("per time to event", "frames to the event", "clips",
                   headers("crossing") | cols,
                   _grouped(labels, index, stats), len(tte))
    table["aggregate"] = ["f1", "auroc", "ap"]  # bsp-reproduce --breakdown: mean ± std
    return table


def _grouped(labels: list, index: np.ndarray, stats) -> list:
    """One row per label: ``stats(mask)`` for the members of each group."""
    return [{"bin": str(lab), **stats(index == i)} for i, lab in enumerate(labels)]


# ---------------------------------------------------------------------- the tables
def build_breakdown(collector: BreakdownCollector, task: str, metrics: dict | None = None,
                    h5_path=None) -> dict:
    """The breakdown document (what ``--save`` writes to :data:`FILE`): ``totals``
    (clips, frames, joints of the scored split), ``summary`` (the overall values, computed
    from the kept arrays), ``tables`` (each with ``title``, ``by``, ``count`` (its unit),
    ``columns`` ``{key: header}``, ``rows`` and ``total``), ``bins`` and ``notes``."""
    parts = collector.parts
    if not parts:
        raise ValueError("breakdown: no test batch was scored")
    h5_path = h5_path or collector.h5_path
    rows = np.concatenate([p["row"] for p in parts])
    profiles = [s for p in parts for s in p["profile"]]
    spec = get_task(task)
    per_frame = _per_frame_values(h5_path, rows,
                                  need_distance=spec.breakdown_bins == "camera_distance")
    notes, bins = [], {}
    if spec.breakdown_per_clip:
        doc = _classification(parts, rows, profiles, per_frame, bins)
        if per_frame["tte_problem"] is not None:
            notes.append(f"no time-to-event table: {per_frame['tte_problem']}")
    else:
        doc = _frame_tables(spec, parts, profiles, per_frame, bins, notes)
    doc.update(task=task, split="test", cost=dict(collector.cost), bins=bins, notes=notes,
               metrics=dict(metrics or {}))
    return doc


def _classification(parts, rows, profiles, per_frame, bins) -> dict:
    score, pred, label, missing = (np.concatenate([p[k] for p in parts])
                                   for k in ("score", "pred", "label", "missing"))
    height = per_frame["height"].mean(1)
    N = len(label)

    def stats(mask):
        return _cls_stats(score[mask], pred[mask], label[mask])

    cols = headers("crossing", "f1", "auroc", "ap")
    h_labels = edges_labels(HEIGHT_EDGES_PX, "px")
    bins["height_px"] = {"rows": h_labels, "per": "clip (mean over its frames)"}
    bins["missing_joints"] = {"rows": ranges_labels(MISSING_BINS),
                              "per": "clip (mean per frame, rounded)"}
    prof, prof_idx = np.unique(np.asarray(profiles, dtype=str), return_inverse=True)
    tables = [
        _table("per pedestrian pixel height", "height", "clips", cols,
               _grouped(h_labels, bin_index(height, HEIGHT_EDGES_PX), stats), N),
        _table("per age/gender profile", "profile", "clips", cols,
               _grouped(prof, prof_idx, stats), N),
        _table("per realised missing-joint count", "missing joints per frame", "clips", cols,
               _grouped(ranges_labels(MISSING_BINS), _missing_index(missing), stats), N)]
    if per_frame["tte_problem"] is None:
        tables.append(_tte_table(per_frame["tte"], stats, bins))
    summary = _cls_stats(score, pred, label)
    return {"totals": {"clips": N, "frames": N * per_frame["height"].shape[1]},
            "summary": summary, "tables": tables, "summary_columns": dict(CLS_COLUMNS),
            "summary_count": "clips"}


def _frame_tables(spec, parts, profiles, per_frame, bins, notes) -> dict:
    N = sum(len(p["row"]) for p in parts)
    height, distance = _scored_frames(parts, per_frame)
    profile = _clip_to_frames(parts, profiles)
    F = len(height)
    stats, cols, joint_rows, joint_cols, total_joints, summary = _joint_scores(
        parts, spec.breakdown_scores, F)
    tables = [_table("per joint", "joint", "joints", joint_cols, joint_rows, total_joints),
              _size_table(spec, height, distance, bins, cols, stats)]
    prof, prof_idx = np.unique(profile.astype(str), return_inverse=True)
    tables.append(_table("per age/gender profile", "profile", "frames", cols,
                         _grouped(prof, prof_idx, stats), F))
    if spec.breakdown_missing_joints:
        missing = _frames(parts, "missing")
        bins["missing_joints"] = {"rows": ranges_labels(MISSING_BINS),
                                  "per": "frame (joints missing from the input)"}
        tables.append(_table("per realised missing-joint count", "missing joints", "frames",
                             cols, _grouped(ranges_labels(MISSING_BINS), _missing_index(missing),
                                            stats), F))
    else:
        notes.append(f"no missing-joint table: {spec.name}'s inputs are crops, not 2D "
                     "joints with missing ones")
    summary_cols = {k: v for k, v in cols.items() if k != "joints"} | headers("joints")
    return {"totals": {"clips": N, "frames": F, "joints": int(total_joints)},
            "summary": summary, "tables": tables, "summary_columns": summary_cols,
            "summary_count": "frames"}


def _scored_frames(parts, per_frame) -> tuple:
    """Each frame's pixel height (one array) and camera distance (a list of the clips'
    arrays; empty where the clip file has none), cut to each clip's scored frames."""
    pos, height, distance = 0, [], []
    for p in parts:
        a, b = p["frames"]
        n = len(p["row"])
        height.append(per_frame["height"][pos:pos + n, a:b].reshape(-1))
        if "distance" in per_frame:
            distance.append(per_frame["distance"][pos:pos + n, a:b].reshape(-1))
        pos += n
    return np.concatenate(height), distance


def _joint_scores(parts, scores: str, F: int) -> tuple:
    """What the frame tables need of the scores, joint errors (``joint_error_mm``) or PCK:
    the statistics of a frame mask, their columns, the per-joint rows and their columns,
    the joint count and the summary."""
    if scores == "joint_error_mm":
        err = _frames(parts, "err")  # (F, 26) mm

        def stats(mask):
            return _lifting_stats(err[mask])

        joint_rows = [{"bin": name, "count": F, "mpjpe_mm": float(err[:, j].mean())
                       if F else math.nan} for j, name in enumerate(JOINT_NAMES)]
        return (stats, headers("joints", "mpjpe_mm"), joint_rows, headers("mpjpe_mm"),
                F * NUM_JOINTS, _lifting_stats(err))
    pred, gt, present = _frames(parts, "pred"), _frames(parts, "gt"), _frames(parts, "present")

    def stats(mask):
        return _pck_stats(pred[mask], gt[mask], present[mask])

    joint_rows = []
    for j, name in enumerate(JOINT_NAMES):
        sel = np.zeros(present.shape, bool)
        sel[:, j] = True
        c = M.pck_counts(pred, gt, alpha=PCK_ALPHA, norm="bbox", visible=present, select=sel)
        joint_rows.append({"bin": name, "count": c.total, "pck_0.05": c.value})
    summary = _pck_stats(pred, gt, present)
    return (stats, headers("joints", "pck_0.05", "pck_auc"), joint_rows, headers("pck_0.05"),
            summary["joints"], summary)


def _size_table(spec, height, distance: list, bins: dict, cols: dict, stats) -> dict:
    """The table per camera distance or per pixel height (the spec's ``breakdown_bins``);
    its bins recorded in ``bins``."""
    # (bins key, edges, unit, what a frame's value is, title, first column, values)
    by_distance = spec.breakdown_bins == "camera_distance"
    key, edges, unit, per, title, column, values = (
        ("distance_m", DISTANCE_EDGES_M, "m", "hips' depth along the camera's forward axis",
         "per camera distance", "distance", np.concatenate(distance)) if by_distance else
        ("height_px", HEIGHT_EDGES_PX, "px", "vertical extent of its ground-truth 2D joints",
         "per pedestrian pixel height", "height", height))
    labels = edges_labels(edges, unit)
    bins[key] = {"rows": labels, "per": f"frame ({per})"}
    return _table(title, column, "frames", cols,
                  _grouped(labels, bin_index(values, edges), stats), len(height))
