"""Clip files -> other tools' formats, through a skeleton map of the user's choice.

* :func:`export_videopose3d`: the ``data_2d_custom_NAME.npz`` that VideoPose3D's
  ``run.py -d custom -k NAME`` loads (``common/custom_dataset.py``): ``positions_2d
  [subject]["custom"] = [array (T, J, 2) float32]``, one subject per (video, track) run of
  consecutive frames, and ``metadata`` (``layout_name`` ``coco``/``h36m``, ``num_joints``,
  ``keypoints_symmetry``, ``video_metadata[subject] = {w, h}``). No NaN: a joint missing
  in some frames is filled by linear interpolation over the run (``np.interp``, as
  VideoPose3D's ``prepare_data_2d_custom.py`` fills missing frames), joints no CARLA joint
  fills are approximated from their neighbours (:data:`FILLED_JOINTS`), and a run in
  which a joint is never seen is left out (listed). Optionally the 3D joints, H36M-17 in
  metres, ``positions_3d[subject]["custom"] = array (T, 17, 3)`` (the dataset class of
  docs/interop.md reads them).
* :func:`export_coco`: COCO keypoint **annotations** (``info``, ``licenses``, ``images``,
  ``annotations`` with ``v`` = 2 / 0, ``categories`` with COCO's 19-edge skeleton; for
  MMPose-style training) or keypoint **results** (a list of ``{image_id, category_id,
  keypoints, score, track_id}`` plus the images JSON), one image per (video, frame) and
  one record per (video, track, frame): frames shared by overlapping clips are written
  once. ``images_dir``: the frames as the JPEGs ``file_name`` names, from the clip file's
  media crops.
"""
from __future__ import annotations

import contextlib
import json

from pathlib import Path, PurePosixPath

import numpy as np

from ..atomic import atomic_output
from ..conversion.vds import open_clip_file
from ..skeleton import CARLA, joint_set, skeleton_map
from .readers import BadInput, option

__all__ = ["read_clips", "export_videopose3d", "export_coco", "ground_frame", "FRAMES_3D",
           "SPLIT_CHOICES",
           "FILLED_JOINTS", "COCO_SKELETON", "VIDEOPOSE3D_LAYOUTS"]

SPLIT_CHOICES = ("train", "val", "test", "all")
FRAMES_3D = ("camera", "world", "absolute", "ground")

#: VideoPose3D's names of our joint sets (``data/data_utils.py``: ``coco_metadata``,
#: ``h36m_metadata``; its visualisation tests ``layout_name != 'coco'``)
VIDEOPOSE3D_LAYOUTS = {"coco17": "coco", "h36m17": "h36m"}

#: joints that no CARLA joint fills, approximated for VideoPose3D (which takes no NaN):
#: ``joint: [(source joint, weight), ...]`` (a weighted sum of points, 2D and 3D alike)
FILLED_JOINTS = {
    "coco17": {"left_ear": [("left_eye", 2.0), ("nose", -1.0)],      # eye + (eye - nose)
               "right_ear": [("right_eye", 2.0), ("nose", -1.0)]},
    "h36m17": {"spine": [("pelvis", 0.5), ("thorax", 0.5)],          # mid(pelvis, thorax)
               "head": [("neck_nose", 2.0), ("thorax", -1.0)]},      # nose + (nose - thorax)
}

#: the COCO person category's skeleton: 19 edges, 1-based keypoint numbers
COCO_SKELETON = [[16, 14], [14, 12], [17, 15], [15, 13], [12, 13], [6, 12], [7, 13],
                 [6, 7], [6, 8], [7, 9], [8, 10], [9, 11], [2, 3], [1, 2], [1, 3],
                 [2, 4], [3, 5], [4, 6], [5, 7]]


def _splits(split: str) -> tuple:
    if split not in SPLIT_CHOICES:
        raise ValueError(f"split must be one of {list(SPLIT_CHOICES)}, got {split!r}")
    return ("train", "val", "test") if split == "all" else (split,)


