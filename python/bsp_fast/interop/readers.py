"""Readers of other tools' 2D pose files: COCO keypoint results / annotations JSON (MMPose,
Detectron2, our exporter) and OpenPose's per-frame JSON, and the labels CSV.

Each reader returns :class:`Detections`: one row per (video, track, frame) with the
source joint set's points and confidences, the image size and where the row came from
(``FILE record N`` / ``FILE``) for error messages. Bad input raises :class:`BadInput`
naming the file, the record and the reason.
"""
from __future__ import annotations

import contextlib
import contextvars
import csv
import json
import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from ..skeleton import joint_set

__all__ = ["BadInput", "Detections", "read_coco", "read_openpose", "read_labels",
           "load_json", "option", "cli_wording"]


class BadInput(ValueError):
    """An input file cannot be imported as it is (the message names file, record, reason).
    Bad data, not a bad argument: exit code 1 (command_line.exit_code reads ``code``)."""

    code = 1


_WORDING = contextvars.ContextVar("bsp_interop_wording", default="python")


def option(python: str, cli: str) -> str:
    """How a message names an option: the command line's spelling (``--skip-short-tracks``)
    inside :func:`cli_wording` (``bsp-interop``), else the Python argument's."""
    return cli if _WORDING.get() == "cli" else python


@contextlib.contextmanager
def cli_wording():
    """Messages raised inside name options as ``bsp-interop`` spells them."""
    token = _WORDING.set("cli")
    try:
        yield
    finally:
        _WORDING.reset(token)


@dataclass
class Detections:
    """Rows of 2D poses: ``points (N, J, 2)`` and ``scores (N, J)`` (float64) in the joint
    set ``joints``; ``video``, ``track`` (str lists), ``frame`` (int64), ``width``,
    ``height`` (int64) and ``where`` (str list) per row. ``notes``: what the reader saw
    about tracks and frames (:func:`track_notes`), for the summary."""

    joints: str
    video: list
    track: list
    frame: np.ndarray
    points: np.ndarray
    scores: np.ndarray
    width: np.ndarray
    height: np.ndarray
    where: list
    source: str
    notes: dict = field(default_factory=dict)
    #: ``{(video, track, frame): crossing}`` where every record carries one (our COCO
    #: export writes each frame's label), else None
    labels: dict | None = None
    #: ``{video: split}`` where every image names one (our COCO export), else None
    splits: dict | None = None


def load_json(path):
    """``json.load`` with a :class:`BadInput` naming the file, line and column."""
    path = Path(path)
    try:
        with path.open("r", encoding="utf-8") as fh:
            return json.load(fh)
    except json.JSONDecodeError as exc:
        raise BadInput(f"{path}: malformed JSON at line {exc.lineno} column {exc.colno}: "
                       f"{exc.msg}; nothing written") from None
    except UnicodeDecodeError as exc:
        raise BadInput(f"{path}: not UTF-8 text ({exc.reason}); nothing written") from None


def _numbers(values, count: int, what: str) -> np.ndarray:
    if not isinstance(values, list) or len(values) != count:
        n = len(values) if isinstance(values, list) else type(values).__name__
        raise ValueError(f"{what} has {n} values, expected {count}")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise ValueError(f"{what} holds a value that is not a number")
    a = np.asarray(values, np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} holds a non-finite number")
    return a


def _image_size(image_size) -> tuple | None:
    if image_size is None:
        return None
    try:
        w, h = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ValueError(f"image_size must be (width, height) in pixels, got {image_size!r}") from None
    if w <= 0 or h <= 0:
        raise ValueError(f"image_size must be positive, got {image_size!r}")
    return w, h


_STEM_DIGITS = re.compile(r"(\d+)$")


