"""``bsp-preview frames``: video frames of one recording with its annotations drawn on."""
from __future__ import annotations

import os

import numpy as np

from .._extras import require
from ..check.core import dataset_paths, read_config
from ..csvio import CROSSING, read_csv
from ..media import ApngReader, VideoReader
from . import draw
from .output import check_output, output_format, parse_frames, save

cv2 = require("cv2", "bsp-preview")

LAYOUTS = ("side", "blend", "rgb")
_COLUMNS = ["id", "camera.idx", "pedestrian.idx", "frame.idx", "camera.recording",
            "camera.semantic_segmentation", "frame.pedestrian.pose.camera", CROSSING]
CROSSING_COLOUR = (255, 90, 90)


def _select_recording(table, recording, camera, pedestrian) -> np.ndarray:
    """Rows of the chosen recording, sorted by frame.idx."""
    ids = list(table.categories("id"))
    codes = table.codes("id")
    if isinstance(recording, (int, np.integer)) or (isinstance(recording, str)
                                                    and recording.isdigit()
                                                    and recording not in ids):
        k = int(recording)
        if not 0 <= k < len(ids):
            raise ValueError(f"recording index {k} out of range: the dataset has {len(ids)} "
                             "ids (0-based, in data.csv order)")
        code = k
    else:
        match = [i for i, x in enumerate(ids) if x == recording] or \
                [i for i, x in enumerate(ids) if x.startswith(str(recording))]
        if len(match) != 1:
            some = ", ".join(ids[:5]) + (" ..." if len(ids) > 5 else "")
            why = "matches several ids" if match else "is not an id of the dataset"
            raise ValueError(f"recording {recording!r} {why}; ids: {some} (or a 0-based "
                             "index)")
        code = match[0]
    rows = np.flatnonzero(codes == code)
    for name, want in (("camera.idx", camera), ("pedestrian.idx", pedestrian)):
        vals = table[name][rows]
        pick = int(vals[0]) if want is None else int(want)
        if not (vals == pick).any():
            raise ValueError(f"{name} {pick} not found for {ids[code]}; it has "
                             f"{sorted(set(vals.tolist()))}")
        rows = rows[vals == pick]
    return rows[np.argsort(table["frame.idx"][rows], kind="stable")]