def read_clips(h5_path, split: str = "all", frame_3d: str | None = None) -> dict:
    """The 2D clips of a clip file (bsp-convert's or an import's) per split:
    ``{split: {uv (N, L, 26, 2), present (N, L, 26), frames (N, L), video, track (lists),
    start (N,), width, height (N,), xyz (N, L, 26, 3) with frame_3d}}``. ``present`` is
    the file's ``visible`` where it has one, else ``uv != (0, 0)``."""
    if frame_3d is not None and frame_3d not in FRAMES_3D:
        raise ValueError(f"frame_3d must be one of {list(FRAMES_3D)}, got {frame_3d!r}")
    out = {}
    with open_clip_file(h5_path) as f:
        if int(f.attrs.get("schema_version", -1)) != 1:
            raise BadInput(f"{h5_path}: not a schema_version 1 clip file")
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f.attrs["joint_names"]]
        if tuple(names) != CARLA.joints:
            raise BadInput(f"{h5_path}: joint_names are not the CARLA-26 skeleton")
        for s in _splits(split):
            g = f[s]
            uv = g["projection_2d"][()]
            present = (g["visible"][()] != 0 if "visible" in g
                       else (uv[..., 0] != 0) | (uv[..., 1] != 0))
            d = dict(uv=uv, present=present, frames=g["targets/frame_idx"][()],
                     video=list(g["meta/video_id"].asstr()[()]),
                     track=list(g["meta/pedestrian_id"].asstr()[()]),
                     start=g["meta/start_frame"][()], width=g["meta/clip_width"][()],
                     height=g["meta/clip_height"][()])
            if "clip_frames" in g and "frames/rgb" in g:
                d["clip_frames"] = g["clip_frames"][()]
            if "targets/is_crossing" in g:
                d["crossing"] = g["targets/is_crossing"][()]
            if frame_3d is not None:
                d["xyz"] = _points_3d(g, frame_3d, h5_path)
            if frame_3d == "ground":
                d["camera"] = g["meta/camera_transform"][()].astype(np.float64)
            out[s] = d
    return out


def _points_3d(g, frame: str, h5_path) -> np.ndarray:
    from ..data.camera import carla_to_opencv
    from ..geometry import invert, transform_points

    name = "targets/absolute_pose_loc" if frame == "absolute" else "targets/world_pose_loc"
    if name not in g or (frame in ("camera", "ground") and "meta/camera_transform" not in g):
        raise BadInput(f"{h5_path}: /{g.name.strip('/')} has no {name} (3D targets): a 2D-only "
                       "file (e.g. imported detections) has no 3D to export; leave out "
                       + option("out_3d", "--out-3d") + " to export the 2D only; nothing "
                       "written")
    xyz = g[name][()].astype(np.float64)
    if frame == "camera":  # metres, OpenCV axes (x right, y down, z forward)
        cam = invert(g["meta/camera_transform"][()].astype(np.float64))
        xyz = carla_to_opencv(transform_points(cam[:, None, None, :], xyz))
    return xyz.astype(np.float32)


def _fill_rules(dst, m) -> dict:
    """``{joint index: [(source index, weight)]}`` for the joints of ``dst`` that the map
    ``m`` (CARLA -> dst) leaves missing and :data:`FILLED_JOINTS` approximates."""
    rules = FILLED_JOINTS.get(dst.name, {})
    return {dst.index(j): [(dst.index(s), w) for s, w in rule]
            for j, rule in rules.items() if not m.present[dst.index(j)]}


def _apply_fills(pts: np.ndarray, ok: np.ndarray, rules: dict) -> None:
    """In place: each filled joint from its sources, present where all of them are."""
    for j, rule in rules.items():
        pts[..., j, :] = sum(w * pts[..., s, :] for s, w in rule)
        ok[..., j] = np.logical_and.reduce([ok[..., s] for s, _ in rule])


def _interpolate(pts: np.ndarray, ok: np.ndarray) -> tuple:
    """``pts (T, J, D)`` with the joints missing in some frames (``ok`` False) filled by
    linear interpolation over the frames (``np.interp``: the first/last seen value before
    the first / after the last sighting), as VideoPose3D's prepare_data_2d_custom.py fills
    missing frames. Returns the filled array, the filled count and the joints never seen."""
    out = pts.astype(np.float64).copy()
    never = [j for j in range(pts.shape[1]) if not ok[:, j].any()]
    t = np.arange(len(pts))
    filled = 0
    for j in range(pts.shape[1]):
        miss = ~ok[:, j]
        if j in never or not miss.any():
            continue
        filled += int(miss.sum())
        for d in range(pts.shape[2]):
            out[miss, j, d] = np.interp(t[miss], t[~miss], out[~miss, j, d])
    return out, filled, never


