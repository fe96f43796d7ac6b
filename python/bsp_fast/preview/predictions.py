"""``bsp-preview predictions``: ground truth against a model's outputs (bsp-predict files).

The file is read by dataset name (see docs/preview.md): root attribute ``task``; per task
the prediction and the ground truth in the same units (bsp-predict's names first, then the
minimal layout ``prediction`` / ``target``):

=================  ===============================  ==============================
task               prediction                       ground truth
=================  ===============================  ==============================
autoencoder        ``pixels`` (N, L, 26, 2)          ``target_pixels``
pose_estimation    ``crop_pixels`` (N, L, 26, 2)     ``target_crop_pixels``
lifting            ``metres_aligned`` (N, L, 26, 3)  ``target_metres``
=================  ===============================  ==============================

Captions use ``label``, ``video_id``, ``clip_id`` and ``frames`` when present.
"""
from __future__ import annotations

import numpy as np

from . import draw
from .clips import CLASS_NAMES, frame_position
from .output import check_output, output_format, save
from .plot3d import VIEWS, SkeletonFigure, limits
from .pose3d import parse_size

PAIRS = {
    "autoencoder": [("pixels", "target_pixels")],
    "pose_estimation": [("crop_pixels", "target_crop_pixels"), ("pixels", "target_pixels")],
    "lifting": [("metres_aligned", "target_metres"), ("metres", "target_metres")],
}
GENERIC = ("prediction", "target")
TASKS = tuple(PAIRS) + ("classification",)


def _attr(v):
    return v.decode() if isinstance(v, bytes) else str(v)


def read_predictions(path) -> dict:
    """{task, units, prediction, target, names, label, video_id, clip_id, frames} of a
    predictions file; ValueError naming what is missing."""
    import h5py

    with h5py.File(path, "r") as f:
        task = _attr(f.attrs.get("task", ""))
        if task not in TASKS:
            raise ValueError(f"{path}: root attribute 'task' must be one of "
                             f"{', '.join(TASKS)}; got {task!r}")
        if task == "classification":
            raise ValueError(f"{path}: classification predictions hold no poses to draw "
                             "(bsp-eval reports their scores)")
        for pred, gt in PAIRS[task] + [GENERIC]:
            if pred in f and gt in f:
                break
        else:
            want = " or ".join(f"{p} + {g}" for p, g in PAIRS[task] + [GENERIC])
            raise ValueError(f"{path}: a {task} predictions file needs datasets {want}; it "
                             f"has {', '.join(sorted(f.keys()))}")
        p, g = f[pred][()].astype(np.float64), f[gt][()].astype(np.float64)
        C = 3 if task == "lifting" else 2
        if p.shape != g.shape or p.ndim != 4 or p.shape[2:] != (26, C):
            raise ValueError(f"{path}: {pred} {p.shape} and {gt} {g.shape} must both be "
                             f"(N, L, 26, {C})")
        N, L = p.shape[:2]
        out = {"task": task, "prediction": p, "target": g, "names": (pred, gt),
               "units": _attr(f.attrs.get("units", "metres" if C == 3 else "pixels"))}
        out["label"] = f["label"][()] if "label" in f else np.full(N, -1)
        out["clip_id"] = f["clip_id"][()] if "clip_id" in f else np.arange(N)
        out["frames"] = f["frames"][()] if "frames" in f else np.tile(np.arange(L), (N, 1))
        vid = f["video_id"][()] if "video_id" in f else [""] * N
        out["video_id"] = [_attr(v) for v in vid]
    return out


def _label(v) -> str:
    v = int(v)
    return CLASS_NAMES[v] if v in (0, 1) else ""


def _panel_2d(d: dict, i: int, k: int, size: int) -> np.ndarray:
    gt, pr = d["target"][i], d["prediction"][i]
    scale, off = draw.fit_transform(np.concatenate([gt, pr]), size)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = (32, 32, 40)
    draw.draw_skeleton(img, gt[k] * scale + off, colour=draw.TRUTH)
    draw.draw_skeleton(img, pr[k] * scale + off, colour=draw.PREDICTION)
    err = np.linalg.norm(pr[k] - gt[k], axis=-1)
    unit = "px" if d["units"].startswith("pix") else d["units"]
    lines = [f"#{i} {_label(d['label'][i])}",
             f"{d['video_id'][i].rsplit('/', 1)[-1][:8]} clip {int(d['clip_id'][i])} "
             f"frame {int(d['frames'][i, k])}",
             f"mean error {np.nanmean(err):.1f} {unit}"]
    return np.concatenate([draw.caption(size, lines), img], 0)


def preview_predictions(preds_h5, out=None, *, clips=None, n: int = 16, clip: int = 0,
                        frame="middle", size=None, cols: int | None = None,
                        fps: float = 10.0, force: bool = False) -> dict:
    """Ground truth (green) against the prediction (magenta).

    2D tasks (autoencoder, pose_estimation): a sheet of clips (``clips`` or the first
    ``n``), both skeletons in one panel of ``size`` pixels (default 160) scaled to fit,
    with the mean joint error of the frame. Lifting: clip ``clip`` in 3D, ground truth and
    prediction side by side with the same axes (``size`` = (width, height), default
    800x400). ``out``: .png (frame ``frame``) or .mp4 (every predicted frame, ``fps``).
    """
    fmt = output_format(out) if out is not None else "png"
    if out is not None:
        check_output(out, force)
    d = read_predictions(preds_h5)
    N, L = d["prediction"].shape[:2]
    ks = [frame_position(frame, L)] if fmt == "png" else list(range(L))
    info = {"task": d["task"], "datasets": list(d["names"])}
    if d["task"] == "lifting":
        if not 0 <= int(clip) < N:
            raise ValueError(f"clip {clip} outside the file's 0..{N - 1}")
        i = int(clip)
        w, h = parse_size(size or (800, 400))
        lo, hi = limits(np.concatenate([d["target"][i], d["prediction"][i]]))
        fig = SkeletonFigure([("ground truth", VIEWS["front"]), ("prediction", VIEWS["front"])],
                             lo, hi, (w, h))
        head = f"{d['video_id'][i].rsplit('/', 1)[-1][:8]} clip {int(d['clip_id'][i])}"

        def pictures():
            for k in ks:
                e = np.linalg.norm(d["prediction"][i, k] - d["target"][i, k], axis=-1).mean()
                yield fig.render([[d["target"][i, k]], [d["prediction"][i, k]]],
                                 f"{head}  frame {int(d['frames'][i, k])}  mean error "
                                 f"{1000 * e:.0f} mm")
        info["clips"] = [i]
    else:
        sel = np.arange(min(int(n), N)) if clips is None else np.asarray(clips, np.int64)
        if len(sel) == 0 or sel.min() < 0 or sel.max() >= N:
            raise ValueError(f"clip indices must be in 0..{N - 1}")
        px = int(size or 160)
        if px < 32:
            raise ValueError(f"size must be at least 32 pixels, got {size}")
        ncol = cols or int(np.ceil(np.sqrt(len(sel))))

        def pictures():
            for k in ks:
                yield draw.grid([_panel_2d(d, int(i), k, px) for i in sel], ncol)
        info["clips"] = [int(i) for i in sel]
    if out is None:
        return dict(info, images=list(pictures()), path=None, format=None, frames=len(ks))
    return dict(save(out, pictures(), fps=fps), **info)
