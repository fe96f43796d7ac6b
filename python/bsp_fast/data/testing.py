"""Small HDF5 files in the exact ``bsp-convert`` schema (docs/hdf5-schema.md), for tests
and benchmarks of the loaders without a CARLA-BSP dataset.

Poses are real kinematics: the female reference skeleton with swinging arms and legs,
forward kinematics through :mod:`bsp_fast.geometry`, a walker moving on a straight line and
a CARLA camera projection, so 2D and 3D arrays of a clip agree. Clips are windows of
per-recording frame sequences (stride = offset), so overlapping clips share frames exactly
as converted data do. ``media=True`` adds the per-split frame table (``frames/rgb``,
``frames/mask``, ``frames/crop_box``, ``frames/joint_visible``, ``frames/mask_bbox``,
``frames/visible_pixels``, ``frames/frame_idx``, ``clip_frames``); the red channel of frame
``k`` holds ``k % 256`` so readers can check they fetched the right frame.
"""
from __future__ import annotations

import json

import numpy as np

from .. import geometry as _geo
from .. import skeleton as _sk

__all__ = ["write_clip_file"]

_W, _H, _FOV = 1600, 600, 90.0
_CAMERA = np.array([0.0, 0.0, 1.7, 0.0, 0.0, 0.0], np.float32)
_SWING = {"arm": (5, 13), "thigh": (21, 16)}  # left/right joint pairs swung in antiphase


def _relative_poses(n_frames: int, phase0: float, cadence: float) -> np.ndarray:
    """(n_frames, 26, 6) relative bone transforms: the reference pose with swinging limbs."""
    rel = np.repeat(_sk.reference_pose("sk_female", "relative")[None], n_frames, 0).copy()
    phase = phase0 + cadence * np.arange(n_frames)
    for left, right in _SWING.values():
        rel[:, left, 3] += 20 * np.sin(phase)
        rel[:, right, 3] -= 20 * np.sin(phase)
    return rel