def _default_frames(fmt: str, annotated: np.ndarray, n_video: int) -> np.ndarray:
    if not len(annotated):
        return np.arange(0, n_video, max(1, n_video // 4))[:4]
    first, last = int(annotated.min()), int(min(annotated.max(), n_video - 1))
    if fmt == "mp4":
        return np.arange(first, last + 1)
    return np.unique(np.linspace(first, last, 4).round().astype(np.int64))


def _panel(rgb, tags, uv, crossing, frame, rid, layout, alpha, scale) -> np.ndarray:
    h, w = rgb.shape[:2]
    W, H = max(1, round(w * scale)), max(1, round(h * scale))
    if (W, H) != (w, h):
        rgb = cv2.resize(rgb, (W, H), interpolation=cv2.INTER_AREA)
        tags = cv2.resize(tags, (W, H), interpolation=cv2.INTER_NEAREST)
    seg = draw.colourise(tags)
    if layout == "blend":
        pics = [draw.blend(rgb, seg, alpha)]
    elif layout == "rgb":
        pics = [rgb.copy()]
    else:
        pics = [rgb.copy(), seg]
    if uv is not None:
        p = uv * np.float32(scale)
        draw.draw_bbox(pics[0], p)
        for pic in pics:
            draw.draw_skeleton(pic, p, radius=max(2, round(2 * scale)))
    body = np.concatenate(pics, 1)
    label = "not annotated" if crossing is None else "crossing" if crossing else "not crossing"
    colour = CROSSING_COLOUR if crossing else None
    bar = draw.caption(body.shape[1], [f"{rid[:8]}  frame {frame}  {label}"], [colour])
    return np.concatenate([bar, body], 0)


def preview_frames(dataset, recording, out=None, *, frames=None, layout: str = "side",
                   alpha: float = 0.5, scale: float = 1.0, cols: int = 1,
                   camera: int | None = None, pedestrian: int | None = None,
                   fps: float | None = None, force: bool = False) -> dict:
    """Frames of one recording: RGB with the 2D skeleton (bones coloured by side), the
    joint bbox, the crossing label and the frame number, and the segmentation in the
    Cityscapes colours beside it (``layout="side"``), blended over it (``"blend"``) or
    left out (``"rgb"``).

    ``recording``: an id of data.csv, a unique prefix of one, or its 0-based index in
    data.csv order. ``frames``: video frame numbers as 'START:STOP:STEP', 'A,B,C' or a
    sequence (default: 4 frames spread over the annotated ones for PNG, every frame from
    the first to the last annotated one for MP4). ``out``: .png (the frames stacked,
    ``cols`` per row) or .mp4 (one video frame each, at ``fps``, default 30); None
    returns the pictures. Returns {path, format, frames, size, recording, frame_idx,
    images (only when out is None)}.
    """
    _check_style(layout, alpha, scale)
    fmt = output_format(out) if out is not None else "png"
    if out is not None:
        check_output(out, force)
    root, csv = dataset_paths(dataset)
    table = read_csv(csv, _COLUMNS, check_duplicates=False)
    rows = _select_recording(table, recording, camera, pedestrian)
    rid = str(table["id"][rows[0]])
    video = VideoReader(os.path.join(root, table["camera.recording"][rows[0]]), threads=0)
    seg = ApngReader(os.path.join(root, table["camera.semantic_segmentation"][rows[0]]))
    fidx = table["frame.idx"][rows]
    n_video = len(video)
    sel = _frame_selection(frames, fmt, fidx, n_video)
    rate = float(read_config(root).get("fps", video.fps or 30.0))
    to_apng = seg.video_to_apng_frames(n_video, rate)
    by_frame = {int(f): r for f, r in zip(fidx, rows)}
    uvs, cross = table["frame.pedestrian.pose.camera"], table[CROSSING]

    def panel(rgb, tag, f: int):
        r = by_frame.get(f)
        return _panel(rgb, tag, None if r is None else uvs[r],
                      None if r is None else bool(cross[r]), f, rid, layout, alpha, scale)

    def pictures():
        return _pictures(video, seg, to_apng, sel, panel)

    info = {"recording": rid, "frame_idx": [int(f) for f in sel]}
    if out is None:
        return dict(info, images=list(pictures()), path=None, format=None, frames=len(sel))
    if fmt == "png":  # one picture that shows every selected frame
        result = dict(save(out, [draw.grid(list(pictures()), cols)]), frames=len(sel))
    else:
        result = save(out, pictures(), fps=fps or 30.0)
    return dict(result, **info)


def _check_style(layout: str, alpha: float, scale: float) -> None:
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}; got {layout!r}")
    if not (0.0 <= float(alpha) <= 1.0):
        raise ValueError(f"alpha must be in [0, 1], got {alpha}")
    if not (0.0 < float(scale) <= 8.0):
        raise ValueError(f"scale must be in (0, 8], got {scale}")


def _frame_selection(frames, fmt: str, fidx: np.ndarray, n_video: int) -> np.ndarray:
    """The video frames to draw: ``frames`` parsed, or the format's default; each must be
    in the video and at least one chosen."""
    sel = parse_frames(frames, n_video) if frames is not None else \
        _default_frames(fmt, fidx, n_video)
    bad = sel[(sel < 0) | (sel >= n_video)]
    if len(bad):
        raise ValueError(f"frame {int(bad[0])} outside the video's 0..{n_video - 1}")
    if not len(sel):
        raise ValueError("nothing to draw: no frames selected")
    return sel


def _pictures(video, seg, to_apng: np.ndarray, sel: np.ndarray, panel):
    """``panel(rgb, tags, frame)`` of each selected frame, decoding 16 frames at a time; a
    frame shown after the animation's end gets an empty segmentation."""
    blank = np.zeros(seg.size[::-1], np.uint8)
    for start in range(0, len(sel), 16):
        chunk = sel[start:start + 16]
        rgbs = video.read(chunk)
        ap = to_apng[chunk]
        tags = seg.read(ap[ap >= 0]) if (ap >= 0).any() else None
        t = 0
        for k, f in enumerate(chunk):
            if ap[k] >= 0:
                tag, t = tags[t], t + 1
            else:
                tag = blank
            yield panel(rgbs[k], tag, int(f))