def _runs(data: dict, with_3d: bool) -> list:
    """One entry per (split, video, track) run of consecutive frames, frames shared by
    overlapping clips taken once: ``dict(split, video, track, frames (T,), uv (T, 26, 2),
    present (T, 26), w, h[, xyz (T, 26, 3)])``, sorted by split, video, track, frame."""
    rows: dict = {}
    for s, c in data.items():
        for i in range(len(c["uv"])):
            key = (s, c["video"][i], c["track"][i])
            per = rows.setdefault(key, {"w": int(c["width"][i]), "h": int(c["height"][i]),
                                        "frames": {}})
            for k in range(c["uv"].shape[1]):
                per["frames"].setdefault(int(c["frames"][i, k]), (c, i, k))
    out = []
    order = {s: n for n, s in enumerate(SPLIT_CHOICES)}
    for (s, video, track) in sorted(rows, key=lambda k: (order[k[0]], k[1], k[2])):
        per = rows[(s, video, track)]
        frames = np.array(sorted(per["frames"]), np.int64)
        cuts = np.flatnonzero(np.diff(frames) != 1) + 1
        for part in np.split(frames, cuts):
            src = [per["frames"][int(f)] for f in part]
            run = dict(split=s, video=video, track=track, frames=part, w=per["w"], h=per["h"],
                       uv=np.stack([c["uv"][i, k] for c, i, k in src]),
                       present=np.stack([c["present"][i, k] for c, i, k in src]))
            if with_3d:
                run["xyz"] = np.stack([c["xyz"][i, k] for c, i, k in src])
                if "camera" in src[0][0]:
                    run["camera"] = src[0][0]["camera"][src[0][1]]
            out.append(run)
    return out


def _quaternion(R: np.ndarray) -> np.ndarray:
    """A rotation matrix as VideoPose3D's quaternion (w, x, y, z; its ``common/
    quaternion.py`` ``qrot``)."""
    w = np.sqrt(max(1.0 + R[0, 0] + R[1, 1] + R[2, 2], 0.0)) / 2
    if w > 1e-6:
        return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                         (R[1, 0] - R[0, 1]) / (4 * w)])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    v = np.zeros(4)
    v[1 + i] = np.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 0.0)) / 2
    v[0] = (R[k, j] - R[j, k]) / (4 * v[1 + i])
    v[1 + j] = (R[j, i] + R[i, j]) / (4 * v[1 + i])
    v[1 + k] = (R[k, i] + R[i, k]) / (4 * v[1 + i])
    return v


def ground_frame(world: np.ndarray, camera) -> tuple:
    """CARLA world points ``(..., 3)`` of one subject -> the **ground frame** of its
    camera: right-handed, z up, y the camera's heading on the ground, x to its right,
    origin on the ground under the camera (the ground: the subject's lowest joint). Also
    the camera there, as VideoPose3D's ``camera_to_world`` takes it: ``(points,
    orientation (w, x, y, z), translation)``; its ``world_to_camera`` of the points gives
    the camera frame (OpenCV axes) of ``--frame camera``."""
    from ..data.camera import opencv_to_carla
    from ..geometry import transform_points

    camera = np.asarray(camera, np.float64)
    yaw = np.radians(camera[4])
    heading, right = np.array([np.cos(yaw), np.sin(yaw), 0.0]), \
        np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    ground = float(world[..., 2].min())

    def to_ground(w):
        d = w - np.array([camera[0], camera[1], 0.0])
        return np.stack([d @ right, d @ heading, w[..., 2] - ground], -1)

    axes = transform_points(camera, opencv_to_carla(np.vstack([np.zeros(3), np.eye(3)])))
    at = to_ground(axes)
    return to_ground(world), _quaternion((at[1:] - at[0]).T), at[0]