def _image_table(doc, path: Path, default_size) -> dict:
    """image id -> (video, frame, width, height) from a COCO-style ``images`` list."""
    images = doc.get("images") if isinstance(doc, dict) else None
    if not isinstance(images, list):
        raise BadInput(f"{path}: no 'images' list (a COCO-style file whose images give the "
                       "video and frame of each image id)")
    table = {}
    for k, im in enumerate(images):
        where = f"{path}: images[{k}]"
        if not isinstance(im, dict) or "id" not in im:
            raise BadInput(f"{where}: an image needs an 'id'")
        name = PurePosixPath(str(im.get("file_name", "")))
        video = im.get("video", im.get("vid_id", str(name.parent) if name.parent.name else None))
        frame = im.get("frame")
        if frame is None:
            m = _STEM_DIGITS.search(name.stem)
            frame = int(m.group(1)) if m else None
        if not video or frame is None or not isinstance(frame, int) or frame < 0:
            raise BadInput(f"{where} (id {im['id']!r}): cannot tell its video and frame: give "
                           "'video' and 'frame', or a file_name like VIDEO/000042.jpg")
        size = (im.get("width"), im.get("height"))
        if size[0] is None or size[1] is None:
            if default_size is None:
                raise BadInput(f"{where} (id {im['id']!r}): no width/height; pass "
                               + option("image_size=(W, H)", "--image-size WxH"))
            size = default_size
        if im["id"] in table:
            raise BadInput(f"{where}: image id {im['id']!r} appears twice")
        table[im["id"]] = (str(video), int(frame), int(size[0]), int(size[1]),
                           im.get("split"))
    return table


def _source_splits(table: dict) -> tuple:
    """``({video: split} or None, note)``: the split every image names (our COCO export
    writes the clip file's), one per video; None where an image names none or a video
    has two."""
    splits, note = {}, ""
    for video, _, _, _, split in table.values():
        if split not in ("train", "val", "test"):
            return None, ""
        if splits.setdefault(video, split) != split:
            return None, (f"video {video!r} has images in the {splits[video]} and {split} "
                          "splits: the split is seeded instead")
    return splits, note


def read_coco(path, images=None, image_size=None, tracks: str = "require",
              joints="coco17") -> Detections:
    """A COCO keypoint **results** file (a JSON list of ``{image_id, category_id,
    keypoints: [x, y, score] * 17, score, track_id?}``, what MMPose and Detectron2 write)
    or a COCO keypoint **annotations** file (a dict with ``images`` and ``annotations``;
    ``v > 0`` counts as confidence 1, ``v = 0`` as 0).

    ``images``: a COCO-style JSON whose ``images`` give each image id's video and frame
    (keys ``video``/``vid_id`` and ``frame``, else the folder and the trailing digits of
    ``file_name``) and size; an annotations file carries its own. ``image_size`` (W, H)
    is used where an image has no width/height. ``tracks``: ``require`` (records without
    ``track_id`` are allowed only where an image holds one detection: track ``"0"``) or
    ``best`` (without track ids, follow one person per video: the one nearest the previous
    frame's pose; see :func:`_assign_untracked`).
    ``joints``: the keypoints' joint set (COCO-17 unless the file follows another layout,
    e.g. ``body25`` from our exporter)."""
    if tracks not in ("require", "best"):
        raise ValueError(f"tracks must be 'require' or 'best', got {tracks!r}")
    path = Path(path)
    records, annotations, table = _coco_records(path, images, _image_size(image_size))
    jset = joint_set(joints)
    table_size = {(v, f): (w, h) for v, f, w, h, _ in table.values()}
    rows, crossing = [], {}
    for k, rec in enumerate(records):
        rows.append(_coco_row(rec, f"{path}: record {k}", table, jset, annotations))
        crossing[rows[-1][5]] = rec.get("crossing")
    frames = {}
    for video, frame, *_ in table.values():
        frames.setdefault(video, set()).add(frame)
    rows = [((*table[r[0]][:2],),) + r[1:] for r in rows]
    rows, notes = _assign_untracked(rows, tracks, frames, _COCO_WORDS)
    out = [(*r[0], r[1], r[2], r[3], *table_size[r[0]], r[5]) for r in rows]
    det = _detections(jset.name, out, str(path), notes)
    if crossing and all(v in (0, 1) for v in crossing.values()):
        det.labels = {(v, t, int(f)): crossing[w]
                      for v, t, f, w in zip(det.video, det.track, det.frame, det.where)}
    det.splits, note = _source_splits(table)
    if note:
        det.notes["split_note"] = note
    return det


