"""The PedestrianActionBenchmark's windows of annotated tracks and the clip file that holds
them (``bsp-interop import jaad|pie``; :mod:`.benchmark_annotations` reads the poses).

As ``action_predict.py`` ``get_data_sequence`` cuts them: a track ends at its event (its
``n = end + 1`` positions); windows of ``obs`` *positions* start at ``n - obs - tte_max``
... ``n - obs - tte_min`` every ``stride``, so a window spans a gap in the frame numbers
where the annotation has one, and its time to event (``tte``) is counted in positions,
``n - (start + obs)``, always ``tte_min`` .. ``tte_max``. The frame numbers between the
window's last frame and the event are kept beside it (``frames_to_event``: the same
where the track has no gap). ``cut_gaps`` leaves out the windows that span a gap.
``drop_first``: the benchmark's models see the last ``obs - 1`` frames of a window (with
``normalize_boxes: True`` it drops the first frame of every input but the box, which it
makes relative to that first frame); the clip file then holds those frames and the
dropped frame's annotated box as ``targets/box_reference``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .. import __version__
from .._native import core as _core
from ..skeleton import CARLA

__all__ = ["Window", "track_windows", "seeded_split", "write_windows"]

SPLITS = ("train", "val", "test")


@dataclass(frozen=True, eq=False)
class Window:
    """One window of ``track``: positions ``first`` .. ``first + obs - 1`` of its frames;
    ``tte`` (the benchmark's, in positions) and ``frames_to_event`` (in frame numbers)
    from its last frame to the event; ``index`` its number within the track."""

    track: object
    first: int
    tte: int
    frames_to_event: int
    index: int


def track_windows(track, obs: int, tte: tuple, stride: int, cut_gaps: bool = False):
    """The windows of ``track`` (None: fewer than ``obs + tte_max`` positions up to the
    event, which the benchmark leaves out: its ``min_track_size``)."""
    n = track.end + 1
    if n < obs + tte[1]:
        return None
    out = []
    for k, i in enumerate(range(n - obs - tte[1], n - obs - tte[0] + 1, stride)):
        last = i + obs - 1
        if cut_gaps and track.frames[last] - track.frames[i] != obs - 1:
            continue
        out.append(Window(track, i, n - 1 - last,
                          track.frames[track.end] - track.frames[last], k))
    return out


def seeded_split(windows: list, *, seed: int, val_frac: float, test_frac: float) -> list:
    """Per window its split, by video, by the core's rule (bsp-convert's seeded split:
    videos fill train, val and test by their numbers of windows), through the clip planner
    with one one-frame recording per window."""
    videos = sorted({w.track.video for w in windows})
    code = {v: i for i, v in enumerate(videos)}
    n = len(windows)
    plan = _core.plan_clips(
        np.array([code[w.track.video] for w in windows], np.int32), np.zeros(n, np.int64),
        np.arange(n, dtype=np.int64), np.zeros(n, np.int64), np.zeros(n, np.uint8),
        np.zeros((n, 1, 2), np.float32), np.ones(n, np.int64), np.ones(n, np.int64),
        clip_length=1, clip_stride=1, eval_clip_stride=1, min_video_length=0,
        label_fraction=0.0, benchmark=False, val_frac=float(val_frac),
        test_frac=float(test_frac), seed=int(seed), balance=False)
    out = [None] * n
    for s in SPLITS:
        for r in plan[s]["recordings"]:
            for row in plan["recording_rows"][r]:
                out[row] = s
    return out


def _boxes(xyxy) -> np.ndarray:
    """(..., 4) x1, y1, x2, y2 -> (..., 2, 2) corners, the layout of ``targets/bboxes``."""
    xyxy = np.asarray(xyxy, np.float32)
    return xyxy.reshape(*xyxy.shape[:-1], 2, 2)


def _joint_boxes(uv, visible) -> np.ndarray:
    lo = np.where(visible[..., None], uv, np.inf).min(-2)
    hi = np.where(visible[..., None], uv, -np.inf).max(-2)
    none = ~visible.any(-1)
    lo[none], hi[none] = 0, 0
    return np.stack([lo, hi], -2).astype(np.float32)


def _split_arrays(windows: list, poses: dict, sizes: dict, skip: int, obs: int) -> dict:
    """The datasets of one split: ``poses[(track id, position)]`` = (uv, visible, conf)
    of the CARLA joints; ``skip`` frames dropped at each window's start."""
    pos = [[w.first + k for k in range(skip, obs)] for w in windows]
    N, L, J = len(windows), obs - skip, len(CARLA.joints)
    pick = lambda i, *shape: np.array(  # noqa: E731
        [[poses[(id(w.track), k)][i] for k in p] for w, p in zip(windows, pos)],
        np.float64).reshape(N, L, J, *shape)
    uv = pick(0, 2).astype(np.float32)
    visible = pick(1).astype(bool)
    frames = np.array([[w.track.frames[k] for k in p] for w, p in zip(windows, pos)],
                      np.int64).reshape(-1, L)
    labels = np.array([w.track.label for w in windows], np.uint8)
    size = np.array([sizes[w.track.video] for w in windows], np.int64).reshape(-1, 2)
    return {"projection_2d": uv, "visible": visible.astype(np.uint8),
            "confidence": pick(2).astype(np.float32), "labels": labels,
            "targets/bboxes": _joint_boxes(uv, visible),
            "targets/annotated_bboxes": _boxes(np.array(
                [[w.track.boxes[k] for k in p] for w, p in zip(windows, pos)]).reshape(N, L, 4)),
            "targets/is_crossing": np.repeat(labels[:, None], L, 1),
            "targets/frame_idx": frames,
            "meta/clip_id": np.array([w.index for w in windows], np.int32),
            "meta/segment": np.zeros(len(windows), np.int32),
            "meta/start_frame": frames[:, 0], "meta/end_frame": frames[:, -1] + 1,
            "meta/clip_width": size[:, 0], "meta/clip_height": size[:, 1],
            "meta/tte": np.array([w.tte for w in windows], np.int32),
            "meta/frames_to_event": np.array([w.frames_to_event for w in windows], np.int32)}


