"""What the JAAD and PIE importers share (:mod:`.jaad`, :mod:`.pie`): annotated tracks cut
as the PedestrianActionBenchmark cuts them, 2D poses joined to the annotated boxes
(OpenPose JSON or the benchmark's pose pickles), and the clip file.

The benchmark (``action_predict.py``, ``get_data_sequence``): each pedestrian's track is
cut to end at its event frame; windows of ``obs_length`` frames start at positions
``len - obs - tte_max`` ... ``len - obs - tte_min`` every ``max(1, int((1 - overlap) *
obs))`` positions (all splits), so a window's last frame lies ``tte_min`` to ``tte_max``
frames before the event; every window of a track has the track's label (crossing = the
pedestrian crosses at the event). Tracks shorter than ``obs + tte_max`` are left out.
Here the kept frames of each track go through :func:`write_clip_file` (the core's planner
with clip length ``obs`` and that stride, label ``last`` on a constant per-frame label:
the same windows), then the clips are regrouped into the dataset's own split.
"""
from __future__ import annotations

import json
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_output
from ..skeletons import CARLA, joint_set, skeleton_map
from .clipfile import write_clip_file
from .readers import BadInput, Detections, load_json
from .safe_pickle import RefusedPickle, load_file

__all__ = ["Track", "window_stride", "import_tracks",
           "SPLITS", "BENCHMARK"]

SPLITS = ("train", "val", "test")
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
    ``frames`` (None: left out, ``skip`` says why), ``split`` (None: the seeded split),
    ``use`` False for tracks only kept to resolve which pose belongs to whom."""

    video: str
    pid: str
    frames: list
    boxes: list
    label: int
    end: int | None
    split: str | None
    where: str
    use: bool = True
    skip: str = ""


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
    36 values}}``, the 18 COCO-18 joints' (x, y) normalised by the image size (values <= 1;
    pixels where a file holds larger ones), (0, 0) where missing. ``path``: one file or a
    folder of them; ``video_key(set, video)`` names the video as the annotations do."""

    def __init__(self, path, video_key, derive: bool = True):
        path = Path(path)
        files = sorted(path.glob("*.pkl")) if path.is_dir() else [path]
        if not files or not files[0].is_file():
            raise BadInput(f"{path}: no pose pickle (*.pkl) there; nothing written")
        self.poses, self.units, self.derive, self.name = {}, {}, derive, str(path)
        self.body25 = set(COCO18_TO_BODY25) | ({8} if derive else set())
        for f in files:
            try:
                doc = load_file(f)
            except RefusedPickle as exc:
                raise BadInput(f"{exc}; nothing written") from None
            if not isinstance(doc, dict):
                raise BadInput(f"{f}: expected a dict of videos, got {type(doc).__name__}; "
                               "nothing written")
            set_id, top, videos = f.stem.split("_")[-1], 0.0, []
            for video, items in doc.items():
                if not isinstance(items, dict):
                    raise BadInput(f"{f}: video {video!r}: expected a dict of "
                                   "'<frame>_<pid>' keys; nothing written")
                videos.append(video_key(set_id, str(video)))
                table = self.poses.setdefault(videos[-1], {})
                for key, value in items.items():
                    frame, _, pid = str(key).partition("_")
                    try:
                        a = np.asarray(value, np.float64).reshape(18, 2)
                        frame = int(frame)
                    except (TypeError, ValueError):
                        raise BadInput(f"{f}: video {video!r} key {key!r}: expected "
                                       "'<frame>_<pid>' -> 36 numbers; nothing written") from None
                    if not np.all(np.isfinite(a)):
                        raise BadInput(f"{f}: video {video!r} key {key!r}: non-finite value; "
                                       "nothing written")
                    table[(frame, pid)] = a
                    top = max(top, float(a.max(initial=0.0)))
            self.units.update({v: "normalised" if top <= 1.0 else "pixels" for v in videos})

    def has_video(self, video: str) -> bool:
        return video in self.poses

    def poses_for(self, video: str, requests: list, size: tuple) -> list:
        """``requests``: ``[(frame, pid)]`` -> per request ``(points, conf)`` or None."""
        table = self.poses.get(video, {})
        scale = np.array(size, np.float64) if self.units.get(video) == "normalised" else 1.0
        out = []
        for frame, pid in requests:
            a = table.get((frame, pid))
            out.append(None if a is None else _body25(np.where(a == 0, 0.0, a * scale),
                                                      self.derive))
        return out


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
def _kept(track: Track, obs: int, tte: tuple) -> range | None:
    """Positions of ``track`` that the benchmark's windows use (None: too short)."""
    n = track.end + 1  # the sequence ends at the event frame
    if n < obs + tte[1]:
        return None
    return range(n - obs - tte[1], n - tte[0])


