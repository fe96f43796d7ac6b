"""Imported 2D detections -> a clip file in the bsp-convert HDF5 schema (2D tasks).

The rows are mapped onto CARLA-26 (:mod:`bsp_fast.skeleton`), a joint counts as
``visible`` when its confidence is at least ``threshold`` (and above 0), and the clips are
planned by the C++ core's planner (``plan_clips``, the one bsp-convert uses), so clip
length, offsets, the benchmark's time-to-event windows, labels, the in-image filter, the
seeded split by video and balancing follow the same rules. Recordings are the (video,
track) pairs; the split's units are the videos. Rows are ordered by (video, track, frame)
first, so the same detections in any order give the same file.
"""
from __future__ import annotations

import json

import numpy as np

from .._version import __version__
from .._native import core as _core
from ..atomic import atomic_output
from ..conversion.api import clip_settings
from ..skeleton import CARLA, skeleton_map
from .readers import BadInput, Detections, option, read_coco, read_labels, read_openpose

__all__ = ["clip_settings", "write_clip_file", "map_joints", "import_coco", "import_openpose"]  # clip_settings: the converter's own

_STR_META = ("video_id", "pedestrian_id", "age", "gender", "model", "map")
SPLITS = ("train", "val", "test")


def _codes(names: list) -> tuple:
    uniq = sorted(set(names))
    index = {n: i for i, n in enumerate(uniq)}
    return np.array([index[n] for n in names], np.int64), uniq


def _longest_runs(video, track, frame) -> dict:
    """(video, track) -> longest run of consecutive frames (rows sorted by key, frame)."""
    runs: dict = {}
    run = 0
    for i in range(len(frame)):
        same = i > 0 and video[i] == video[i - 1] and track[i] == track[i - 1]
        run = run + 1 if same and frame[i] == frame[i - 1] + 1 else 1
        key = (video[i], track[i])
        runs[key] = max(runs.get(key, 0), run)
    return runs


def _crossing(det: Detections, labels, order) -> np.ndarray:
    if labels is None:
        return np.zeros(len(order), np.uint8)
    out = np.zeros(len(order), np.uint8)
    missing = []
    for k, i in enumerate(order):
        value = labels.get((det.video[i], det.track[i], int(det.frame[i])))
        if value is None:
            missing.append(i)
        else:
            out[k] = value
    if missing:
        i = missing[0]
        raise BadInput(f"labels: no row for video {det.video[i]!r} track {det.track[i]!r} frame "
                       f"{int(det.frame[i])} ({det.where[i]}) and {len(missing) - 1} more "
                       "detections; every detected frame needs a crossing label")
    return out


def map_joints(joints: str, points, scores, threshold: float, derive: bool) -> tuple:
    """Detected joints of the set ``joints`` -> CARLA-26: ``(map, uv f32, visible,
    confidence f32, at_origin)``; a joint is visible when its score is at least
    ``threshold`` and above 0 and it is not at (0, 0) (``at_origin``: the loaders read
    (0, 0) as missing, so those are counted for the report and left out)."""
    m = skeleton_map(joints, CARLA, derive)
    seen = (scores >= threshold) & (scores > 0)
    uv, visible = m.apply(points, seen, fill=0.0)
    conf, _ = m.apply(scores[..., None], seen, fill=0.0)
    at_origin = visible & (uv[..., 0] == 0) & (uv[..., 1] == 0)
    visible &= ~at_origin
    uv = np.where(visible[..., None], uv, 0.0).astype(np.float32)
    conf = np.where(visible, conf[..., 0], 0.0).astype(np.float32)
    return m, uv, visible, conf, at_origin