_STR_META = ("video_id", "pedestrian_id", "age", "gender", "model", "map")


def write_windows(path, windows: list, split: list, poses: dict, sizes: dict, *, obs: int,
                  drop_first: bool, attrs: dict) -> dict:
    """Writes the clip file ``path`` (HDF5, the bsp-convert layout of docs/interop.md):
    per split its windows ordered by (video, pedestrian, start), plus ``targets/
    annotated_bboxes`` (the annotation's boxes), ``meta/tte``, ``meta/frames_to_event``
    and, with ``drop_first``, ``targets/box_reference``; ``attrs`` as root attributes.
    Returns ``{split: (windows, [not-crossing, crossing])}``."""
    import h5py

    text, skip, out = h5py.string_dtype(), int(drop_first), {}
    with h5py.File(path, "w") as f:
        for s in SPLITS:
            ws = sorted((w for w, x in zip(windows, split) if x == s),
                        key=lambda w: (w.track.video, w.track.pid, w.first))
            g = f.create_group(s)
            for name, a in _split_arrays(ws, poses, sizes, skip, obs).items():
                g[name] = a
            if drop_first:
                g["targets/box_reference"] = _boxes(
                    np.array([w.track.boxes[w.first] for w in ws]).reshape(-1, 4))
            meta = dict(video_id=[w.track.video for w in ws],
                        pedestrian_id=[w.track.pid for w in ws])
            for k in _STR_META:
                g.create_dataset(f"meta/{k}", data=meta.get(k, [""] * len(ws)), dtype=text)
            counts = np.bincount(g["labels"][()], minlength=2).astype(np.int64)
            g.attrs["class_counts"] = counts
            g.attrs["recordings"] = len({(w.track.video, w.track.pid) for w in ws})
            f.attrs[f"class_counts_{s}"] = counts
            out[s] = (len(ws), counts.tolist())
        f.attrs.update(dict(schema_version=1, created_by=f"bsp_fast {__version__}",
                            clip_length=obs - skip, media=0, compression="none",
                            class_labels=["not-crossing", "crossing"],
                            joint_names=list(CARLA.joints),
                            parents=np.asarray(CARLA.parents, np.int64)))
        f.attrs.update({k: (json.dumps(v, sort_keys=True) if isinstance(v, dict) else v)
                        for k, v in attrs.items()})
    return out