def _join_poses(tracks: list, keep: dict, source, sizes: dict) -> tuple:
    """Rows of the kept frames with their poses; ``(rows, frames_without_pose)``."""
    by_frame: dict = {}
    for t in tracks:
        for k, fr in enumerate(t.frames):
            by_frame.setdefault((t.video, fr), []).append((t, k))
    rows, missing = [], 0
    needed = sorted({(t.video, t.frames[k]) for t, ks in keep.items() for k in ks})
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
            if t not in keep or k not in keep[t]:
                continue
            if pose is None:
                missing += 1
                pose = (np.zeros((25, 2)), np.zeros(25))
            rows.append((t, frame, pose))
    return rows, missing


def import_tracks(tracks: list, out, *, dataset: str, source, sizes: dict, root,
                  obs_length: int = 16, tte=(30, 60),
                  overlap: float = 0.6, threshold: float = 0.3, derive: bool = True,
                  seed=None, val_frac=None, test_frac=None, force: bool = False,
                  settings: dict | None = None) -> dict:
    """Cuts ``tracks`` as the benchmark does, joins the poses of ``source``
    (:class:`OpenPoseFrames` or :class:`PickledPoses`) and writes the clip file ``out``."""
    if isinstance(obs_length, bool) or not isinstance(obs_length, int) or obs_length < 1:
        raise ValueError(f"obs_length must be a positive integer, got {obs_length!r}")
    tte = tuple(int(v) for v in tte)
    if len(tte) != 2 or not 0 <= tte[0] <= tte[1]:
        raise ValueError(f"tte must be (min, max) with 0 <= min <= max, got {tte!r}")
    stride = window_stride(overlap, obs_length)
    keep, short, skipped = {}, 0, []
    for t in tracks:
        if not t.use:
            continue
        if t.end is None:
            skipped.append(f"{t.where}: pedestrian {t.pid!r}: {t.skip}")
            continue
        k = _kept(t, obs_length, tte)
        if k is None:
            short += 1
        else:
            keep[t] = set(k)
    if not keep:
        raise BadInput(f"{root}: no pedestrian track has the {obs_length + tte[1]} frames "
                       "before its event that a window needs; nothing written")
    for video in sorted({t.video for t in keep}):
        if not source.has_video(video):
            raise BadInput(f"{source.name}: no poses for video {video!r} "
                           f"({_source_name(source)}); nothing written")
    rows, no_pose = _join_poses(tracks, keep, source, sizes)
    det = Detections(
        joints="body25", video=[t.video for t, _, _ in rows], track=[t.pid for t, _, _ in rows],
        frame=np.array([f for _, f, _ in rows], np.int64),
        points=np.array([p[0] for _, _, p in rows], np.float64).reshape(-1, 25, 2),
        scores=np.array([p[1] for _, _, p in rows], np.float64).reshape(-1, 25),
        width=np.array([sizes[t.video][0] for t, _, _ in rows], np.int64),
        height=np.array([sizes[t.video][1] for t, _, _ in rows], np.int64),
        where=[f"{t.where} pedestrian {t.pid} frame {f}" for t, f, _ in rows], source=str(root))
    labels = {(t.video, t.pid, f): t.label for t, f, _ in rows}
    split_opts = {k: v for k, v in dict(seed=seed, val_frac=val_frac,
                                        test_frac=test_frac).items() if v is not None}
    events = {(t.video, t.pid): t.frames[t.end] for t in keep}
    fixed = {t.video: t.split for t in keep if t.split is not None}
    names = joint_set("body25").joints  # CARLA joints whose BODY_25 sources the poses have
    filled = np.array([kind != "missing" and all(names.index(n) in source.body25 for n in src)
                       for _, kind, src in skeleton_map("body25", CARLA, derive).describe()])
    info = dict(dataset=dataset, obs_length=obs_length, time_to_event=list(tte),
                overlap=float(overlap), stride=stride,
                split_rule="fixed" if fixed else "seeded by video", **(settings or {}))
    with tempfile.TemporaryDirectory(prefix="bsp-interop-") as tmp:
        first = write_clip_file(det, Path(tmp) / "clips.h5", labels=labels, threshold=threshold,
                                derive=derive, skip_short=True, clip_length=obs_length,
                                clip_offset=stride, eval_clip_offset=stride, label="last",
                                **split_opts)
        with atomic_output(out, force=force) as dst:
            report = _regroup(Path(tmp) / "clips.h5", dst, fixed, events, info, filled)
    report.update(output=str(out), rows=first["rows"], tracks=len(keep), short_tracks=short,
                  skipped=skipped + first["skipped"], frames_without_pose=no_pose,
                  joints=[n for n, f in zip(CARLA.joints, filled) if f], settings=info)
    return report


