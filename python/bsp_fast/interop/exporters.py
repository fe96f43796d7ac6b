"""Clip files -> other tools' formats, through a skeleton map of the user's choice.

* :func:`export_videopose3d`: VideoPose3D's ``.npz`` layout, ``positions_2d[subject][action]
  = [array (L, J, 2)]`` plus ``metadata`` (``layout_name``, ``num_joints``,
  ``keypoints_symmetry``, ``video_metadata``), and optionally ``positions_3d[subject]
  [action] = array (L, J, 3)`` (metres). One action per clip: subject = the split,
  action = ``"<video_id> <pedestrian_id> <start_frame>"``. Missing joints are NaN.
* :func:`export_coco`: COCO keypoint **annotations** (``images``, ``annotations`` with
  ``v`` = 2 / 0, ``categories``; for MMPose-style training) or keypoint **results** (a
  list of ``{image_id, category_id, keypoints, score, track_id}`` plus the images JSON),
  one image per (video, frame) and one record per (video, track, frame): frames shared by
  overlapping clips are written once.
"""
from __future__ import annotations

import json

import numpy as np

from ..atomic import atomic_output
from ..conversion.vds import open_clip_file
from ..skeletons import CARLA, joint_set, skeleton_map
from .readers import BadInput

__all__ = ["read_clips", "export_videopose3d", "export_coco", "FRAMES_3D", "SPLIT_CHOICES"]

SPLIT_CHOICES = ("train", "val", "test", "all")
FRAMES_3D = ("camera", "world", "absolute")


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
            if frame_3d is not None:
                d["xyz"] = _points_3d(g, frame_3d, h5_path)
            out[s] = d
    return out


def _points_3d(g, frame: str, h5_path) -> np.ndarray:
    from ..data.camera import carla_to_opencv
    from ..geometry import invert, transform_points

    name = "targets/absolute_pose_loc" if frame == "absolute" else "targets/world_pose_loc"
    if name not in g or (frame == "camera" and "meta/camera_transform" not in g):
        raise BadInput(f"{h5_path}: /{g.name.strip('/')} has no {name} (3D targets): a 2D-only "
                       "file (e.g. imported detections) has no 3D to export")
    xyz = g[name][()].astype(np.float64)
    if frame == "camera":  # metres, OpenCV axes (x right, y down, z forward)
        cam = invert(g["meta/camera_transform"][()].astype(np.float64))
        xyz = carla_to_opencv(transform_points(cam[:, None, None, :], xyz))
    return xyz.astype(np.float32)


def _mapped(clips: dict, key: str, m) -> tuple:
    pts, ok = m.apply(clips[key], clips["present"], fill=np.nan)
    return pts.astype(np.float32), ok


def export_videopose3d(h5_path, out_2d, out_3d=None, *, joints="h36m17", split: str = "all",
                       frame_3d: str = "camera", derive: bool = True,
                       force: bool = False) -> dict:
    """Writes ``out_2d`` (and ``out_3d``: 3D joints in ``frame_3d`` = ``camera`` (OpenCV
    axes), ``world`` or ``absolute`` (the walker's frame), metres) in VideoPose3D's
    layout with the ``joints`` set (module docstring). Returns counts."""
    dst = joint_set(joints)
    m = skeleton_map(CARLA, dst, derive)
    data = read_clips(h5_path, split, frame_3d if out_3d is not None else None)
    pos2d, pos3d, video_meta = {}, {}, {}
    for s, c in data.items():
        uv, _ = _mapped(c, "uv", m)
        xyz = _mapped(c, "xyz", m)[0] if out_3d is not None else None
        pos2d[s], pos3d[s] = {}, {}
        for i in range(len(uv)):
            action = f"{c['video'][i]} {c['track'][i]} {int(c['start'][i])}"
            pos2d[s][action] = [uv[i]]
            video_meta[action] = {"w": int(c["width"][i]), "h": int(c["height"][i])}
            if xyz is not None:
                pos3d[s][action] = xyz[i]
    metadata = {"layout_name": dst.name, "num_joints": len(dst),
                "keypoints_symmetry": [list(dst.left), list(dst.right)],
                "joint_names": list(dst.joints), "video_metadata": video_meta}
    targets = [(out_2d, dict(positions_2d=pos2d, metadata=metadata))]
    if out_3d is not None:
        targets.append((out_3d, dict(positions_3d=pos3d)))
    _save_all(targets, force, _save_npz)
    return {"clips": {s: len(v) for s, v in pos2d.items()}, "joints": dst.name,
            "present": [n for n, p in zip(dst.joints, m.present) if p]}