def _fixed_plan(plan_for, st: dict, eval_stride: int, row_split: list) -> dict:
    """The planner's clips with each recording in its video's given split (``row_split``
    per row: a round trip keeps the split it came with): the train recordings'
    clips as planned with the train stride, the others' with the eval stride, from
    whichever split the planner put them in; the train split balanced as the planner
    balances (the first clips of each class, as many as the rarer class has)."""
    plans = {"train": plan_for(st["clip_offset"], st["clip_offset"], False)}
    plans["val"] = plans["test"] = (plans["train"] if eval_stride == st["clip_offset"]
                                    else plan_for(eval_stride, eval_stride, False))
    rec_rows = plans["train"]["recording_rows"]
    out = {k: plans["train"][k] for k in ("recording_rows", "skipped",
                                          "clips_rejected_out_of_image")}
    keys = ("recording", "first", "segment", "index", "label", "time_to_event")
    for s in SPLITS:
        mine = lambda r: row_split[rec_rows[r][0]] == s  # noqa: E731
        parts = [plans[s][t] for t in SPLITS]
        take = [np.array([mine(r) for r in p["recording"]], bool) for p in parts]
        out[s] = {k: np.concatenate([np.asarray(p[k])[m] for p, m in zip(parts, take)])
                  for k in keys}
        out[s]["recordings"] = sorted(r for p in parts for r in p["recordings"] if mine(r))
    if st["balance"]:
        lab = out["train"]["label"]
        keep = min(int((lab == 0).sum()), int((lab == 1).sum()))
        rank = np.array([(lab[:i] == lab[i]).sum() for i in range(len(lab))], np.int64)
        out["train"] = dict({k: v[rank < keep] for k, v in out["train"].items()
                             if k != "recordings"}, recordings=out["train"]["recordings"])
    return out


def _tracks(det: Detections, L: int, skip_short: bool) -> tuple:
    """``(vcode, videos, tcode, tracks, order, runs, short, skipped)``: the detections'
    video and track codes, their rows ordered by video, track and frame without the tracks
    whose longest run of consecutive frames is shorter than a clip (an error unless
    ``skip_short``), each track's longest run, the short ones and why they were left out."""
    vcode, videos = _codes(det.video)
    tcode, tracks = _codes(det.track)
    order = np.lexsort((det.frame, tcode, vcode))
    runs = _longest_runs(vcode[order], tcode[order], det.frame[order])
    short = {k: n for k, n in runs.items() if n < L}
    skipped = [f"video {videos[v]!r} track {tracks[t]!r}: longest run of consecutive frames "
               f"{n} < clip length {L}" for (v, t), n in short.items()]
    if short and not skip_short:
        raise BadInput(f"{det.source}: {len(short)} track(s) shorter than a clip: "
                       + "; ".join(skipped[:5]) + ("; ..." if len(skipped) > 5 else "")
                       + "; pass " + option("skip_short=True", "--skip-short-tracks")
                       + " to leave them out; nothing written")
    if short:
        order = np.array([i for i in order if (vcode[i], tcode[i]) not in short], np.int64)
        if len(order) == 0:
            raise BadInput(f"{det.source}: every track is shorter than a clip of {L} frames; "
                           "nothing written")
    return vcode, videos, tcode, tracks, order, runs, short, skipped


def _plan_rows(rows: dict, st: dict, clip_options: dict, fixed) -> dict:
    """The core's clip plan of ``rows``: the seeded split, or ``fixed`` (each row's split
    kept, :func:`_fixed_plan`)."""
    plan_for = lambda stride, eval_stride, balance: _core.plan_clips(  # noqa: E731
        rows["video"].astype(np.int32), np.zeros(len(rows["frame"]), np.int64),
        rows["track"], rows["frame"], rows["crossing"], rows["uv"], rows["width"],
        rows["height"], clip_length=st["clip_length"], clip_stride=stride,
        eval_clip_stride=eval_stride,
        min_video_length=clip_options.get("min_video_length") or 0,
        label_fraction=st["label_fraction"], benchmark=st["benchmark"],
        val_frac=float(st["val_frac"]), test_frac=float(st["test_frac"]), seed=st["seed"],
        balance=balance)
    eval_stride = clip_options.get("eval_clip_offset") or st["clip_offset"]
    if fixed is None:
        return plan_for(st["clip_offset"], eval_stride, st["balance"])
    return _fixed_plan(plan_for, st, eval_stride, fixed)