def _coco_records(path: Path, images, size) -> tuple:
    """The records of a COCO results list or annotations dict, whether they are
    annotations, and the image table (from ``images``, else the annotations file's own)."""
    doc = load_json(path)
    if isinstance(doc, dict) and "annotations" in doc:
        records, annotations = doc["annotations"], True
        table = _image_table(load_json(images) if images else doc,
                             Path(images) if images else path, size)
    elif isinstance(doc, list):
        records, annotations = doc, False
        if images is None:
            raise BadInput(f"{path}: a COCO results list names images by id only; pass the "
                           "COCO-style JSON of those images ("
                           + option("images=PATH", "--images IMAGES.json") + ")")
        table = _image_table(load_json(images), Path(images), size)
    else:
        raise BadInput(f"{path}: expected a COCO results list or a COCO annotations dict "
                       f"with 'annotations', got a JSON {type(doc).__name__}")
    if not isinstance(records, list):
        raise BadInput(f"{path}: 'annotations' must be a list")
    return records, annotations, table


def _coco_row(rec, where: str, table: dict, jset, annotations: bool) -> tuple:
    """One COCO record checked: (image id, track or None, (J, 2) points, confidences,
    score, where it is)."""
    J = len(jset)
    try:
        if not isinstance(rec, dict):
            raise ValueError("not a JSON object")
        for key in ("image_id", "keypoints"):
            if key not in rec:
                raise ValueError(f"no {key!r}")
        if rec.get("category_id", 1) != 1:
            raise ValueError(f"category_id {rec['category_id']!r} is not 1 (person)")
        kp = _numbers(rec["keypoints"], 3 * J, f"keypoints ({jset.name})").reshape(J, 3)
        if rec["image_id"] not in table:
            raise ValueError(f"image_id {rec['image_id']!r} is not in the images list")
        score = float(rec.get("score", 1.0)) if not annotations else 1.0
    except (ValueError, TypeError) as exc:
        raise BadInput(f"{where}: {exc}") from None
    conf = (kp[:, 2] > 0).astype(np.float64) if annotations else kp[:, 2]
    track = rec.get("track_name", rec.get("track_id"))  # our exporter: both
    return (rec["image_id"], None if track is None else str(track), kp[:, :2], conf,
            score, f"{where} (image_id {rec['image_id']!r})")


_COCO_WORDS = dict(
    image="image", id="track_id",
    several="{n} detections without track_id in this image; run a tracker first (a "
            "'track_id' per record), or follow one person per video ({best})")
_OPENPOSE_WORDS = dict(
    image="frame", id="person_id",
    several="{n} people without person_id in this frame; run OpenPose with --tracking 1 "
            "(a person_id per person), or follow one person per video ({best})")

#: ``tracks='best'``: a nearest pose farther than this (mean joint distance over the
#: followed pose's box diagonal) from where the followed person was heading starts a new
#: track (an identity switch)
SWITCH_DISTANCE = 0.5
#: ``tracks='best'``: a nearest pose whose box diagonal is more than this factor larger or
#: smaller than the followed one's is someone else (a person nearer the camera in front)
SIZE_JUMP = 1.5
#: ``tracks='best'``: another person within this much (box diagonals) of the nearest one's
#: distance makes a frame ambiguous: the track stops there, the frame is not followed
AMBIGUOUS_MARGIN = 0.15