def _viewer_run(uv, xyz, r: dict) -> tuple:
    """``--viewer``: a run padded to start at its video's frame 0 (the first pose held over
    the frames before it, as VideoPose3D pads at the edges), so that the pose of video
    frame ``n`` is row ``n``: what run.py's render (``--viz-video``, ``--viz-skip``)
    pairs with the video's frames."""
    pad = int(r["frames"][0])
    hold = lambda a: None if a is None else np.concatenate([np.repeat(a[:1], pad, 0), a])  # noqa: E731
    return hold(uv), hold(xyz), pad


def _subject_names(runs: list) -> list:
    """``VIDEO/TRACK``; ``VIDEO/TRACK@FIRST_FRAME`` where a track has several runs (gaps
    in its frames), ``VIDEO/TRACK@SPLIT@FIRST_FRAME`` where that is not yet unique (one
    video name in two splits); commas (run.py splits --subjects-train at them) become
    ``_``."""
    def forms(r):
        base = f"{r['video']}/{r['track']}".replace(",", "_")
        first = int(r["frames"][0])
        return (base, f"{base}@{first}", f"{base}@{r['split']}@{first}")

    level: dict = {}
    for depth in range(3):
        seen: dict = {}
        for k, r in enumerate(runs):
            if level.get(k, 0) == depth:
                seen.setdefault(forms(r)[depth], []).append(k)
        for ks in seen.values():
            if len(ks) > 1:
                for k in ks:
                    level[k] = depth + 1
    if any(v > 2 for v in level.values()):
        raise BadInput("two runs get the same VideoPose3D subject name (video or track names "
                       "that differ only by a comma); rename them")
    return [forms(r)[level.get(k, 0)] for k, r in enumerate(runs)]


def _h36m_3d(r: dict, frame_3d: str, m3, rules3: dict, cameras: dict, name: str):
    """A run's ground-truth 3D joints as H36M-17 in ``frame_3d`` (every joint is known,
    seen or not); in the ground frame its camera goes into ``cameras[name]``."""
    world = r["xyz"].astype(np.float64)
    if frame_3d == "ground":
        world, q, t = ground_frame(world, r["camera"])
        cameras[name] = {"orientation": q.astype(np.float32).tolist(),
                         "translation": t.astype(np.float32).tolist()}
    xyz, ok3 = m3.apply(world, fill=np.nan)
    _apply_fills(xyz, ok3, rules3)
    return xyz


def _joints_2d(r: dict, m, rules: dict) -> tuple:
    """``(uv, interpolated, never)``: a run's 2D joints in the target set, filled by the
    rules and interpolated over time; ``never``: joints missing in every frame."""
    uv, ok = m.apply(r["uv"].astype(np.float64), r["present"], fill=np.nan)
    _apply_fills(uv, ok, rules)
    return _interpolate(uv, ok)


def _fill_text(js, rules: dict) -> dict:
    """``{joint: "0.5*a + 0.5*b"}``: how each filled joint of set ``js`` was made."""
    return {js.joints[j]: " + ".join(f"{w:g}*{js.joints[s]}" for s, w in rule)
            for j, rule in rules.items()}