def _recording(n_frames: int, rng: np.random.Generator) -> dict:
    """Per-frame arrays of one recording (walker on a straight line, static camera)."""
    rel = _relative_poses(n_frames, rng.uniform(0, 6.28), rng.uniform(0.15, 0.3))
    mesh = np.array([0, 0, -0.92, 0, -90, 0], np.float64)
    comp = _geo.forward_kinematics(rel, root=mesh)
    yaw = rng.uniform(-180, 180)
    start = np.array([rng.uniform(9, 14), rng.uniform(-4, 4), 0.92])
    step = np.array([np.cos(np.deg2rad(yaw)), np.sin(np.deg2rad(yaw)), 0]) * 1.4 / 30
    loc = start + step[None] * np.arange(n_frames)[:, None]
    walker = np.concatenate([loc, np.tile([0.0, yaw, 0.0], (n_frames, 1))], 1)
    world = _geo.to_world(comp, walker)
    uv = _geo.project(world[..., :3], _CAMERA.astype(np.float64), _W, _H, _FOV)
    cross_from = rng.integers(n_frames // 3, n_frames) if rng.random() < 0.5 else n_frames
    return dict(rel=rel, comp=comp, world=world, walker=walker, uv=uv,
                velocity=np.tile(step * 30, (n_frames, 1)),
                crossing=(np.arange(n_frames) >= cross_from).astype(np.uint8))


def _loc_rot(t6: np.ndarray) -> tuple:
    return t6[..., :3].astype(np.float32), _geo.rotation_matrix(t6[..., 3:]).astype(np.float32)


def _inside(uv: np.ndarray) -> np.ndarray:
    """Per frame: every joint finite and inside the image (docs/dataset-format.md,
    "7. From rows to clips and splits")."""
    u, v = uv[..., 0], uv[..., 1]
    return np.all(np.isfinite(uv).all(-1) & (u >= 0) & (u <= _W) & (v >= 0) & (v <= _H), -1)


def _clip_arrays(recs: list, L: int, stride: int) -> dict:
    """Windows of every recording whose frames all lie in the image -> per-clip arrays
    (before the split shuffle)."""
    out = {k: [] for k in ("rec", "first", "clip_id")}
    for r, rec in enumerate(recs):
        ok = _inside(rec["uv"])
        starts = [f for f in range(0, len(ok) - L + 1, stride) if ok[f:f + L].all()]
        out["rec"] += [r] * len(starts)
        out["first"] += starts
        out["clip_id"] += [f // stride for f in starts]
    return {k: np.asarray(v, np.int64) for k, v in out.items()}


def _gather(recs, clips, key, L):
    return np.stack([recs[r][key][f:f + L] for r, f in zip(clips["rec"], clips["first"])])


def _write_split(g, recs, clips, L, chunk, media: dict | None, rotations: bool = True):
    n = len(clips["rec"])
    def rows(shape):
        return (max(1, min(chunk, n)),) + tuple(shape[1:])

    def put(name, a):
        return g.create_dataset(name, data=a, chunks=rows(a.shape) if a.size else None)

    uv = _gather(recs, clips, "uv", L).astype(np.float32)
    labels = _gather(recs, clips, "crossing", L)[:, -1]
    put("projection_2d", uv)
    put("labels", labels.astype(np.uint8))
    for name, key in (("relative_pose", "rel"), ("absolute_pose", "comp"), ("world_pose", "world")):
        t6 = _gather(recs, clips, key, L)
        put(f"targets/{name}_loc", t6[..., :3].astype(np.float32))
        if rotations:
            put(f"targets/{name}_rot", _loc_rot(t6)[1])
    loc, rot = _loc_rot(_gather(recs, clips, "walker", L))
    put("targets/world_loc", loc)
    put("targets/world_rot", rot)
    put("targets/velocity", _gather(recs, clips, "velocity", L).astype(np.float32))
    put("targets/bboxes", np.stack([uv.min(2), uv.max(2)], 2))
    put("targets/is_crossing", _gather(recs, clips, "crossing", L))
    frame_idx = clips["first"][:, None] + np.arange(L)
    put("targets/frame_idx", frame_idx.astype(np.int64))
    strings = {"video_id": [f"clips/rec{r:04d}-0" for r in clips["rec"]],
               "pedestrian_id": ["0_0"] * n, "model": ["walker.pedestrian.0001"] * n,
               "map": ["/Game/Carla/Maps/Town01"] * n,
               "age": [("adult", "child")[r % 2] for r in clips["rec"]],
               "gender": [("female", "male")[(r // 2) % 2] for r in clips["rec"]]}
    import h5py

    for name, v in strings.items():
        put(f"meta/{name}", np.array(v, dtype=h5py.string_dtype()))
    put("meta/clip_id", clips["clip_id"].astype(np.int32))
    put("meta/segment", np.zeros(n, np.int32))
    put("meta/start_frame", clips["first"].astype(np.int64))
    put("meta/end_frame", (clips["first"] + L).astype(np.int64))
    put("meta/clip_width", np.full(n, _W, np.int64))
    put("meta/clip_height", np.full(n, _H, np.int64))
    put("meta/camera_transform", np.tile(_CAMERA, (n, 1)))
    put("meta/tte", np.full(n, -1, np.int32))  # not benchmark windows: no event
    g.attrs["class_counts"] = np.bincount(labels, minlength=2).astype(np.int64)
    g.attrs["recordings"] = len(set(clips["rec"].tolist()))
    if media is not None:
        _write_media(g, recs, clips, L, media["size"], rows)
    return np.bincount(labels, minlength=2)


def _write_media(g, recs, clips, L, S, rows):
    """The per-split frame table: frames of the split's recordings, each stored once."""
    used = sorted(set(clips["rec"].tolist()))
    base, offset = {}, 0
    for r in used:
        base[r], offset = offset, offset + len(recs[r]["uv"])
    uv = np.concatenate([recs[r]["uv"] for r in used]).astype(np.float32)
    F = len(uv)
    lo, hi = uv.min(1), uv.max(1)
    centre, half = (lo + hi) / 2, (hi - lo).max(1) / 2 * 1.2 + 1
    box = np.concatenate([centre - half[:, None], centre + half[:, None]], 1).astype(np.float32)
    rgb = np.zeros((F, S, S, 3), np.uint8)
    rgb[..., 0] = (np.arange(F) % 256).astype(np.uint8)[:, None, None]
    rgb[..., 1] = np.arange(S, dtype=np.uint8)[None, None, :]
    mask = np.zeros((F, S, S), np.uint8)
    mask[:, S // 4:3 * S // 4, S // 3:2 * S // 3] = 4  # CARLA tag 4 = Pedestrian
    rng = np.random.default_rng(F)
    vis = (rng.random((F, 26)) > 0.1).astype(np.uint8)
    frames = np.array([base[r] + f for r, f in zip(clips["rec"], clips["first"])])
    k = max(1, min(64, F))  # bsp-convert's layout: 64-frame chunks, deflated masks
    g.create_dataset("frames/rgb", data=rgb, chunks=(k, S, S, 3))
    g.create_dataset("frames/mask", data=mask, chunks=(k, S, S), compression="gzip",
                     compression_opts=1)
    g.create_dataset("frames/crop_box", data=box)
    g.create_dataset("frames/joint_visible", data=vis)
    mb = np.tile(np.array([S / 3, S / 4, 2 * S / 3, 3 * S / 4], np.float32), (F, 1))
    g.create_dataset("frames/mask_bbox", data=mb)
    g.create_dataset("frames/visible_pixels", data=np.full(F, (S // 2) * (S // 3), np.int64))
    g.create_dataset("frames/frame_idx",
                     data=np.concatenate([np.arange(len(recs[r]["uv"])) for r in used]))
    g.create_dataset("clip_frames", data=(frames[:, None] + np.arange(L)).astype(np.int64),
                     chunks=rows((len(frames), L)))


def write_clip_file(path, clips=(96, 24, 24), clip_length: int = 8, clip_offset: int | None = None,
                    frames_per_recording: int | None = None, seed: int = 0, chunk: int = 64,
                    media: bool = False, crop_size: int = 32, rotations: bool = True) -> dict:
    """Writes a schema-v1 file with about ``clips`` (train, val, test) clips; returns
    ``{"clips": {split: n}, "class_counts": {split: [n0, n1]}}``.

    Recordings of ``frames_per_recording`` frames (default ``4 * clip_length``) are sliced
    into windows every ``clip_offset`` frames (default: the clip length), windows with a
    joint outside the image are dropped (as bsp-convert does), and each split takes whole
    recordings until it holds at least its share of clips. ``rotations=False``
    leaves out the ``*_pose_rot`` arrays (large, unused by the loaders) for benchmark files.
    """
    import h5py

    L = int(clip_length)
    stride = int(clip_offset or L)
    R = int(frames_per_recording or 4 * L)
    rng = np.random.default_rng(seed)
    info = {"clips": {}, "class_counts": {}}
    with h5py.File(path, "w") as f:
        for split, want in zip(("train", "val", "test"), clips):
            recs, parts, have = [], [], 0
            while have < max(1, int(want)):
                recs.append(_recording(R, rng))
                part = _clip_arrays(recs[-1:], L, stride)
                part["rec"] += len(recs) - 1
                parts.append(part)
                have += len(part["rec"])
            c = {k: np.concatenate([q[k] for q in parts]) for k in parts[0]}
            order = rng.permutation(len(c["rec"]))
            c = {k: v[order] for k, v in c.items()}
            counts = _write_split(f.create_group(split), recs, c, L, chunk,
                                  {"size": crop_size} if media else None, rotations)
            info["clips"][split] = len(order)
            info["class_counts"][split] = counts.tolist()
            f.attrs[f"class_counts_{split}"] = counts.astype(np.int64)
        _root_attrs(f, L, stride, seed)
        f.attrs["media"] = int(media)
        if media:  # crops around the encoded joints, like bsp-convert's mask boxes
            f.attrs["crop_size"], f.attrs["crop_box"] = int(crop_size), "mask"
    return info


def _root_attrs(f, L, stride, seed):
    import h5py

    s = h5py.string_dtype()
    f.attrs.update({"schema_version": 1, "created_by": "bsp_fast.data.testing",
                    "clip_length": L, "clip_stride": stride, "eval_clip_stride": stride,
                    "min_video_length": L, "label_rule": "last", "benchmark": 0,
                    "val_frac": 0.2, "test_frac": 0.2, "seed": seed, "balance": 0,
                    "fov": _FOV, "compression": "none"})
    f.attrs.create("class_labels", np.array(["not-crossing", "crossing"], dtype=s))
    f.attrs.create("joint_names", np.array(_sk.JOINT_NAMES, dtype=s))
    f.attrs["parents"] = np.asarray(_sk.PARENTS, np.int32)
    f.attrs["settings_json"] = json.dumps({"clip_length": L, "clip_offset": stride})