def _box_of(points, conf) -> tuple:
    seen = conf > 0
    p = points[seen] if seen.any() else points
    lo, hi = p.min(0), p.max(0)
    return (lo + hi) / 2, max(float(np.hypot(*(hi - lo))), 1.0)


def _distance(prev, cand) -> float:
    """Mean distance of the joints seen in both poses (else of the box centres), over
    the previous pose's box diagonal."""
    (pp, pc), (cp, cc) = prev, cand
    centre, diag = _box_of(pp, pc)
    both = (pc > 0) & (cc > 0)
    if both.any():
        return float(np.linalg.norm(pp[both] - cp[both], axis=1).mean()) / diag
    return float(np.linalg.norm(centre - _box_of(cp, cc)[0])) / diag


class _Follower:
    """One person followed through a video (``tracks='best'``): each frame takes the
    pose nearest where the followed one was heading (its last pose moved on by its box
    centre's motion per frame). Never silently someone else: a nearest pose too far
    (:data:`SWITCH_DISTANCE`) or of another size (:data:`SIZE_JUMP`) starts a new track;
    a frame where another person is about as close (:data:`AMBIGUOUS_MARGIN`) ends the
    track and is not followed, and the next clear frame starts a new one. Every new track
    after the first is a listed identity switch."""

    def __init__(self, video: str, word: str):
        self.video, self.word, self.track = video, word, -1
        self.prev = self.frame = self.unclear = None
        self.velocity = np.zeros(2)

    def _start(self, frame, reason: str, switches: list) -> None:
        self.track += 1
        if self.track > 0:
            switches.append(f"video {self.video!r} {self.word} {frame}: {reason}; track "
                            f"{self.track - 1} ends, track {self.track} starts")
        self.velocity, self.unclear = np.zeros(2), None

    def step(self, frame: int, group: list, switches: list):
        """The row followed in ``frame`` (None: an ambiguous frame, not followed)."""
        if self.prev is None:
            pick = max(group, key=lambda g: g[4])
            self._start(frame, "", switches)
        else:
            pts, conf = self.prev
            ahead = (pts + self.velocity * (frame - self.frame), conf)
            d = np.array([_distance(ahead, (g[2], g[3])) for g in group])
            order = np.argsort(d, kind="stable")
            pick, best = group[order[0]], float(d[order[0]])
            ratio = _box_of(pick[2], pick[3])[1] / _box_of(pts, conf)[1]
            close = len(group) > 1 and d[order[1]] <= best + AMBIGUOUS_MARGIN
            if close and best <= SWITCH_DISTANCE:
                self.unclear = self.unclear or (frame, float(d[order[1]]), best)
                return None
            reason = (f"the nearest person is {best:.2f} box diagonals from where the "
                      "followed one was heading" if best > SWITCH_DISTANCE else
                      f"the nearest person is {ratio:.2f} times the followed one's size"
                      if max(ratio, 1 / ratio) > SIZE_JUMP else None)
            if reason is None and self.unclear is not None:
                first, other, near = self.unclear
                reason = (f"from {self.word} {first} to {frame - 1} another person was "
                          "about as near where the followed one was heading "
                          f"({other:.2f} box diagonals against {near:.2f}): who is who "
                          "cannot be told, those frames are not followed")
            if reason is not None:
                self._start(frame, reason, switches)
            else:
                step = _box_of(pick[2], pick[3])[0] - _box_of(pts, conf)[0]
                self.velocity = step / max(frame - self.frame, 1)
        self.prev, self.frame = (pick[2], pick[3]), frame
        return pick