def export_videopose3d(h5_path, out_2d, out_3d=None, *, joints="coco17", split: str = "all",
                       frame_3d: str | None = None, viewer: bool = False, derive: bool = True,
                       force: bool = False) -> dict:
    """Writes ``out_2d``, the ``data_2d_custom_NAME.npz`` of VideoPose3D's ``run.py -d
    custom -k NAME``, with the 2D ``joints`` set (``coco17``, what its in-the-wild models
    take; ``h36m17``; others keep our layout name), and ``out_3d`` (H36M-17, metres, in
    ``frame_3d`` = ``camera`` (OpenCV axes, what VideoPose3D trains on; the default),
    ``world``, ``absolute`` (the walker's frame) or ``ground`` (:func:`ground_frame`, with
    each subject's camera in the 3D metadata)). ``viewer``: what VideoPose3D's render
    expects: every subject starts at its video's frame 0 (:func:`_viewer_run`) and the 3D
    is in the ground frame. Module docstring: subjects, filling, no NaN. Returns counts,
    the subjects per split and the runs left out."""
    frame_3d = _frame_3d(frame_3d, viewer)
    dst = joint_set(joints)
    m = skeleton_map(CARLA, dst, derive)
    rules = _fill_rules(dst, m)
    data = read_clips(h5_path, split, frame_3d if out_3d is not None else None)
    runs = _runs(data, out_3d is not None)
    if not runs:
        raise BadInput(f"{h5_path}: no clip in split {split!r}; nothing to export")
    h36m = joint_set("h36m17")
    m3 = skeleton_map(CARLA, h36m, derive)
    rules3 = _fill_rules(h36m, m3)
    pos2d, pos3d, video_meta, source, cameras = {}, {}, {}, {}, {}
    subjects = {s: [] for s in data}
    dropped, filled = [], 0
    for name, r in zip(_subject_names(runs), runs):
        uv, n, never = _joints_2d(r, m, rules)
        if never:
            dropped.append(f"{name} ({r['split']}, frames {int(r['frames'][0])}-"
                           f"{int(r['frames'][-1])}): never sees "
                           + ", ".join(dst.joints[j] for j in never))
            continue
        filled += n
        xyz = None if out_3d is None else _h36m_3d(r, frame_3d, m3, rules3, cameras, name)
        uv, xyz, pad = _viewer_run(uv, xyz, r) if viewer else (uv, xyz, 0)
        pos2d[name] = {"custom": [uv.astype(np.float32)]}
        video_meta[name] = {"w": int(r["w"]), "h": int(r["h"])}
        subjects[r["split"]].append(name)
        source[name] = _source(r, pad)
        if xyz is not None:
            pos3d[name] = {"custom": xyz.astype(np.float32)}
    if not pos2d:
        raise BadInput(f"{h5_path}: every run misses a joint in all its frames ("
                       + "; ".join(dropped[:3]) + "); nothing written")
    fills = _fill_text(dst, rules)
    metadata = {"layout_name": VIDEOPOSE3D_LAYOUTS.get(dst.name, dst.name),
                "num_joints": len(dst), "keypoints_symmetry": [list(dst.left), list(dst.right)],
                "video_metadata": video_meta, "joint_names": list(dst.joints),
                "subjects": subjects, "source": source, "filled_joints": fills,
                "interpolated_joints": filled}
    targets = [(out_2d, dict(positions_2d=pos2d, metadata=metadata), _save_npz)]
    if out_3d is not None:
        targets.append((out_3d, _archive_3d(pos3d, cameras, frame_3d, h36m, rules3), _save_npz))
    _save_all(targets, force)
    return {"subjects": {s: len(v) for s, v in subjects.items()}, "joints": dst.name,
            "layout_name": metadata["layout_name"], "subject_names": subjects,
            "num_joints": len(dst),
            "dropped": dropped, "interpolated": filled, "filled_joints": fills,
            "present": [n for n, p in zip(dst.joints, m.present) if p]}


def _frame_3d(frame_3d: str | None, viewer: bool) -> str:
    """The 3D frame asked for, or the default: ``ground`` for the viewer, else ``camera``
    (the viewer's 3D is always in the ground frame)."""
    if viewer and frame_3d not in (None, "ground"):
        raise ValueError(f"the viewer export writes its 3D in the ground frame (z up), not "
                         f"{frame_3d!r}: leave out {option('frame_3d', '--frame')} or give "
                         "ground")
    return frame_3d or ("ground" if viewer else "camera")


def _source(r: dict, pad: int) -> dict:
    """Where a subject comes from: split, video, track and its frames (end exclusive)."""
    return {"split": r["split"], "video": r["video"], "track": r["track"],
            "start_frame": int(r["frames"][0]), "end_frame": int(r["frames"][-1]) + 1,
            "padded_frames": pad}


def _archive_3d(pos3d: dict, cameras: dict, frame_3d: str, h36m, rules3: dict) -> dict:
    """The 3D archive's arrays: H36M-17 positions in metres and their metadata."""
    meta3 = {"layout_name": "h36m", "num_joints": len(h36m), "cameras": cameras,
             "joint_names": list(h36m.joints), "units": "metres", "frame": frame_3d,
             "filled_joints": _fill_text(h36m, rules3)}
    return dict(positions_3d=pos3d, metadata=meta3)


