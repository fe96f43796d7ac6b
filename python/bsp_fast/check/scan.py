"""The media side of bsp-check: one job per segmentation file, run on a thread pool.

A job opens the videos of its recordings (the reader counts frames by scanning packets,
without decoding), then decodes the segmentation APNG once, forward, copying out only the
frames that rows are annotated on, and measures each such row's mask: tag-4 (pedestrian)
pixels inside a window around the row's projected joints, and, only where that window
holds none, whether the frame holds any at all. The C++ readers release the GIL while they
read, so jobs on several threads use several cores.
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
    "rows": {key: (mask_any, mask_near, scanned)}}; every error is caught and returned.
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
    keys, wins, apng = [], [], []
    W, H = reader.size
    for key, _, frames, uv, *_ in entries:
        f = np.asarray(frames, np.int64)
        idx = np.full(len(f), -1, np.int64)
        ok = (f >= 0) & (f <= last)
        idx[ok] = mapping[f[ok]]
        keys.append(key)
        apng.append(idx)
        wins.append(joint_windows(uv, W, H))
        out["rows"][key] = (np.zeros(len(f), bool), np.zeros(len(f), np.int64),
                            np.zeros(len(f), bool))
    try:
        _measure(reader, keys, apng, wins, out["rows"])
    except Exception as e:  # noqa: BLE001 - a damaged frame: rows before it are measured
        info["error"] = f"{type(e).__name__}: {e}"
    return out


def _measure(reader: ApngReader, keys, apng, wins, results) -> None:
    flat_idx = np.concatenate(apng) if apng else np.empty(0, np.int64)
    owner = np.concatenate([np.full(len(a), i) for i, a in enumerate(apng)]) if apng else flat_idx
    local = np.concatenate([np.arange(len(a)) for a in apng]) if apng else flat_idx
    flat_win = np.concatenate(wins) if wins else np.empty((0, 4), np.int64)
    keep = flat_idx >= 0
    order = np.flatnonzero(keep)[np.argsort(flat_idx[keep], kind="stable")]
    frames_needed = np.unique(flat_idx[order])
    W, H = reader.size
    step = max(1, BATCH_BYTES // max(1, W * H * max(1, reader.channels)))
    pos = 0
    for b in range(0, len(frames_needed), step):
        want = frames_needed[b:b + step]
        batch = reader.read(want)
        if batch.ndim != 3:  # not a palette/grey file: no tags to look at
            raise ValueError("segmentation is not an 8-bit palette (class tag) image")
        top = want[-1]
        while pos < len(order) and flat_idx[order[pos]] <= top:
            i = order[pos]
            frame = batch[np.searchsorted(want, flat_idx[i])]
            u0, v0, u1, v1 = flat_win[i]
            near = int(np.count_nonzero(frame[v0:v1, u0:u1] == PEDESTRIAN_TAG)) \
                if u1 > u0 and v1 > v0 else 0
            any_, near_, scanned = results[keys[owner[i]]]
            k = local[i]
            near_[k] = near
            any_[k] = near > 0 or _has_tag(frame)
            scanned[k] = True
            pos += 1


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
