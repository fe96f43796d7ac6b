"""The media side of bsp-check: one job per segmentation file, run on a thread pool.

A job opens the videos of its recordings (the reader counts frames by scanning packets,
without decoding), then decodes the segmentation APNG once, forward, copying out only the
frames that rows are annotated on, and measures each such row's mask: is there a tag-4
(pedestrian) pixel near the row's projected joints (first the joints' own pixels, gathered
for a whole batch in one NumPy call; for the rows none of them hits, a window around the
joints), and, only where there is none, anywhere in the frame. The C++ readers release the
GIL while they read, so jobs on several threads use several cores.
"""
from __future__ import annotations

import os

import numpy as np

from ..media import ApngReader, VideoReader
from .rows import UV

PEDESTRIAN_TAG = 4
#: The window around the joints: their bounding box grown by this share of its larger
#: side, and by at least WINDOW_MIN_MARGIN pixels, on every side.
WINDOW_MARGIN = 0.25
WINDOW_MIN_MARGIN = 8
BATCH_BYTES = 8 << 20


def joint_windows(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """(n, 4) int64 pixel windows [u0, v0, u1, v1) (clipped to the image; empty when no
    joint is finite) around (n, 26, 2) projected joints."""
    uv = np.asarray(uv, np.float64)
    ok = np.isfinite(uv).all(-1)
    lo = np.where(ok[..., None], uv, np.inf).min(1)
    hi = np.where(ok[..., None], uv, -np.inf).max(1)
    with np.errstate(invalid="ignore"):
        side = np.max(hi - lo, axis=1)
        margin = np.maximum(WINDOW_MIN_MARGIN, WINDOW_MARGIN * np.nan_to_num(side))
        a = np.floor(lo - margin[:, None])
        b = np.floor(hi + margin[:, None]) + 1
    any_ok = ok.any(1)
    a = np.where(any_ok[:, None], a, 0)
    b = np.where(any_ok[:, None], b, 0)
    size = np.array([width, height], np.float64)
    a = np.clip(a, 0, size)
    b = np.clip(b, 0, size)
    return np.concatenate([a, b], 1).astype(np.int64)


def _has_tag(frame: np.ndarray, tag: int = PEDESTRIAN_TAG) -> bool:
    # bytes.find is a memchr: the fastest whole-frame test NumPy offers no short cut for.
    return frame.tobytes().find(bytes([tag])) >= 0


def _open_video(path: str) -> dict:
    try:
        r = VideoReader(path, threads=1)
        return {"frames": len(r), "size": list(r.size), "fps": r.fps, "error": None}
    except Exception as e:  # noqa: BLE001 - every reader error is a finding
        return {"frames": None, "size": None, "fps": None, "error": f"{type(e).__name__}: {e}"}


def scan_job(root: str, seg: str, entries: list, fps: float) -> dict:
    """Checks one segmentation file and the videos of the recordings that use it.

    ``entries``: [(key, video path, rows' frame.idx, rows' (n, 26, 2) joints, width,
    height)], all relative paths. Returns {"videos": {path: info}, "segmentation": info,
    "rows": {key: (mask_any, mask_near, scanned)}} (three bool arrays per recording);
    every error is caught and returned.
    """
    out: dict = {"videos": {}, "segmentation": None, "rows": {}}
    for _, video, *_ in entries:
        if video not in out["videos"]:
            out["videos"][video] = _open_video(os.path.join(root, video))
    info: dict = {"frames": None, "size": None, "error": None, "covers": None}
    out["segmentation"] = info
    try:
        reader = ApngReader(os.path.join(root, seg))
    except Exception as e:  # noqa: BLE001
        info["error"] = f"{type(e).__name__}: {e}"
        return out
    info["frames"], info["size"] = len(reader), list(reader.size)
    video_fps = [v["fps"] for v in out["videos"].values() if v["fps"]]
    fps = video_fps[0] if video_fps else fps
    last = max((int(e[2].max()) for e in entries if len(e[2])), default=-1)
    mapping = reader.video_to_apng_frames(last + 1, fps) if last >= 0 else np.empty(0, np.int64)
    info["covers"] = int(np.count_nonzero(mapping >= 0))
    # Every row of every recording of this file, as (apng frame, window).
    keys, wins, apng, joints = [], [], [], []
    W, H = reader.size
    for key, _, frames, uv, *_ in entries:
        f = np.asarray(frames, np.int64)
        idx = np.full(len(f), -1, np.int64)
        ok = (f >= 0) & (f <= last)
        idx[ok] = mapping[f[ok]]
        keys.append(key)
        apng.append(idx)
        wins.append(joint_windows(uv, W, H))
        joints.append(_joint_pixels(np.asarray(uv, np.float64), W, H))
    try:
        _measure(reader, keys, apng, wins, joints, out["rows"])
    except Exception as e:  # noqa: BLE001 - a damaged frame: rows before it are measured
        info["error"] = f"{type(e).__name__}: {e}"
    return out


def _joint_pixels(uv: np.ndarray, width: int, height: int) -> tuple:
    """(x, y, ok) int64 pixel of each joint and whether it lies in the image."""
    with np.errstate(invalid="ignore"):
        x, y = np.floor(uv[..., 0]), np.floor(uv[..., 1])
        ok = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (y >= 0) & (x < width) & (y < height)
    return (np.where(ok, x, 0).astype(np.int64), np.where(ok, y, 0).astype(np.int64), ok)


def _measure(reader: ApngReader, keys, apng, wins, joints, results) -> None:
    """Fills results[key] = (any pedestrian pixel in the frame, one near the joints,
    measured) per row. Most rows are settled by the joints' own pixels, gathered for a
    whole batch at once; only the others have their window scanned."""
    n = sum(len(a) for a in apng)
    flat_idx = np.concatenate(apng) if n else np.empty(0, np.int64)
    flat_win = np.concatenate(wins) if n else np.empty((0, 4), np.int64)
    jx, jy, jok = (np.concatenate([j[i] for j in joints]) if n else np.empty((0, 26), np.int64)
                   for i in range(3))
    near = np.zeros(n, bool)
    any_ = np.zeros(n, bool)
    scanned = np.zeros(n, bool)
    order = np.flatnonzero(flat_idx >= 0)
    order = order[np.argsort(flat_idx[order], kind="stable")]
    frames_needed = np.unique(flat_idx[order])
    sorted_idx = flat_idx[order]
    W, H = reader.size
    step = max(1, BATCH_BYTES // max(1, W * H * max(1, reader.channels)))
    tag, frame = PEDESTRIAN_TAG, None
    try:
        for b in range(0, len(frames_needed), step):
            want = frames_needed[b:b + step]
            batch = reader.read(want)
            if batch.ndim != 3:  # not a palette/grey file: no tags to look at
                raise ValueError("segmentation is not an 8-bit palette (class tag) image")
            rows = order[np.searchsorted(sorted_idx, want[0], side="left"):
                         np.searchsorted(sorted_idx, want[-1], side="right")]
            at = np.searchsorted(want, flat_idx[rows])
            hit = ((batch[at[:, None], jy[rows], jx[rows]] == tag) & jok[rows]).any(1)
            near[rows[hit]] = any_[rows[hit]] = True
            miss = ~hit
            for i, k, (u0, v0, u1, v1) in zip(rows[miss].tolist(), at[miss].tolist(),
                                               flat_win[rows[miss]].tolist()):
                frame = batch[k]
                c = u1 > u0 and v1 > v0 and bool((frame[v0:v1, u0:u1] == tag).any())
                near[i] = c
                any_[i] = c or _has_tag(frame, tag)
            scanned[rows] = True
            # Free this batch before reading the next, so its memory is reused instead of
            # a fresh allocation being page-faulted in.
            del batch
            frame = None
    finally:
        start = 0
        for key, a in zip(keys, apng):
            stop = start + len(a)
            results[key] = (any_[start:stop], near[start:stop], scanned[start:stop])
            start = stop


def scan_entries(table, recs: list) -> dict:
    """{segmentation path: [entry, ...]} for the recordings that may be opened."""
    uv = table[UV]
    jobs: dict = {}
    for r in recs:
        if r.broken:
            continue
        jobs.setdefault(r.segmentation, []).append(
            (r.index, r.video, r.frames, uv[r.rows], r.width, r.height))
    return jobs