def _source_name(source) -> str:
    if isinstance(source, OpenPoseFrames):
        return "no VIDEO_<frame>_keypoints.json file of it"
    return "not a video of the pose pickle"


def _regroup(src, dst, fixed: dict, events: dict, info: dict, filled) -> dict:
    """Copies the clip file ``src`` to ``dst`` with its clips in the split ``fixed`` gives
    their video (videos not in it keep the seeded split), ordered by (video, track,
    start), plus ``meta/tte`` (frames from a window's last frame to the event) and the
    benchmark's settings as attributes; ``joints_mapped`` only where the poses have the
    joint's sources (``filled``)."""
    import h5py

    with h5py.File(src, "r") as f, h5py.File(dst, "w") as g:
        names = []
        f["train"].visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset)
                              else None)
        text = {n for n in names if h5py.check_string_dtype(f["train"][n].dtype)}
        cat = {n: np.concatenate([f[s][n].asstr()[()] if n in text else f[s][n][()]
                                  for s in SPLITS]) for n in names}
        origin = np.concatenate([[s] * len(f[s]["labels"]) for s in SPLITS]).astype(object)
        video, track = cat["meta/video_id"], cat["meta/pedestrian_id"]
        split = np.array([fixed.get(v, o) for v, o in zip(video, origin)], object)
        # int32 as bsp-convert writes it (docs/hdf5-schema.md, "Time to event")
        cat["meta/tte"] = (np.array([events[(v, t)] for v, t in zip(video, track)], np.int64)
                           - (cat["meta/end_frame"] - 1)).astype(np.int32)
        for k, v in f.attrs.items():
            g.attrs[k] = v
        report = dict(clips={}, class_counts={}, missing_joints={})
        mapped = np.asarray(f.attrs["joints_mapped"], bool) & filled
        for s in SPLITS:
            idx = np.flatnonzero(split == s)
            idx = idx[np.lexsort((cat["meta/start_frame"][idx], track[idx].astype(str),
                                  video[idx].astype(str)))]
            grp = g.create_group(s)
            for n, a in cat.items():
                if n in text:
                    grp.create_dataset(n, data=a[idx].tolist(), dtype=h5py.string_dtype())
                else:
                    grp[n] = a[idx]
            counts = np.bincount(cat["labels"][idx], minlength=2).astype(np.int64)
            grp.attrs["class_counts"] = counts
            grp.attrs["recordings"] = len(set(zip(video[idx], track[idx])))
            g.attrs[f"class_counts_{s}"] = counts
            report["clips"][s], report["class_counts"][s] = int(len(idx)), counts.tolist()
            vis = cat["visible"][idx][..., mapped]
            report["missing_joints"][s] = (int(vis.size - vis.sum()), int(vis.size))
        tte = cat["meta/tte"]
        report["tte_range"] = (int(tte.min()), int(tte.max())) if len(tte) else None
        settings = json.loads(f.attrs["settings_json"])
        settings.update(info, labels=f"{info['dataset']} attributes (crossing)")
        g.attrs.update(dict(benchmark=1, label_rule="video", labels_source=settings["labels"],
                            settings_json=json.dumps(settings, sort_keys=True),
                            dataset=info["dataset"], split_rule=info["split_rule"],
                            time_to_event=np.asarray(info["time_to_event"], np.int64),
                            overlap=info["overlap"], pose_source=info.get("poses", ""),
                            joints_mapped=mapped.astype(np.uint8)))
    return report


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