def _save_npz(path, arrays: dict) -> None:
    with open(path, "wb") as fh:  # a file object: np.savez adds no ".npz" to it
        np.savez_compressed(fh, **{k: np.array(v, dtype=object) for k, v in arrays.items()})


def _save_all(targets: list, force: bool) -> None:
    """Writes every ``(path, payload, save[, folder])`` under temporary names, then
    publishes them: an error in any leaves none of them behind."""
    with contextlib.ExitStack() as stack:
        for path, payload, save, *folder in targets:
            tmp = stack.enter_context(atomic_output(path, force=force,
                                                    folder=bool(folder and folder[0])))
            save(tmp, payload)


def _frames(data: dict) -> tuple:
    """Unique (video, track, frame) rows across clips and splits, with their points, the
    image size, where the media crop is (``(split, frame-table row)`` or None), the split
    and the frame's crossing label (None where the file has none)."""
    rows = {}
    for s, c in data.items():
        media, crossing = c.get("clip_frames"), c.get("crossing")
        for i in range(len(c["uv"])):
            for k in range(c["uv"].shape[1]):
                key = (c["video"][i], c["track"][i], int(c["frames"][i, k]))
                rows.setdefault(key, (c["uv"][i, k], c["present"][i, k], int(c["width"][i]),
                                      int(c["height"][i]),
                                      None if media is None else (s, int(media[i, k])), s,
                                      None if crossing is None else int(crossing[i, k])))
    keys = sorted(rows)
    return keys, [rows[k] for k in keys]


def _track_ids(keys: list) -> dict:
    """(video, track) -> an integer track_id: the track name where every name is an
    integer, else a number per (video, track) in sorted order (the name kept as
    ``track_name``)."""
    pairs = sorted({(v, t) for v, t, _ in keys})
    if all(t.lstrip("-").isdigit() for _, t in pairs):
        return {p: int(p[1]) for p in pairs}
    return {p: n for n, p in enumerate(pairs)}


def _image_name(video: str, frame: int) -> str:
    p = PurePosixPath(video)
    if not video or p.is_absolute() or ".." in p.parts or "\\" in video:
        raise BadInput(f"video {video!r} cannot name an image folder (absolute, '..' or a "
                       "backslash); nothing written")
    return f"{video}/{frame:06d}.jpg"


def export_coco(h5_path, out, *, kind: str = "annotations", images_out=None,
                images_dir=None, joints="coco17", split: str = "all", derive: bool = True,
                force: bool = False) -> dict:
    """Writes COCO keypoint ``annotations`` (one JSON) or ``results`` (``out``, and the
    images JSON ``images_out`` that names each image id's video and frame) with the
    ``joints`` set. Missing joints are ``0, 0, 0``. ``images_dir``: also the frames as
    the JPEGs ``file_name`` names (``VIDEO/000042.jpg`` below it): each a black frame of
    the image's size with every track's media crop of that frame pasted where it was cut
    (the clip file keeps crops, not whole frames; a file without media is an error).
    Returns counts."""
    if kind not in ("annotations", "results"):
        raise ValueError(f"kind must be 'annotations' or 'results', got {kind!r}")
    if kind == "results" and images_out is None:
        raise ValueError("results name images by id only: give "
                         + option("images_out", "--images IMAGES.json")
                         + " for the images JSON")
    dst = joint_set(joints)
    m = skeleton_map(CARLA, dst, derive)
    data = read_clips(h5_path, split)
    keys, rows = _frames(data)
    if not keys:
        raise BadInput(f"{h5_path}: no clip in split {split!r}; nothing to export")
    if images_dir is not None and any(r[4] is None for r in rows):
        raise BadInput(f"{h5_path}: no media frames (frames/rgb, clip_frames: a file "
                       "converted by bsp-convert without --no-media) to write the images "
                       f"from; leave out {option('images_dir', '--write-images')}; "
                       "nothing written")
    uv, ok = m.apply(np.stack([r[0] for r in rows]).astype(np.float64),
                     np.stack([r[1] for r in rows]), fill=0.0)
    track_ids = _track_ids(keys)
    masks = _Masks(h5_path) if kind == "annotations" and any(r[4] for r in rows) else None
    images, records = _coco_entries(keys, rows, uv, ok, kind, track_ids, masks,
                                    _one_split(data))
    images_doc = _images_doc(h5_path, images, dst)
    if kind == "annotations":
        targets = [(out, dict(images_doc, annotations=records), _save_json)]
    else:
        targets = [(out, records, _save_json), (images_out, images_doc, _save_json)]
    if masks is not None:
        masks.close()
    if images_dir is not None:
        targets.append((images_dir, (h5_path, images, keys, rows), _save_images, True))
    _save_all(targets, force)
    return {"images": len(images), "records": len(records), "joints": dst.name,
            "present": [n for n, p in zip(dst.joints, m.present) if p],
            "images_written": len(images) if images_dir is not None else 0}