def _save_npz(path, arrays: dict) -> None:
    with open(path, "wb") as fh:  # a file object: np.savez adds no ".npz" to it
        np.savez_compressed(fh, **{k: np.array(v, dtype=object) for k, v in arrays.items()})


def _save_all(targets: list, force: bool, save) -> None:
    """Writes every ``(path, payload)`` under temporary names, then publishes them: an
    error in any leaves none of them behind."""
    import contextlib

    with contextlib.ExitStack() as stack:
        for path, payload in targets:
            save(stack.enter_context(atomic_output(path, force=force)), payload)


def _frames(data: dict) -> tuple:
    """Unique (video, track, frame) rows across clips and splits, with their points."""
    rows = {}
    for c in data.values():
        for i in range(len(c["uv"])):
            for k in range(c["uv"].shape[1]):
                key = (c["video"][i], c["track"][i], int(c["frames"][i, k]))
                rows.setdefault(key, (c["uv"][i, k], c["present"][i, k], int(c["width"][i]),
                                      int(c["height"][i])))
    keys = sorted(rows)
    return keys, [rows[k] for k in keys]


def export_coco(h5_path, out, *, kind: str = "annotations", images_out=None,
                joints="coco17", split: str = "all", derive: bool = True,
                force: bool = False) -> dict:
    """Writes COCO keypoint ``annotations`` (one JSON) or ``results`` (``out``, and the
    images JSON ``images_out`` that names each image id's video and frame) with the
    ``joints`` set. Missing joints are ``0, 0, 0``. Returns counts."""
    if kind not in ("annotations", "results"):
        raise ValueError(f"kind must be 'annotations' or 'results', got {kind!r}")
    if kind == "results" and images_out is None:
        raise ValueError("results name images by id only: give images_out (--images FILE) "
                         "for the images JSON")
    dst = joint_set(joints)
    m = skeleton_map(CARLA, dst, derive)
    keys, rows = _frames(read_clips(h5_path, split))
    if not keys:
        raise BadInput(f"{h5_path}: no clip in split {split!r}; nothing to export")
    uv, ok = m.apply(np.stack([r[0] for r in rows]).astype(np.float64),
                     np.stack([r[1] for r in rows]), fill=0.0)
    image_ids: dict = {}
    images, records = [], []
    for n, ((video, track, frame), row) in enumerate(zip(keys, rows)):
        if (video, frame) not in image_ids:
            image_ids[(video, frame)] = len(images) + 1
            images.append({"id": len(images) + 1, "file_name": f"{video}/{frame:06d}.jpg",
                           "width": row[2], "height": row[3], "video": video, "frame": frame})
        keypoints = []
        for (x, y), present in zip(uv[n], ok[n]):  # v = 2 (visible) / score 1.0, or 0, 0, 0
            flag = (2 if kind == "annotations" else 1.0) if present else 0
            keypoints += [float(x), float(y), flag] if present else [0.0, 0.0, flag]
        rec = {"image_id": image_ids[(video, frame)], "category_id": 1,
               "keypoints": keypoints, "track_id": track}
        if kind == "annotations":
            rec.update(_box(uv[n], ok[n]), id=n + 1, iscrowd=0, num_keypoints=int(ok[n].sum()))
        else:
            rec["score"] = 1.0
        records.append(rec)
    category = {"id": 1, "name": "person", "supercategory": "person",
                "keypoints": list(dst.joints),
                "skeleton": [[j + 1, p + 1] for j, p in enumerate(dst.parents or ()) if p >= 0]}
    images_doc = {"images": images, "categories": [category]}
    if kind == "annotations":
        targets = [(out, dict(images_doc, annotations=records))]
    else:
        targets = [(out, records), (images_out, images_doc)]
    _save_all(targets, force, _save_json)
    return {"images": len(images), "records": len(records), "joints": dst.name,
            "present": [n for n, p in zip(dst.joints, m.present) if p]}


def _box(uv, ok) -> dict:
    if not ok.any():
        return {"bbox": [0.0, 0.0, 0.0, 0.0], "area": 0.0}
    lo, hi = uv[ok].min(0), uv[ok].max(0)
    w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
    return {"bbox": [float(lo[0]), float(lo[1]), w, h], "area": w * h}


def _save_json(path, doc) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh)
