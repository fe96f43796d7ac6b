"""Where previews go: PNG (one picture) or MP4 (one picture per frame), written under a
temporary name and renamed, never over an existing file without ``force``."""
from __future__ import annotations

import itertools
import os

import numpy as np

from .._extras import require
from ..atomic import write_bytes
from ..media import VideoWriter

cv2 = require("cv2", "bsp-preview")

FORMATS = ("png", "mp4")


def output_format(path) -> str:
    """'png' or 'mp4' from the file name; ValueError otherwise."""
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    if ext not in FORMATS:
        raise ValueError(f"output must end in .png or .mp4, got {os.fspath(path)!r}")
    return ext


def check_output(path, force: bool) -> str:
    path = os.fspath(path)
    output_format(path)
    if os.path.exists(path) and not force:
        raise FileExistsError(f"{path} exists; pass force=True (--force) to replace it")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise FileNotFoundError(f"output directory {parent} does not exist")
    return path


def write_png(path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                            [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise RuntimeError(f"OpenCV could not encode {path}")
    write_bytes(path, data.tobytes())


def even_pad(image: np.ndarray) -> np.ndarray:
    """Pads with black to even width and height (H.264 in yuv420p needs both)."""
    h, w = image.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return image
    out = np.zeros((h + h % 2, w + w % 2, 3), np.uint8)
    out[:h, :w] = image
    return out


def write_mp4(path, images, fps: float) -> int:
    """Encodes an iterable of equally sized RGB pictures; returns the frame count."""
    writer, n = None, 0
    try:
        for img in images:
            img = even_pad(img)
            if writer is None:
                writer = VideoWriter(path, img.shape[1], img.shape[0], fps=fps)
            writer.write(img)
            n += 1
        if writer is None:
            raise ValueError("nothing to draw: no frames selected")
        writer.close()
    except BaseException:
        if writer is not None:
            del writer  # an unfinished file is removed by the writer
        raise
    return n


def save(path, images, fps: float = 30.0) -> dict:
    """PNG: the first picture; MP4: all of them (any iterable, drawn as it is consumed).
    Returns {path, format, frames, size (w, h)}. Call :func:`check_output` first."""
    path = os.fspath(path)
    fmt = output_format(path)
    it = iter(images)
    first = next(it, None)
    if first is None:
        raise ValueError("nothing to draw: no frames selected")
    h, w = even_pad(first).shape[:2] if fmt == "mp4" else first.shape[:2]
    if fmt == "png":
        write_png(path, first)
        return {"path": path, "format": fmt, "frames": 1, "size": (w, h)}
    n = write_mp4(path, itertools.chain([first], it), fps)
    return {"path": path, "format": fmt, "frames": n, "size": (w, h)}


def parse_frames(spec, n: int) -> np.ndarray:
    """Frame numbers from 'START:STOP:STEP' (Python slice over 0..n-1), 'A,B,C' or 'K'."""
    if spec is None:
        return np.arange(n)
    if isinstance(spec, slice):
        return np.arange(n)[spec]
    if not isinstance(spec, str):
        a = np.asarray(spec, np.int64).reshape(-1)
        return a
    s = spec.strip()
    try:
        if ":" in s:
            parts = [int(p) if p.strip() else None for p in s.split(":")]
            if len(parts) > 3:
                raise ValueError
            return np.arange(n)[slice(*parts)]
        return np.array([int(p) for p in s.split(",")], np.int64)
    except ValueError:
        raise ValueError(f"frames must be START:STOP:STEP, a comma list or one number, "
                         f"got {spec!r}") from None