def _one_split(data: dict) -> bool:
    """Whether every video lies in one split (then each image records it)."""
    in_splits: dict = {}
    for s, c in data.items():
        for v in c["video"]:
            in_splits.setdefault(v, set()).add(s)
    return all(len(v) == 1 for v in in_splits.values())


def _coco_entries(keys, rows, uv, ok, kind: str, track_ids: dict, masks,
                  one_split: bool) -> tuple:
    """The COCO ``images`` (one per video frame) and the records (one per track and
    frame: keypoints, track, label; box, area and mask for ``annotations``, a score for
    ``results``)."""
    named = any(str(v) != t for (_, t), v in track_ids.items())
    image_ids: dict = {}
    images, records = [], []
    for n, ((video, track, frame), row) in enumerate(zip(keys, rows)):
        if (video, frame) not in image_ids:
            image_ids[(video, frame)] = len(images) + 1
            images.append({"id": len(images) + 1, "file_name": _image_name(video, frame),
                           "width": row[2], "height": row[3], "video": video, "frame": frame,
                           "license": 1})
            if one_split:  # import coco keeps it
                images[-1]["split"] = row[5]
        keypoints = []
        for (x, y), present in zip(uv[n], ok[n]):  # v = 2 (visible) / score 1.0, or 0, 0, 0
            flag = (2 if kind == "annotations" else 1.0) if present else 0
            keypoints += [float(x), float(y), flag] if present else [0.0, 0.0, flag]
        rec = {"image_id": image_ids[(video, frame)], "category_id": 1,
               "keypoints": keypoints, "track_id": track_ids[(video, track)]}
        if named:
            rec["track_name"] = track
        if row[6] is not None:  # the frame's label: import coco reads it back
            rec["crossing"] = row[6]
        if kind == "annotations":
            rec.update(_box(uv[n], ok[n]), id=n + 1, iscrowd=0, num_keypoints=int(ok[n].sum()))
            if masks is not None and row[4] is not None:
                rec.update(masks.segment(row[4], row[2], row[3]))
        else:
            rec["score"] = 1.0
        records.append(rec)
    return images, records


def _images_doc(h5_path, images: list, dst) -> dict:
    """The COCO document around ``images``: info, license and the person category with
    the ``dst`` joint set's keypoints and skeleton."""
    import datetime

    from .._version import __version__

    skeleton = (COCO_SKELETON if dst.name == "coco17" else
                [[j + 1, p + 1] for j, p in enumerate(dst.parents or ()) if p >= 0])
    category = {"id": 1, "name": "person", "supercategory": "person",
                "keypoints": list(dst.joints), "skeleton": skeleton}
    today = datetime.date.today()
    return {"info": {"description": f"bsp-interop export coco of {h5_path}",
                     "version": "1.0", "year": today.year, "url": "",
                     "contributor": f"bsp_fast {__version__}",
                     "date_created": today.isoformat()},
            "licenses": [{"id": 1, "name": "the source dataset's license", "url": ""}],
            "images": images, "categories": [category]}