def write_clip_file(det: Detections, out, *, labels=None, threshold: float = 0.3,
                    derive: bool = True, skip_short: bool = False, force: bool = False,
                    splits: dict | None = None, labels_source: str | None = None,
                    **clip_options) -> dict:
    """Writes the clips of ``det`` to ``out`` (HDF5, docs/interop.md) and returns a report.

    ``labels``: ``{(video, track, frame): crossing}`` (:func:`read_labels`); without it
    every label is 0 (autoencoder data). ``threshold``: minimum confidence of a visible
    joint. ``derive``: the skeleton map's standard derivations (hips, neck from COCO).
    A track whose longest run of consecutive frames is shorter than a clip is an error
    unless ``skip_short`` (then it is left out and listed). ``splits``: ``{video:
    split}`` to keep (:func:`_fixed_plan`) instead of the seeded split; ``labels_source``
    names where ``labels`` came from (default ``csv``). ``clip_options``: those of
    :func:`clip_settings`. Nothing is left behind on error."""
    if not isinstance(threshold, (int, float)) or not 0 <= threshold <= 1e6:
        raise ValueError(f"threshold must be a number >= 0, got {threshold!r}")
    st = clip_settings(**clip_options)
    L = st["clip_length"]
    if len(det.frame) == 0:
        raise BadInput(f"{det.source}: no detection to import")
    vcode, videos, tcode, tracks, order, runs, short, skipped = _tracks(det, L, skip_short)
    crossing = _crossing(det, labels, order)
    m, uv, visible, conf, at_origin = map_joints(det.joints, det.points[order],
                                                 det.scores[order], threshold, derive)
    rows = dict(video=vcode[order], track=tcode[order], frame=det.frame[order],
                width=det.width[order], height=det.height[order], crossing=crossing,
                uv=uv, visible=visible, confidence=conf)
    plan = _plan_rows(rows, st, clip_options, None if splits is None else
                      [splits[videos[v]] for v in rows["video"]])
    clips = {s: int(len(plan[s]["first"])) for s in ("train", "val", "test")}
    if sum(clips.values()) == 0:
        reasons = "; ".join(f"{r}" for _, r in plan["skipped"][:3])
        raise BadInput(f"{det.source}: no clip of {L} frames could be cut ({reasons}); "
                       "nothing written")
    names = dict(videos=videos, tracks=tracks)
    report = dict(rows=int(len(order)), tracks=len(runs) - len(short), clips=clips,
                  class_counts={}, skipped=skipped + [
                      f"video {videos[rows['video'][plan['recording_rows'][r][0]]]!r} track "
                      f"{tracks[rows['track'][plan['recording_rows'][r][0]]]!r}: {why}"
                      for r, why in plan["skipped"]],
                  clips_rejected_out_of_image=int(plan["clips_rejected_out_of_image"]),
                  joints_at_origin=int(at_origin.sum()),
                  joints=[n for n, p in zip(CARLA.joints, m.present) if p],
                  frames=dict(det.notes),
                  settings=dict(st, source=det.source, source_joints=det.joints,
                                threshold=float(threshold), derive=bool(derive),
                                labels=labels_source or ("csv" if labels is not None
                                                         else "none"),
                                split_rule="source" if splits else "seeded by video"))
    with atomic_output(out, force=force) as tmp:
        _write(tmp, plan, rows, names, st, report, m)
    report["output"] = str(out)
    report["warnings"] = [f"the {s} split is empty" for s, n in clips.items() if n == 0]
    return report


def _split_arrays(plan: dict, split: str, rows: dict, L: int) -> dict:
    p = plan[split]
    rec_rows = plan["recording_rows"]
    idx = np.array([[rec_rows[r][f + k] for k in range(L)]
                    for r, f in zip(p["recording"], p["first"])], np.int64).reshape(-1, L)
    uv, vis = rows["uv"][idx], rows["visible"][idx]
    lo = np.where(vis[..., None], uv, np.inf).min(-2)
    hi = np.where(vis[..., None], uv, -np.inf).max(-2)
    none = ~vis.any(-1)
    lo[none], hi[none] = 0, 0
    return dict(idx=idx, uv=uv, visible=vis, confidence=rows["confidence"][idx],
                bboxes=np.stack([lo, hi], -2).astype(np.float32),
                is_crossing=rows["crossing"][idx], frames=rows["frame"][idx],
                labels=np.asarray(p["label"], np.uint8), clip_id=np.asarray(p["index"], np.int32),
                segment=np.asarray(p["segment"], np.int32),
                tte=np.asarray(p["time_to_event"], np.int32))