def _assign_untracked(rows: list, tracks: str, frames: dict, words: dict) -> tuple:
    """Rows ``((video, frame), track or None, points, conf, score, where)``. Rows without a
    track id: track ``"0"`` where alone in their frame; several in one frame are an error
    with ``tracks='require'``; ``tracks='best'`` follows one person per video
    (:class:`_Follower`; each identity switch starts the next track, ``"1"``, ...).
    ``frames``: every frame each video has (files or images, with people or not). Returns
    the kept rows and the notes (:func:`track_notes`)."""
    by_frame: dict = {}
    for r in rows:
        if r[1] is None:
            by_frame.setdefault(r[0], []).append(r)
    keep = [r for r in rows if r[1] is not None]
    switches, dropped = [], 0
    best = option("tracks='best'", "--tracks best")
    per_video: dict = {}  # grouped once: a scan of every key per video is quadratic
    for video, frame in by_frame:
        per_video.setdefault(video, []).append(frame)
    for video in sorted(per_video):
        follow = _Follower(video, words["image"])
        for frame in sorted(per_video[video]):
            group = by_frame[(video, frame)]
            if len(group) > 1 and tracks == "require":
                raise BadInput(f"{group[0][5]}: " + words["several"].format(n=len(group),
                                                                          best=best))
            pick = group[0] if tracks == "require" else follow.step(frame, group, switches)
            dropped += len(group) - (pick is not None)
            if pick is not None:
                keep.append((pick[0], str(max(follow.track, 0))) + pick[2:])
    return keep, track_notes(rows, frames, switches, dropped, words)


def track_notes(rows: list, frames: dict, switches: list, dropped: int, words: dict) -> dict:
    """``identity_switches`` (lines), ``empty_frames`` (``{video: n}``: frames with no
    person), ``dropped_frames`` (``{video: [frame, ...]}``: frame numbers missing between
    a video's first and last frame), ``dropped_detections`` (people not followed)."""
    with_people = {r[0] for r in rows}
    empty, missing = {}, {}
    for video, have in sorted(frames.items()):
        n = sum((video, f) not in with_people for f in have)
        if n:
            empty[video] = n
        gaps = sorted(set(range(min(have), max(have) + 1)) - set(have)) if have else []
        if gaps:
            missing[video] = gaps
    return dict(identity_switches=switches, empty_frames=empty, dropped_frames=missing,
                dropped_detections=int(dropped), frame_word=words["image"])


_OPENPOSE_NAME = re.compile(r"^(?P<video>.+)_(?P<frame>\d+)_keypoints\.json$")


def read_openpose(folder, image_size, tracks: str = "require") -> Detections:
    """OpenPose ``--write_json`` output: files ``VIDEO_<frame>_keypoints.json`` in
    ``folder`` (searched recursively), each ``{"people": [{"person_id": [id],
    "pose_keypoints_2d": [x, y, c] * 25}, ...]}`` (BODY_25). Tracks are the
    ``person_id`` (OpenPose's ``--tracking``); an untracked person (``-1``) is track
    ``"0"`` when alone in the frame (with ``tracks='best'``, the person nearest the
    previous frame's pose: :func:`_assign_untracked`).
    ``image_size`` (W, H): OpenPose files do not record it."""
    if tracks not in ("require", "best"):
        raise ValueError(f"tracks must be 'require' or 'best', got {tracks!r}")
    size = _image_size(image_size)
    if size is None:
        raise ValueError("image_size (W, H) is needed: OpenPose JSON does not record it")
    folder = Path(folder)
    if not folder.is_dir():
        raise BadInput(f"{folder}: not a folder of OpenPose *_keypoints.json files")
    files = sorted(folder.rglob("*_keypoints.json"))
    if not files:
        raise BadInput(f"{folder}: no *_keypoints.json file in it")
    J = len(joint_set("body25"))
    rows = []
    frames: dict = {}
    for path in files:
        m = _OPENPOSE_NAME.match(path.name)
        if m is None:
            raise BadInput(f"{path}: name is not VIDEO_<frame>_keypoints.json")
        doc = load_json(path)
        people = doc.get("people") if isinstance(doc, dict) else None
        if not isinstance(people, list):
            raise BadInput(f"{path}: no 'people' list")
        image = (m.group("video"), int(m.group("frame")))
        frames.setdefault(image[0], set()).add(image[1])
        for k, person in enumerate(people):
            where = f"{path}: people[{k}]"
            try:
                if not isinstance(person, dict):
                    raise ValueError("not a JSON object")
                kp = _numbers(person.get("pose_keypoints_2d"), 3 * J,
                              "pose_keypoints_2d").reshape(J, 3)
            except ValueError as exc:
                raise BadInput(f"{where}: {exc}") from None
            pid = person.get("person_id", [-1])
            pid = pid[0] if isinstance(pid, list) and pid else pid
            track = None if pid in (-1, None) else str(pid)
            rows.append((image, track, kp[:, :2], kp[:, 2], float(kp[:, 2].mean()), where))
    rows, notes = _assign_untracked(rows, tracks, frames, _OPENPOSE_WORDS)
    out = [(r[0][0], r[0][1], r[1], r[2], r[3], size[0], size[1], r[5]) for r in rows]
    return _detections("body25", out, str(folder), notes)