class _Masks:
    """COCO ``segmentation`` and ``area`` of a frame from the clip file's media: the
    pedestrian's pixels (``frames/mask`` == 4) of its crop, scaled back to the crop box
    (nearest neighbour) in the whole image, as an uncompressed RLE (column-major runs,
    zeros first: pycocotools' ``frPyObjects`` reads it); the area is the segmentation's
    (COCO's rule), at the crop's resolution."""

    def __init__(self, h5_path):
        import h5py

        self.f = h5py.File(h5_path, "r")

    def close(self) -> None:
        self.f.close()

    def segment(self, where, W: int, H: int) -> dict:
        split, r = where
        g = self.f[split]
        box = g["frames/crop_box"][r].astype(np.float64)
        if "frames/mask" not in g or not np.all(np.isfinite(box)):
            return {"segmentation": _rle(np.zeros((H, 0), bool), H, W, 0), "area": 0.0}
        u0, v0, u1, v1 = (int(round(x)) for x in box)
        crop = g["frames/mask"][r] == 4
        S = crop.shape[0]
        rows = (np.arange(max(v0, 0), min(v1, H)) - v0) * S // max(v1 - v0, 1)
        cols = (np.arange(max(u0, 0), min(u1, W)) - u0) * S // max(u1 - u0, 1)
        block = np.zeros((H, len(cols)), bool)
        block[max(v0, 0):max(v0, 0) + len(rows)] = crop[np.ix_(rows, cols)]
        return {"segmentation": _rle(block, H, W, max(u0, 0)), "area": float(block.sum())}


def _rle(block: np.ndarray, H: int, W: int, col0: int) -> dict:
    """COCO's uncompressed RLE of an ``H x W`` image that is 0 but for ``block (H, c)``
    at columns ``col0 .. col0 + c - 1``."""
    flat = block.ravel(order="F").astype(np.int8)
    before, after = col0 * H, (W - col0 - block.shape[1]) * H
    if flat.size == 0:
        return {"counts": [H * W], "size": [H, W]}
    bounds = np.concatenate([[0], np.flatnonzero(np.diff(flat)) + 1, [flat.size]])
    runs = np.diff(bounds).tolist()
    if flat[0]:
        runs.insert(0, 0)
    runs[0] += before
    if flat[-1]:
        runs.append(after)
    else:
        runs[-1] += after
    return {"counts": [int(n) for n in runs], "size": [int(H), int(W)]}


def _save_images(folder, payload) -> None:
    """Every image of ``images`` as a JPEG under ``folder``: black, with each of its rows'
    media crops resized back to its crop box and pasted there (clipped to the image)."""
    import h5py

    from .._extras import require

    cv2 = require("cv2", "bsp-interop export coco --write-images")
    h5_path, images, keys, rows = payload
    by_image: dict = {}
    for (video, _, frame), row in zip(keys, rows):
        by_image.setdefault((video, frame), []).append(row[4])
    with h5py.File(h5_path, "r") as f:
        for im in images:
            canvas = np.zeros((im["height"], im["width"], 3), np.uint8)
            for split, r in by_image[(im["video"], im["frame"])]:
                g = f[split]
                box = g["frames/crop_box"][r].astype(np.float64)
                if not np.all(np.isfinite(box)):
                    continue  # a fully occluded frame has no crop
                _paste(canvas, g["frames/rgb"][r], box, cv2)
            path = Path(folder) / im["file_name"]
            path.parent.mkdir(parents=True, exist_ok=True)
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(canvas[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, 95])
            if not ok:
                raise OSError(f"{path}: JPEG encoding failed")
            path.write_bytes(buf.tobytes())


def _paste(canvas, crop, box, cv2) -> None:
    u0, v0, u1, v1 = (int(round(x)) for x in box)
    if u1 <= u0 or v1 <= v0:
        return
    big = cv2.resize(crop, (u1 - u0, v1 - v0), interpolation=cv2.INTER_LINEAR)
    H, W = canvas.shape[:2]
    a0, b0, a1, b1 = max(u0, 0), max(v0, 0), min(u1, W), min(v1, H)
    if a1 > a0 and b1 > b0:
        canvas[b0:b1, a0:a1] = big[b0 - v0:b1 - v0, a0 - u0:a1 - u0]


def _box(uv, ok) -> dict:
    if not ok.any():
        return {"bbox": [0.0, 0.0, 0.0, 0.0], "area": 0.0}
    lo, hi = uv[ok].min(0), uv[ok].max(0)
    w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    return {"bbox": [float(lo[0]), float(lo[1]), w, h], "area": w * h}


def _save_json(path, doc) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh)