def _write(path, plan: dict, rows: dict, names: dict, st: dict, report: dict, m) -> None:
    import h5py

    L = st["clip_length"]
    text = h5py.string_dtype()
    with h5py.File(path, "w") as f:
        for split in ("train", "val", "test"):
            a = _split_arrays(plan, split, rows, L)
            first = a["idx"][:, 0] if len(a["idx"]) else np.zeros(0, np.int64)
            g = f.create_group(split)
            g["projection_2d"] = a["uv"].astype(np.float32)
            g["visible"] = a["visible"].astype(np.uint8)
            g["confidence"] = a["confidence"]
            g["labels"] = a["labels"]
            g["targets/bboxes"] = a["bboxes"]
            g["targets/is_crossing"] = a["is_crossing"].astype(np.uint8)
            g["targets/frame_idx"] = a["frames"].astype(np.int64)
            meta = dict(video_id=[names["videos"][v] for v in rows["video"][first]],
                        pedestrian_id=[names["tracks"][t] for t in rows["track"][first]])
            for k in _STR_META:
                g.create_dataset(f"meta/{k}", data=meta.get(k, [""] * len(first)), dtype=text)
            g["meta/clip_id"] = a["clip_id"]
            g["meta/segment"] = a["segment"]
            g["meta/start_frame"] = a["frames"][:, 0] if len(first) else np.zeros(0, np.int64)
            g["meta/end_frame"] = (a["frames"][:, -1] + 1 if len(first)
                                   else np.zeros(0, np.int64))
            g["meta/clip_width"] = rows["width"][first].astype(np.int64)
            g["meta/clip_height"] = rows["height"][first].astype(np.int64)
            g["meta/tte"] = a["tte"]  # the planner's time to event; -1 without --benchmark
            counts = np.bincount(a["labels"], minlength=2).astype(np.int64)
            g.attrs["class_counts"] = counts
            g.attrs["recordings"] = len(plan[split]["recordings"])
            f.attrs[f"class_counts_{split}"] = counts
            report["class_counts"][split] = counts.tolist()
        rule = ("video" if st["benchmark"] else "last" if st["label_fraction"] == 0
                else "any:%f" % st["label_fraction"])
        attrs = dict(schema_version=1, created_by=f"bsp_fast {__version__}", clip_length=L,
                     clip_stride=st["clip_offset"], eval_clip_stride=st["eval_clip_offset"],
                     min_video_length=st["min_video_length"], label_rule=rule,
                     benchmark=int(st["benchmark"]), val_frac=float(st["val_frac"]),
                     test_frac=float(st["test_frac"]), seed=st["seed"],
                     balance=int(st["balance"]), media=0, compression="none",
                     class_labels=["not-crossing", "crossing"], joint_names=list(CARLA.joints),
                     parents=np.asarray(CARLA.parents, np.int64),
                     source_path=report["settings"]["source"],
                     source_format=m.source.name, joints_mapped=m.present.astype(np.uint8),
                     visibility_threshold=report["settings"]["threshold"],
                     labels_source=report["settings"]["labels"],
                     settings_json=json.dumps(report["settings"], sort_keys=True))
        for k, v in attrs.items():
            f.attrs[k] = v


def import_coco(path, out, *, images=None, labels=None, image_size=None, tracks="require",
                joints="coco17", **options) -> dict:
    """:func:`read_coco` then :func:`write_clip_file` (``labels``: a labels CSV path;
    without it, the records' own ``crossing`` where every record has one, as our COCO
    export writes them; the images' ``split``, where every image names one, is kept)."""
    det = read_coco(path, images=images, image_size=image_size, tracks=tracks, joints=joints)
    return write_clip_file(det, out, labels=det.labels if labels is None else read_labels(labels),
                           splits=det.splits, **options,
                           labels_source="csv" if labels is not None else
                           "records" if det.labels is not None else None)


def import_openpose(folder, out, *, image_size, labels=None, tracks="require",
                    **options) -> dict:
    """:func:`read_openpose` then :func:`write_clip_file`."""
    det = read_openpose(folder, image_size, tracks=tracks)
    return write_clip_file(det, out, labels=None if labels is None else read_labels(labels),
                           **options)