def _detections(joints: str, rows: list, source: str, notes=None) -> Detections:
    """Rows ``(video, frame, track, points, scores, W, H, where)``; duplicates refused."""
    seen = {}
    for r in rows:
        key = (r[0], r[2], r[1])
        if key in seen:
            raise BadInput(f"{r[7]}: video {r[0]!r} track {r[2]!r} frame {r[1]} appears twice "
                           f"(also {seen[key]})")
        seen[key] = r[7]
    J = len(joint_set(joints))
    return Detections(
        joints=joints, video=[r[0] for r in rows], track=[r[2] for r in rows],
        frame=np.array([r[1] for r in rows], np.int64),
        points=np.array([r[3] for r in rows], np.float64).reshape(-1, J, 2),
        scores=np.array([r[4] for r in rows], np.float64).reshape(-1, J),
        width=np.array([r[5] for r in rows], np.int64),
        height=np.array([r[6] for r in rows], np.int64),
        where=[r[7] for r in rows], source=source, notes=dict(notes or {}))


LABEL_COLUMNS = ("video", "track", "frame", "crossing")


def read_labels(path) -> dict:
    """The labels CSV (header ``video,track,frame,crossing``; crossing 0 or 1) as
    ``{(video, track, frame): crossing}``; BadInput names the line."""
    path = Path(path)
    out: dict = {}
    try:
        with path.open("r", encoding="utf-8", newline="") as fh:
            reader = csv.reader(fh)
            header = [h.strip() for h in next(reader, [])]
            missing = [c for c in LABEL_COLUMNS if c not in header]
            if missing:
                raise BadInput(f"{path}: line 1: header lacks {missing}; expected columns "
                               f"{','.join(LABEL_COLUMNS)}")
            col = {c: header.index(c) for c in LABEL_COLUMNS}
            for line, row in enumerate(reader, start=2):
                if not row or all(not c.strip() for c in row):
                    continue
                try:
                    video, track = row[col["video"]].strip(), row[col["track"]].strip()
                    frame = int(row[col["frame"]])
                    crossing = int(row[col["crossing"]])
                except (IndexError, ValueError):
                    raise BadInput(f"{path}: line {line}: expected video,track,frame (integer),"
                                   f"crossing (0 or 1), got {row!r}") from None
                if crossing not in (0, 1) or frame < 0 or not video or not track:
                    raise BadInput(f"{path}: line {line}: crossing must be 0 or 1 and frame "
                                   f">= 0, got {row!r}")
                key = (video, track, frame)
                if key in out:
                    raise BadInput(f"{path}: line {line}: video {video!r} track {track!r} frame "
                                   f"{frame} labelled twice")
                out[key] = crossing
    except UnicodeDecodeError as exc:
        raise BadInput(f"{path}: not UTF-8 text ({exc.reason})") from None
    return out

