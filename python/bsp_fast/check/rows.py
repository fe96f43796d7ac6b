"""The data.csv side of bsp-check: recordings, references, duplicates, gaps, statistics.

Nothing here opens a media file; :mod:`.scan` does that. A *recording* is the rows of one
(id, camera.idx, pedestrian.idx), sorted by frame.idx (file order among equal frames).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..csvio import CROSSING, read_csv

IN_SEG = "frame.pedestrian.pose.in_segmentation"
UV = "frame.pedestrian.pose.camera"
COLUMNS = ("id", "camera.idx", "pedestrian.idx", "frame.idx", "camera.width", "camera.height",
           "camera.recording", "camera.semantic_segmentation", "pedestrian.age",
           "pedestrian.gender", CROSSING, UV, IN_SEG)
#: File name endings bsp-check treats as media (files no row references are reported).
MEDIA_SUFFIXES = (".mp4", ".apng", ".png", ".avi", ".mkv", ".mov", ".webm", ".npy", ".npz")


@dataclass
class Recording:
    """Rows of one (id, camera.idx, pedestrian.idx) and what the CSV says about them."""

    index: int
    id: str
    camera_idx: int
    pedestrian_idx: int
    rows: np.ndarray          # row numbers, sorted by frame.idx (file order among equals)
    frames: np.ndarray        # frame.idx of those rows
    video: str                # camera.recording of the first row
    segmentation: str         # camera.semantic_segmentation of the first row
    width: int
    height: int
    age: str
    gender: str
    duplicates: np.ndarray    # rows (of `rows`) repeating an earlier row's frame.idx
    segments: int = 1
    missing_frames: int = 0   # frames inside [first, last] with no row
    problems: list = field(default_factory=list)   # (kind, message); kinds break it
    # Filled by the media scan (None: not looked at).
    video_frames: int | None = None
    segmentation_frames: int | None = None
    mask_any: np.ndarray | None = None    # (rows,) tag-4 pixel anywhere in the frame
    mask_near: np.ndarray | None = None   # (rows,) a tag-4 pixel near the joints
    scanned: np.ndarray | None = None     # (rows,) the row's mask frame was decoded
    # Row findings of the media scan: rows (table row numbers) whose in_segmentation
    # disagrees with the mask, rows with no tag-4 pixel around their joints.
    mismatch: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    occluded: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    never_visible: bool = False

    @property
    def key(self) -> str:
        return f"{self.id} camera {self.camera_idx} pedestrian {self.pedestrian_idx}"

    @property
    def broken(self) -> bool:
        return bool(self.problems)


def unsafe_path(p: str) -> str:
    """Why a media path from data.csv must not be opened, or "" when it is fine."""
    if not p:
        return "empty path"
    if p.startswith(("/", "\\")) or os.path.isabs(p) or (len(p) > 1 and p[1] == ":"):
        return "absolute path"
    if any(part == ".." for part in p.replace("\\", "/").split("/")):
        return "path leaves the dataset (..)"
    return ""


def read_table(csv: str, threads: int | None):
    """The columns bsp-check needs; duplicates are found here, not refused by the reader."""
    return read_csv(csv, COLUMNS, threads=threads, check_duplicates=False)


def recordings(table) -> list:
    """Groups the rows into recordings, in the order they first appear in the file."""
    n = len(table)
    if n == 0:
        return []
    idc = table.codes("id")
    cam, ped, fi = table["camera.idx"], table["pedestrian.idx"], table["frame.idx"]
    order = np.lexsort((np.arange(n), fi, ped, cam, idc))
    k = np.stack([idc[order], cam[order], ped[order]], 1)
    starts = np.flatnonzero(np.r_[True, (k[1:] != k[:-1]).any(1)])
    ends = np.r_[starts[1:], n]
    groups = [order[a:b] for a, b in zip(starts, ends)]
    groups.sort(key=lambda g: g.min())
    ids = table.categories("id")
    out = []
    for i, rows in enumerate(groups):
        out.append(_recording(table, i, rows, ids))
    return out


def _first_and_more(table, name: str, rows: np.ndarray) -> tuple:
    codes = table.codes(name)[rows]
    cats = table.categories(name)
    return str(cats[codes[0]]), np.unique(codes).size > 1


def _recording(table, index: int, rows: np.ndarray, ids) -> Recording:
    r0 = rows[0]
    fi = table["frame.idx"][rows]
    video, v_many = _first_and_more(table, "camera.recording", rows)
    seg, s_many = _first_and_more(table, "camera.semantic_segmentation", rows)
    age, _ = _first_and_more(table, "pedestrian.age", rows)
    gender, _ = _first_and_more(table, "pedestrian.gender", rows)
    w, h = table["camera.width"][rows], table["camera.height"][rows]
    dup = np.r_[False, fi[1:] == fi[:-1]]
    rec = Recording(index=index, id=str(ids[table.codes("id")[r0]]),
                    camera_idx=int(table["camera.idx"][r0]),
                    pedestrian_idx=int(table["pedestrian.idx"][r0]), rows=rows, frames=fi,
                    video=video, segmentation=seg, width=int(w[0]), height=int(h[0]),
                    age=age, gender=gender, duplicates=rows[dup])
    uniq = fi[~dup]
    if len(uniq):
        steps = np.diff(uniq)
        rec.segments = int(np.count_nonzero(steps > 1)) + 1
        rec.missing_frames = int((steps[steps > 1] - 1).sum())
    if v_many or s_many:
        rec.problems.append(("inconsistent_recording", "its rows reference several "
                             + ("videos" if v_many else "segmentation files")))
    if (w != w[0]).any() or (h != h[0]).any():
        rec.problems.append(("inconsistent_recording", "its rows give several image sizes"))
    if len(fi) and fi[0] < 0:
        rec.problems.append(("negative_frame_idx", f"frame.idx {int(fi[0])} < 0"))
    for what, p in (("camera.recording", video), ("camera.semantic_segmentation", seg)):
        why = unsafe_path(p)
        if why:
            line = int(table.lines[r0])
            rec.problems.append(("unsafe_path", f"{what} {p!r} (line {line}): {why}; "
                                 "not opened"))
    return rec


def media_on_disk(root: str) -> list:
    """Media files under the dataset root, as '/'-separated paths relative to it."""
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for name in sorted(filenames):
            if name.lower().endswith(MEDIA_SUFFIXES):
                rel = os.path.relpath(os.path.join(dirpath, name), root)
                found.append(rel.replace(os.sep, "/"))
    return found


def event_camera_file(path: str, ids: set) -> bool:
    """`clips/<id>-2.*`: the optional event-camera output no column references."""
    stem = os.path.basename(path).rsplit(".", 1)[0]
    return stem.endswith("-2") and stem[:-2] in ids


def statistics(table, recs: list, clip_frames: int | None = None) -> dict:
    """Scenes, annotated and crossing frames per (age, gender), and the annotated share.

    Duplicate rows count once. A recording's frame total is its video's frame count when
    the video was read, else (poses only, missing video) ``clip_frames`` (config.yaml's
    clip_length_in_frames) when given, else its last frame.idx + 1.
    """
    crossing = table[CROSSING]
    per: dict = {}
    total_frames, basis = 0, set()
    for r in recs:
        rows = r.rows[~np.isin(r.rows, r.duplicates)]
        p = per.setdefault((r.age, r.gender), {"age": r.age, "gender": r.gender, "scenes": 0,
                                               "frames": 0, "crossing_frames": 0})
        p["scenes"] += 1
        p["frames"] += int(len(rows))
        p["crossing_frames"] += int(np.count_nonzero(crossing[rows]))
        if r.video_frames is not None:
            total_frames += r.video_frames
            basis.add("video frame counts")
        elif clip_frames:
            total_frames += int(clip_frames)
            basis.add("config.yaml clip_length_in_frames")
        elif len(r.frames):
            total_frames += int(r.frames.max()) + 1
            basis.add("last frame.idx + 1")
    rows = sorted(per.values(), key=lambda p: (p["age"], p["gender"]))
    total = {"age": "all", "gender": "all",
             "scenes": sum(p["scenes"] for p in rows),
             "frames": sum(p["frames"] for p in rows),
             "crossing_frames": sum(p["crossing_frames"] for p in rows)}
    for p in rows + [total]:
        p["crossing_share"] = p["crossing_frames"] / p["frames"] if p["frames"] else 0.0
    return {"per_profile": rows, "total": total, "video_frames": total_frames,
            "annotated_share": total["frames"] / total_frames if total_frames else None,
            "video_frames_from": " and ".join(sorted(basis)) or "none"}
