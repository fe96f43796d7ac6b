"""What the JAAD and PIE importers share (:mod:`.jaad`, :mod:`.pie`): annotated tracks, 2D
poses joined to the annotated boxes (OpenPose JSON or the benchmark's pose pickles), and
the import itself: the tracks cut into the PedestrianActionBenchmark's windows and
written to a clip file by :mod:`.benchmark_windows` (which says how the benchmark cuts
them: by position, every window of a track with the track's label).
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_output
from ..skeleton import CARLA, joint_set
from .benchmark_windows import SPLITS, seeded_split, track_windows, write_windows
from .clipfile import clip_settings, map_joints
from .readers import BadInput, load_json
from .safe_pickle import RefusedPickle, load_file

__all__ = ["Track", "window_stride", "import_tracks", "check_options", "refuse_existing",
           "SPLITS", "BENCHMARK"]

#: the benchmark's defaults: observation length, time to event (frames), overlap per dataset
BENCHMARK = dict(obs_length=16, tte=(30, 60), overlap={"jaad": 0.8, "pie": 0.6})
#: OpenPose COCO-18 (the benchmark's pose pickles: nose, neck, Rsho, Relb, Rwri, Lsho,
#: Lelb, Lwri, Rhip, Rkne, Rank, Lhip, Lkne, Lank, Reye, Leye, Rear, Lear) -> BODY_25
#: indices (BODY_25 = COCO-18 with MidHip at 8 and the feet appended)
COCO18_TO_BODY25 = [0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18]
_OPENPOSE_NAME = re.compile(r"^(?P<video>.+)_(?P<frame>\d+)_keypoints\.json$")
_SET = re.compile(r"^set\d+$")


@dataclass(eq=False)
class Track:
    """One annotated pedestrian: ``frames`` and ``boxes`` (x1, y1, x2, y2) in file order,
    ``label`` (1: crosses at the event), ``end`` the index of the event frame in
    ``frames`` (the benchmark's sequence ends there; below 0: nothing left), ``split``
    (None: the seeded split), ``use`` False for tracks only kept to resolve which pose
    belongs to whom."""

    video: str
    pid: str
    frames: list
    boxes: list
    label: int
    end: int
    split: str | None
    where: str
    use: bool = True


def check_options(obs_length, tte, overlap, threshold) -> tuple:
    """The benchmark options, checked (``ValueError`` naming the allowed values) before
    anything is read; returns ``(tte, stride)``."""
    if isinstance(obs_length, bool) or not isinstance(obs_length, int) or obs_length < 2:
        raise ValueError(f"obs_length must be an integer >= 2, got {obs_length!r}")
    tte = tuple(int(v) for v in tte)
    if len(tte) != 2 or not 0 <= tte[0] <= tte[1]:
        raise ValueError(f"tte must be (min, max) with 0 <= min <= max, got {tte!r}")
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or threshold < 0:
        raise ValueError(f"threshold must be a number >= 0, got {threshold!r}")
    return tte, window_stride(overlap, obs_length)


def refuse_existing(out, force: bool) -> None:
    """An existing output without ``force`` is refused before any input is read (a full
    dataset takes minutes to read)."""
    if not force and Path(out).exists():
        raise FileExistsError(f"{out} exists; pass --force to replace it")


def window_stride(overlap: float, obs_length: int) -> int:
    """The benchmark's ``olap_res``: ``obs`` for no overlap, else ``int((1 - overlap) *
    obs)``, at least 1."""
    if not (isinstance(overlap, (int, float)) and 0 <= overlap < 1):
        raise ValueError(f"overlap must lie in [0, 1), got {overlap!r}")
    return obs_length if overlap == 0 else max(1, int((1 - overlap) * obs_length))


# ------------------------------------------------------------------------------- poses
def _body25(coco18: np.ndarray, derive: bool) -> tuple:
    """(18, 2) pixels (0, 0 = missing) -> BODY_25 points and confidences (1 / 0)."""
    pts, conf = np.zeros((25, 2)), np.zeros(25)
    seen = ~np.all(coco18 == 0, axis=1)
    pts[COCO18_TO_BODY25], conf[COCO18_TO_BODY25] = coco18, seen.astype(np.float64)
    if derive and seen[8] and seen[11]:  # MidHip = mid(RHip, LHip), as OpenPose's own
        pts[8], conf[8] = (coco18[8] + coco18[11]) / 2, 1.0
    return pts, conf


class PickledPoses:
    """The benchmark's pose pickles: ``pose_<set>.pkl`` = ``{video: {"<frame:05d>_<pid>":
    36 values}}``, the 18 COCO-18 joints' (x, y), (0, 0) where missing. ``path``: one
    file or a folder of them; ``video_key(set, video)`` names the video as the annotations
    do. The benchmark's own pickles hold coordinates normalised by the image size; some
    tools write pixels. Decided per video: normalised when at most half of its non-zero
    coordinates exceed 1 (values above 1 then lie outside the image, and are counted in
    ``warnings``), else pixels (values beyond the image size counted likewise). A pose
    whose 36 values are all 0 is a pose without any joint (every joint missing), counted
    in ``all_zero``."""

    def __init__(self, path, video_key, derive: bool = True):
        path = Path(path)
        files = sorted(path.glob("*.pkl")) if path.is_dir() else [path]
        if not files or not files[0].is_file():
            raise BadInput(f"{path}: no pose pickle (*.pkl) there; nothing written")
        self.poses, self.units, self.derive, self.name = {}, {}, derive, str(path)
        self.body25 = set(COCO18_TO_BODY25) | ({8} if derive else set())
        self.all_zero, self.warnings = 0, []
        for f in files:
            try:
                doc = load_file(f)
            except RefusedPickle as exc:
                raise BadInput(f"{exc}; nothing written") from None
            if not isinstance(doc, dict):
                raise BadInput(f"{f}: expected a dict of videos, got {type(doc).__name__}; "
                               "nothing written")
            set_id = f.stem.split("_")[-1]
            for video, items in doc.items():
                key = video_key(set_id, str(video))
                self.poses[key] = _video_poses(f, video, items)
                self.all_zero += sum(not a.any() for a in self.poses[key].values())

    def has_video(self, video: str) -> bool:
        return video in self.poses

    def _unit(self, video: str, size: tuple) -> str:
        """``normalised`` or ``pixels`` for ``video`` (decided once, with its warning)."""
        if video not in self.units:
            values = np.array(list(self.poses.get(video, {}).values())).reshape(-1, 2)
            nonzero = values[values.any(1)]
            over = int((nonzero > 1).sum())
            unit = "pixels" if over > nonzero.size / 2 else "normalised"
            outside = (over if unit == "normalised" else
                       int((nonzero > np.array(size, np.float64)).sum()))
            outside += int((nonzero < 0).sum())
            if outside:
                self.warnings.append(
                    f"{self.name}: video {video!r}: read as {unit} coordinates; {outside} of "
                    f"{nonzero.size} coordinates lie outside the image (kept as they are)")
            self.units[video] = unit
        return self.units[video]

    def poses_for(self, video: str, requests: list, size: tuple) -> list:
        """``requests``: ``[(frame, pid)]`` -> per request ``(points, conf)`` or None."""
        table = self.poses.get(video, {})
        scale = np.array(size, np.float64) if self._unit(video, size) == "normalised" else 1.0
        out = []
        for frame, pid in requests:
            a = table.get((frame, pid))
            out.append(None if a is None else _body25(np.where(a == 0, 0.0, a * scale),
                                                      self.derive))
        return out


def _video_poses(f, video, items) -> dict:
    """``{(frame, pid): (18, 2)}`` of one video of the pickle ``f``."""
    if not isinstance(items, dict):
        raise BadInput(f"{f}: video {video!r}: expected a dict of '<frame>_<pid>' keys; "
                       "nothing written")
    table = {}
    for key, value in items.items():
        frame, _, pid = str(key).partition("_")
        try:
            a = np.asarray(value, np.float64).reshape(18, 2)
            frame = int(frame)
        except (TypeError, ValueError):
            raise BadInput(f"{f}: video {video!r} key {key!r}: expected '<frame>_<pid>' -> "
                           "36 numbers; nothing written") from None
        if not np.all(np.isfinite(a)):
            raise BadInput(f"{f}: video {video!r} key {key!r}: non-finite value; "
                           "nothing written")
        table[(frame, pid)] = a
    return table


class OpenPoseFrames:
    """OpenPose ``--write_json`` files below ``folder``: ``VIDEO_<frame>_keypoints.json``
    (BODY_25, every person of the frame). ``video_key(set, video)`` names the video as the
    annotations do; ``set`` is a ``setNN_`` prefix of the name or the nearest ``setNN``
    folder (PIE), else None."""

    def __init__(self, folder, video_key):
        folder = Path(folder)
        if not folder.is_dir():
            raise BadInput(f"{folder}: not a folder of OpenPose *_keypoints.json files; "
                           "nothing written")
        self.files, self.name, self.body25 = {}, str(folder), set(range(25))
        for path in sorted(folder.rglob("*_keypoints.json")):
            m = _OPENPOSE_NAME.match(path.name)
            if m is None:
                continue
            video, set_id = m.group("video"), None
            pre = re.match(r"^(set\d+)_(.+)$", video)
            if pre:
                set_id, video = pre.groups()
            else:
                set_id = next((p.name for p in path.relative_to(folder).parents
                               if _SET.match(p.name)), None)
            self.files[(video_key(set_id, video), int(m.group("frame")))] = path
        if not self.files:
            raise BadInput(f"{folder}: no *_keypoints.json file in it; nothing written")
        self.videos = {v for v, _ in self.files}

    def has_video(self, video: str) -> bool:
        return video in self.videos

    def people(self, video: str, frame: int) -> list:
        path = self.files.get((video, frame))
        if path is None:
            return []
        doc = load_json(path)
        people = doc.get("people") if isinstance(doc, dict) else None
        if not isinstance(people, list):
            raise BadInput(f"{path}: no 'people' list; nothing written")
        out = []
        for k, person in enumerate(people):
            kp = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
            try:
                a = np.asarray(kp, np.float64).reshape(25, 3)
            except (TypeError, ValueError):
                raise BadInput(f"{path}: people[{k}]: pose_keypoints_2d must hold 75 numbers "
                               "(BODY_25); nothing written") from None
            if not np.all(np.isfinite(a)):
                raise BadInput(f"{path}: people[{k}]: non-finite value; nothing written")
            out.append((a[:, :2], a[:, 2]))
        return out


def fit(box, points, conf) -> tuple:
    """How well a pose fits an annotated box: (share of its detected joints inside the box
    grown by 10 % on each side, IoU of the joints' box with it)."""
    seen = conf > 0
    if not seen.any():
        return 0.0, 0.0
    x1, y1, x2, y2 = box
    mx, my = 0.1 * (x2 - x1), 0.1 * (y2 - y1)
    p = points[seen]
    inside = ((p[:, 0] >= x1 - mx) & (p[:, 0] <= x2 + mx)
              & (p[:, 1] >= y1 - my) & (p[:, 1] <= y2 + my))
    (a1, b1), (a2, b2) = p.min(0), p.max(0)
    inter = max(0.0, min(x2, a2) - max(x1, a1)) * max(0.0, min(y2, b2) - max(y1, b1))
    union = (x2 - x1) * (y2 - y1) + (a2 - a1) * (b2 - b1) - inter
    return float(inside.mean()), float(inter / union) if union > 0 else 0.0


def match_people(boxes: list, people: list, min_fit: float = 0.5) -> list:
    """Greedy one-to-one: each annotated box (best fits first) gets the OpenPose person
    whose detected joints lie inside it the most (IoU breaks ties), if at least
    ``min_fit`` of them do. Returns per box a person index or None."""
    pairs = []
    for i, b in enumerate(boxes):
        for j, (pts, conf) in enumerate(people):
            share, iou = fit(b, pts, conf)
            if share >= min_fit:
                pairs.append((share, iou, -i, -j))
    out, taken = [None] * len(boxes), set()
    for share, iou, i, j in sorted(pairs, reverse=True):
        if out[-i] is None and -j not in taken:
            out[-i], _ = -j, taken.add(-j)
    return out


# --------------------------------------------------------------------------- import
def _join_poses(tracks: list, windows: list, obs: int, source, sizes: dict) -> tuple:
    """``({(track id, position): (points, conf)}, frames_without_pose)``: BODY_25 poses of
    every position the windows use (zeros where none matches)."""
    by_frame: dict = {}
    for t in tracks:
        for k, fr in enumerate(t.frames):
            by_frame.setdefault((t.video, fr), []).append((t, k))
    wanted = {(id(w.track), w.first + k) for w in windows for k in range(obs)}
    needed = sorted({(w.track.video, w.track.frames[w.first + k])
                     for w in windows for k in range(obs)})
    out, missing, empty = {}, 0, (np.zeros((25, 2)), np.zeros(25))
    for video, frame in needed:
        entries = by_frame[(video, frame)]
        if isinstance(source, OpenPoseFrames):
            people = source.people(video, frame)
            who = match_people([t.boxes[k] for t, k in entries], people)
            poses = [None if w is None else people[w] for w in who]
        else:
            poses = source.poses_for(video, [(frame, t.pid) for t, _ in entries],
                                     sizes[video])
        for (t, k), pose in zip(entries, poses):
            if (id(t), k) in wanted:
                missing += pose is None
                out[(id(t), k)] = empty if pose is None else pose
    return out, missing


def _windows(tracks: list, obs: int, tte: tuple, stride: int, cut_gaps: bool) -> tuple:
    """``(windows, pedestrians kept, pedestrians too short)`` of the imported tracks."""
    windows, kept, short = [], 0, 0
    for t in tracks:
        if not t.use:
            continue
        ws = track_windows(t, obs, tte, stride, cut_gaps)
        if ws is None:
            short += 1
        else:
            kept += 1
            windows += ws
    return windows, kept, short


def import_tracks(tracks: list, out, *, dataset: str, source, sizes: dict, root,
                  obs_length: int = 16, tte=(30, 60), overlap: float = 0.6,
                  threshold: float = 0.3, derive: bool = True, cut_gaps: bool = False,
                  drop_first: bool = False, seed=None, val_frac=None, test_frac=None,
                  force: bool = False, settings: dict | None = None) -> dict:
    """Cuts ``tracks`` as the benchmark does (:mod:`.benchmark_windows`), joins the poses
    of ``source`` (:class:`OpenPoseFrames` or :class:`PickledPoses`) and writes the clip
    file ``out``; returns the report."""
    tte, stride = check_options(obs_length, tte, overlap, threshold)
    windows, kept, short = _windows(tracks, obs_length, tte, stride, cut_gaps)
    if not windows:
        raise BadInput(f"{root}: no pedestrian track has the {obs_length + tte[1]} frames "
                       "up to its event that a window needs; nothing written")
    for video in sorted({w.track.video for w in windows}):
        if not source.has_video(video):
            raise BadInput(f"{source.name}: no poses for video {video!r} "
                           f"({_source_name(source)}); nothing written")
    raw, no_pose = _join_poses(tracks, windows, obs_length, source, sizes)
    keys = list(raw)
    m, uv, visible, conf, _ = map_joints("body25", np.array([raw[k][0] for k in keys]),
                                         np.array([raw[k][1] for k in keys]), threshold,
                                         derive)
    poses = {k: (uv[i], visible[i], conf[i]) for i, k in enumerate(keys)}
    split, info = _split(windows, seed, val_frac, test_frac)
    names = joint_set("body25").joints  # CARLA joints whose BODY_25 sources the poses have
    filled = m.present & np.array([all(names.index(n) in source.body25 for n in src)
                                   for _, _, src in m.describe()])
    info.update(dataset=dataset, obs_length=obs_length, time_to_event=list(tte),
                overlap=float(overlap), stride=stride, windows_across_gaps=not cut_gaps,
                first_frame_dropped=bool(drop_first), threshold=float(threshold),
                derive=bool(derive), root=str(root), **(settings or {}))
    with atomic_output(out, force=force) as tmp:
        counts = write_windows(tmp, windows, split, poses, sizes, obs=obs_length,
                               drop_first=drop_first,
                               attrs=_attributes(info, filled, stride, obs_length + tte[1]))
    return _report(out, windows, split, counts, info, (kept, short, no_pose), poses, source,
                   filled)


def _split(windows: list, seed, val_frac, test_frac) -> tuple:
    """Per window its split (the dataset's own where the tracks have one, else seeded
    by video) and the settings that say which."""
    if all(w.track.split is not None for w in windows):
        return [w.track.split for w in windows], dict(split_rule="fixed")
    opts = clip_settings(**{k: v for k, v in dict(seed=seed, val_frac=val_frac,
                                                  test_frac=test_frac).items()
                            if v is not None})
    rule = dict(seed=opts["seed"], val_frac=float(opts["val_frac"]),
                test_frac=float(opts["test_frac"]))
    return seeded_split(windows, **rule), dict(split_rule="seeded by video", **rule)


def _attributes(info: dict, filled, stride: int, min_length: int) -> dict:
    """The root attributes: bsp-convert's names where they mean the same (``benchmark``
    1, ``label_rule`` video: every window has its pedestrian's label), the benchmark's
    settings, and ``settings_json`` holding the same values."""
    settings = dict(info, benchmark=True, label="video", clip_length=info["obs_length"]
                    - int(info["first_frame_dropped"]), clip_offset=stride,
                    eval_clip_offset=stride, min_video_length=min_length,
                    labels=f"{info['dataset']} attributes (crossing)", balance=False,
                    source_joints="body25")
    return dict(clip_stride=stride, eval_clip_stride=stride, min_video_length=min_length,
                label_rule="video", benchmark=1, balance=0,
                val_frac=float(info.get("val_frac", 0.0)),
                test_frac=float(info.get("test_frac", 0.0)), seed=int(info.get("seed", 0)),
                source_path=str(info.get("root", "")), source_format="body25",
                joints_mapped=np.asarray(filled, np.uint8),
                visibility_threshold=info["threshold"], labels_source=settings["labels"],
                dataset=info["dataset"], split_rule=info["split_rule"],
                obs_length=info["obs_length"],
                time_to_event=np.asarray(info["time_to_event"], np.int64),
                overlap=info["overlap"], pose_source=info.get("poses", ""),
                windows_across_gaps=int(info["windows_across_gaps"]),
                first_frame_dropped=int(info["first_frame_dropped"]),
                settings_json=json.dumps(settings, sort_keys=True))


def _report(out, windows, split, counts, info, numbers, poses, source, filled) -> dict:
    """The import's report: counts per split, the TTE ranges, the windows across gaps,
    the poses' notes, the missing joints per split (``--stats``)."""
    obs, skip = info["obs_length"], int(info["first_frame_dropped"])
    gaps = [w for w in windows
            if w.track.frames[w.first + obs - 1] - w.track.frames[w.first] != obs - 1]
    missing = {s: [0, 0] for s in SPLITS}
    for w, s in zip(windows, split):
        for k in range(w.first + skip, w.first + obs):
            vis = poses[(id(w.track), k)][1][filled]
            missing[s][0] += int(vis.size - vis.sum())
            missing[s][1] += int(vis.size)
    kept, short, no_pose = numbers
    return dict(output=str(out), rows=len(poses), tracks=kept, short_tracks=short,
                clips={s: n for s, (n, _) in counts.items()},
                class_counts={s: c for s, (_, c) in counts.items()},
                tte_range=(min(w.tte for w in windows), max(w.tte for w in windows)),
                frames_to_event_range=(min(w.frames_to_event for w in windows),
                                       max(w.frames_to_event for w in windows)),
                windows_across_gaps=len(gaps),
                pedestrians_with_gaps=sorted({f"{w.track.video}/{w.track.pid}" for w in gaps}),
                frames_without_pose=no_pose, all_zero_poses=getattr(source, "all_zero", 0),
                warnings=list(getattr(source, "warnings", [])),
                missing_joints={s: tuple(v) for s, v in missing.items()},
                joints=[n for n, f in zip(CARLA.joints, filled) if f], settings=info,
                skipped=[])


def _source_name(source) -> str:
    if isinstance(source, OpenPoseFrames):
        return "no VIDEO_<frame>_keypoints.json file of it"
    return "not a video of the pose pickle"


def stats_lines(report: dict) -> list:
    """``--stats``: the share of missing joints over the imported windows (the CARLA
    joints the pose source fills, every frame of every clip), per split and in all."""
    miss = report["missing_joints"]
    total = [sum(v[i] for v in miss.values()) for i in (0, 1)]
    share = lambda m, n: f"{100.0 * m / n:.2f} %" if n else "n/a"  # noqa: E731
    n_joints = len(report["joints"])
    lines = [f"missing joints over the imported windows: {share(*total)} "
             f"({total[0]} of {total[1]} joint-frames; the {n_joints} of "
             f"{len(CARLA.joints)} CARLA joints the poses fill)"]
    lines += [f"  {s}: {share(*miss[s])}" for s in SPLITS]
    lines.append(f"  annotated frames without a matching pose: "
                 f"{report['frames_without_pose']}")
    return lines
