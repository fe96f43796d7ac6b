"""``bsp-preview clips``: a contact sheet of the clips of a bsp-convert HDF5 file."""
from __future__ import annotations

import numpy as np

from .._extras import require
from . import draw
from .output import check_output, output_format, save

cv2 = require("cv2", "bsp-preview")

SPLITS = ("train", "val", "test")
CAPTION_LINES = 3
PANEL_BG = (32, 32, 40)
TRAIL = (110, 110, 110)
CLASS_NAMES = ("not-crossing", "crossing")


def frame_position(frame, L: int) -> int:
    """'first', 'middle', 'last' or an int (negative counts from the end) -> 0..L-1."""
    named = {"first": 0, "middle": L // 2, "last": L - 1}
    if isinstance(frame, str) and frame in named:
        return named[frame]
    try:
        k = int(frame)
    except (TypeError, ValueError):
        raise ValueError(f"frame must be first, middle, last or a number, got {frame!r}") \
            from None
    if not -L <= k < L:
        raise ValueError(f"frame {k} outside the clip's 0..{L - 1}")
    return k % L


def _strings(ds, sel) -> list:
    return [x.decode() if isinstance(x, bytes) else str(x) for x in ds[sel]]


def read_clips(path, split: str, sel=None, n: int = 16, seed=None) -> dict:
    """The arrays a sheet needs for clips `sel` (or the first / `seed`-random `n`)."""
    from ..conversion.vds import open_clip_file

    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}; got {split!r}")
    with open_clip_file(path) as f:
        if split not in f:
            raise ValueError(f"{path} has no split {split!r} (has {', '.join(f.keys())})")
        g = f[split]
        N = g["labels"].shape[0]
        if N == 0:
            raise ValueError(f"split {split!r} of {path} holds no clips")
        if sel is None:
            if int(n) < 1:
                raise ValueError(f"n must be a positive number of clips, got {n}")
            pick = np.arange(N) if seed is None else np.random.default_rng(seed).permutation(N)
            sel = np.sort(pick[: min(int(n), N)])
        sel = np.asarray(sel, np.int64).reshape(-1)
        if len(sel) == 0 or sel.min() < 0 or sel.max() >= N:
            raise ValueError(f"clip indices must be in 0..{N - 1}, got {sel.tolist()}")
        order = np.argsort(sel)
        s = sel[order]
        uniq, inv = np.unique(s, return_inverse=True)
        back = np.empty_like(order)
        back[order] = np.arange(len(order))

        def take(name):
            a = g[name][uniq]
            return a[inv][back]

        out = {"index": sel, "uv": take("projection_2d"), "label": take("labels"),
               "frame_idx": take("targets/frame_idx"), "clip_id": take("meta/clip_id"),
               "segment": take("meta/segment") if "meta/segment" in g else
               np.zeros(len(sel), np.int32)}
        for k in ("video_id", "age", "gender"):
            out[k] = [_strings(g[f"meta/{k}"], [int(i)])[0] for i in sel]
        out["media"] = bool(f.attrs.get("media", 0)) and "frames/rgb" in g
        if out["media"]:
            cf = take("clip_frames")
            rows, rinv = np.unique(cf.reshape(-1), return_inverse=True)
            out["rgb"] = g["frames/rgb"][rows][rinv].reshape(cf.shape + g["frames/rgb"].shape[1:])
            out["crop_box"] = g["frames/crop_box"][rows][rinv].reshape(cf.shape + (4,))
            out["joint_visible"] = g["frames/joint_visible"][rows][rinv].reshape(cf.shape + (26,))
    return out


def _short_id(video_id: str) -> str:
    return video_id.rsplit("/", 1)[-1][:8]


def clip_panel(c: dict, i: int, k: int, size: int) -> np.ndarray:
    """Panel of clip i (of the arrays from :func:`read_clips`) at clip frame k."""
    uv = c["uv"][i, k].astype(np.float64)
    if c["media"]:
        u0, v0, u1, v1 = c["crop_box"][i, k].astype(np.float64)
        img = cv2.resize(np.ascontiguousarray(c["rgb"][i, k]), (size, size),
                         interpolation=cv2.INTER_LINEAR)
        p = (uv - [u0, v0]) * (size / (u1 - u0))
        draw.draw_skeleton(img, p, radius=2, visible=c["joint_visible"][i, k])
    else:
        img = np.empty((size, size, 3), np.uint8)
        img[:] = PANEL_BG
        scale, off = draw.fit_transform(c["uv"][i], size)
        hips = c["uv"][i, :, 1].astype(np.float64) * scale + off
        ok = np.isfinite(hips).all(1)
        if ok.sum() > 1:
            cv2.polylines(img, [np.floor(hips[ok]).astype(np.int32)], False, TRAIL, 1)
        draw.draw_skeleton(img, uv * scale + off, radius=2)
    label = int(c["label"][i])
    lines = [f"#{int(c['index'][i])} {CLASS_NAMES[label] if label < 2 else label}",
             f"{_short_id(c['video_id'][i])} clip {int(c['clip_id'][i])} "
             f"seg {int(c['segment'][i])}",
             f"{c['age'][i]} {c['gender'][i]} frame {int(c['frame_idx'][i, k])}"]
    bar = draw.caption(size, lines, [(255, 90, 90) if label == 1 else None, None, None])
    return np.concatenate([bar, img], 0)


def preview_clips(clips_h5, out=None, *, split: str = "train", n: int = 16, clips=None,
                  frame="middle", size: int = 128, cols: int | None = None, seed=None,
                  fps: float = 10.0, force: bool = False) -> dict:
    """A contact sheet of clips: the pedestrian crop with its skeleton for files converted
    with media (joints the mask does not show are rings), the skeleton alone (scaled to the
    panel, with the hips' path over the clip in grey) otherwise; each panel ``size`` pixels
    square under a 3-line caption (clip index and label; recording, clip and segment ids;
    age, gender and frame.idx).

    ``clips``: clip indices of the split (default: the first ``n``, or ``n`` at random
    with ``seed``). ``frame``: the clip frame shown (first, middle, last or a number).
    ``out``: .png (one sheet) or .mp4 (the sheet at every clip frame, ``fps``); None
    returns the pictures. Returns {path, format, frames, size, clips, images?}.
    """
    if int(size) < 32:
        raise ValueError(f"size must be at least 32 pixels, got {size}")
    fmt = output_format(out) if out is not None else "png"
    if out is not None:
        check_output(out, force)
    c = read_clips(clips_h5, split, clips, n, seed)
    L = c["uv"].shape[1]
    cols = cols or int(np.ceil(np.sqrt(len(c["index"]))))
    if int(cols) < 1:
        raise ValueError(f"cols must be positive, got {cols}")

    def sheet(k):
        return draw.grid([clip_panel(c, i, k, int(size)) for i in range(len(c["index"]))],
                         cols)

    info = {"clips": [int(i) for i in c["index"]], "media": c["media"]}
    ks = [frame_position(frame, L)] if fmt == "png" else list(range(L))
    if out is None:
        return dict(info, images=[sheet(k) for k in ks], path=None, format=None, frames=len(ks))
    return dict(save(out, (sheet(k) for k in ks), fps=fps), **info)
