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

Captions use ``label``, ``video_id``, ``clip_id`` and ``frames`` when present. Also drawn
when present: the autoencoder's noisy input (``input_pixels``, missing joints at (0, 0)),
and for pose estimation the crops the model saw, read from the converted file named by the
``source`` attribute (or ``clips_h5``) at the clips' ``row`` of ``split``, with the
skeletons in image pixels (``pixels``, and ``projection_2d`` of that file).
"""
from __future__ import annotations

import numpy as np

from .._extras import require
from . import draw
from .clips import CLASS_NAMES, frame_position
from .output import check_output, output_format, save
from .plot3d import VIEWS, SkeletonFigure, limits
from .pose3d import parse_size

cv2 = require("cv2", "bsp-preview")

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
        out["input"] = (f["input_pixels"][()].astype(np.float64)
                        if task == "autoencoder" and "input_pixels" in f else None)
        crops = task == "pose_estimation" and "pixels" in f and "row" in f
        out["pixels"] = f["pixels"][()].astype(np.float64) if crops else None
        out["row"] = f["row"][()] if crops else None
        out["source"] = _attr(f.attrs["source"]) if "source" in f.attrs else None
        out["split"] = _attr(f.attrs.get("split", "test"))
        out["frame_start"] = int(f.attrs.get("frame_start", 0))
    return out


def read_crops(d: dict, sel, clips_h5=None) -> dict | None:
    """The crops behind pose-estimation predictions ``d`` (of :func:`read_predictions`) for
    clips ``sel``: {rgb (n, L', S, S, 3), crop_box (n, L', 4), truth (n, L', 26, 2) image
    pixels}; None when the file has no ``pixels``/``row`` to place them (a minimal file).
    ValueError when the converted file is missing or holds no crops."""
    from pathlib import Path

    from ..conversion.vds import open_clip_file

    if d["pixels"] is None:
        return None
    path = clips_h5 or d["source"]
    if path is None:
        return None
    if not Path(path).is_file():
        raise ValueError(f"{path}: the converted file of these predictions (their 'source' "
                         "attribute) does not exist; pass the file that holds the crops "
                         "(--clips-h5 CLIPS.h5)")
    L = d["prediction"].shape[1]
    rows = np.asarray(d["row"], np.int64)[np.asarray(sel, np.int64)]
    uniq, inv = np.unique(rows, return_inverse=True)
    k0 = d["frame_start"]
    with open_clip_file(path) as f:
        if d["split"] not in f:
            raise ValueError(f"{path} has no split {d['split']!r} (has {', '.join(f.keys())})")
        g = f[d["split"]]
        if "frames/rgb" not in g:
            raise ValueError(f"{path} holds no crops (converted with --no-media)")
        if len(uniq) and uniq[-1] >= g["labels"].shape[0]:
            raise ValueError(f"{path}: split {d['split']!r} has no row {int(uniq[-1])}: not "
                             "the file these predictions were made from")
        cf = g["clip_frames"][uniq][inv][:, k0:k0 + L]
        truth = g["projection_2d"][uniq][inv][:, k0:k0 + L].astype(np.float64)
        frames, finv = np.unique(cf.reshape(-1), return_inverse=True)
        rgb = g["frames/rgb"][frames][finv]
        box = g["frames/crop_box"][frames][finv].astype(np.float64)
    return {"rgb": rgb.reshape(cf.shape + rgb.shape[1:]), "crop_box": box.reshape(cf.shape + (4,)),
            "truth": truth}


def _label(v) -> str:
    v = int(v)
    return CLASS_NAMES[v] if v in (0, 1) else ""


def _no_missing(uv):
    """Joints a deformed input lost are (0, 0): NaN, so they are not drawn."""
    uv = np.array(uv, np.float64)
    uv[(uv == 0).all(-1)] = np.nan
    return uv


def _panel_2d(d: dict, i: int, k: int, size: int, crop=None, c: int = 0) -> np.ndarray:
    """Panel of clip i at frame k: truth and prediction (and the autoencoder's input) on a
    dark square scaled to fit, or on the crop (``crop`` of :func:`read_crops`, entry c)."""
    gt, pr = d["target"][i], d["prediction"][i]
    if crop is not None:
        u0, v0, u1, v1 = crop["crop_box"][c, k]
        img = cv2.resize(np.ascontiguousarray(crop["rgb"][c, k]), (size, size),
                         interpolation=cv2.INTER_LINEAR)
        s = size / (u1 - u0)
        skeletons = [(crop["truth"][c, k], draw.TRUTH), (d["pixels"][i, k], draw.PREDICTION)]
        skeletons = [((uv - [u0, v0]) * s, col) for uv, col in skeletons]
    else:
        inp = None if d.get("input") is None else _no_missing(d["input"][i])
        scale, off = draw.fit_transform(np.concatenate([gt, pr] + ([] if inp is None
                                                                  else [inp])), size)
        img = np.empty((size, size, 3), np.uint8)
        img[:] = (32, 32, 40)
        skeletons = [] if inp is None else [(inp[k] * scale + off, draw.INPUT)]
        skeletons += [(gt[k] * scale + off, draw.TRUTH), (pr[k] * scale + off, draw.PREDICTION)]
    for uv, colour in skeletons:
        draw.draw_skeleton(img, uv, colour=colour)
    err = np.linalg.norm(pr[k] - gt[k], axis=-1)
    unit = "px" if d["units"].startswith("pix") else d["units"]
    lines = [f"#{i} {_label(d['label'][i])}",
             f"{d['video_id'][i].rsplit('/', 1)[-1][:8]} clip {int(d['clip_id'][i])} "
             f"frame {int(d['frames'][i, k])}",
             f"mean error {np.nanmean(err):.1f} {unit}"]
    return np.concatenate([draw.caption(size, lines), img], 0)


def preview_predictions(preds_h5, out=None, *, clips=None, n: int = 16, clip: int = 0,
                        frame="middle", size=None, cols: int | None = None,
                        fps: float = 10.0, force: bool = False, clips_h5=None) -> dict:
    """Ground truth (green) against the prediction (magenta).

    2D tasks: a sheet of clips (``clips`` or the first ``n``), the skeletons in one panel
    of ``size`` pixels (default 160) with the mean joint error of the frame. Autoencoder:
    scaled to fit, with the noisy input (grey, missing joints left out) under them. Pose
    estimation: on the crop the model saw, from the converted file (``clips_h5``, default
    the predictions' ``source``); scaled to fit on a dark square for a file without
    ``pixels`` and ``row``. Lifting: clip ``clip`` in 3D from the front and from the side,
    both skeletons in each view, same axes (``size`` = (width, height), default 800x400).
    ``out``: .png (frame ``frame``) or .mp4 (every predicted frame, ``fps``).
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
        fig = SkeletonFigure([(f"{v}: truth green, prediction magenta", VIEWS[v])
                              for v in ("front", "side")], lo, hi, (w, h), n_skeletons=2,
                             colours=[draw.TRUTH, draw.PREDICTION])
        head = f"{d['video_id'][i].rsplit('/', 1)[-1][:8]} clip {int(d['clip_id'][i])}"

        def pictures():
            for k in ks:
                e = np.linalg.norm(d["prediction"][i, k] - d["target"][i, k], axis=-1).mean()
                both = [d["target"][i, k], d["prediction"][i, k]]
                yield fig.render([both, both],
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
        crop = read_crops(d, sel, clips_h5) if d["task"] == "pose_estimation" else None

        def pictures():
            for k in ks:
                yield draw.grid([_panel_2d(d, int(i), k, px, crop, c)
                                 for c, i in enumerate(sel)], ncol)
        info["clips"] = [int(i) for i in sel]
        info["background"] = "crops" if crop is not None else "plain"
    if out is None:
        return dict(info, images=list(pictures()), path=None, format=None, frames=len(ks))
    return dict(save(out, pictures(), fps=fps), **info)
