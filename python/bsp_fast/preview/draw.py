"""Drawing primitives of bsp-preview (OpenCV on RGB uint8 arrays).

Images are (H, W, 3) uint8 **RGB** throughout; only the PNG writer converts to BGR.
Joint (u, v) in pixels (origin at the top-left corner of the image, pixel column j covers u
in [j, j + 1); docs/preview.md, "bsp-preview: look at the data") is drawn centred on pixel
(floor(u), floor(v)).
"""
from __future__ import annotations

import numpy as np

from .._extras import require
from .. import skeleton as sk
from ..media import CITYSCAPES_PALETTE

cv2 = require("cv2", "bsp-preview")

#: Bone and joint colours (RGB) by side of the body.
LEFT = (0, 170, 255)
RIGHT = (255, 140, 0)
CENTRE = (60, 230, 60)
BBOX = (255, 255, 255)
#: Ground truth and prediction colours of `bsp-preview predictions`.
TRUTH = (60, 230, 60)
PREDICTION = (255, 0, 255)
#: The autoencoder's noisy input in `bsp-preview predictions`.
INPUT = (150, 150, 150)
CAPTION_BG = (24, 24, 24)
CAPTION_FG = (235, 235, 235)
FONT = cv2.FONT_HERSHEY_SIMPLEX
#: Caption bar height per line of text, in pixels.
LINE_HEIGHT = 14


def joint_side(j: int) -> str:
    name = sk.JOINT_NAMES[j]
    return "left" if name.endswith("__L") else "right" if name.endswith("__R") else "centre"


#: (26, 3) colour of each joint; a bone takes its child joint's colour.
JOINT_COLOURS = np.array([{"left": LEFT, "right": RIGHT, "centre": CENTRE}[joint_side(j)]
                          for j in range(sk.NUM_JOINTS)], np.uint8)


def colourise(tags: np.ndarray) -> np.ndarray:
    """(H, W) class tags -> (H, W, 3) RGB in the Cityscapes colours (unknown tags black)."""
    pal = np.zeros((256, 3), np.uint8)
    pal[: len(CITYSCAPES_PALETTE)] = CITYSCAPES_PALETTE
    return pal[np.asarray(tags, np.uint8)]


def blend(rgb: np.ndarray, overlay: np.ndarray, alpha: float) -> np.ndarray:
    return cv2.addWeighted(overlay, float(alpha), rgb, 1.0 - float(alpha), 0.0)


def _pt(u: float, v: float) -> tuple:
    return int(np.floor(u)), int(np.floor(v))


def _finite(p) -> bool:
    return bool(np.isfinite(p).all()) and abs(p[0]) < 1e6 and abs(p[1]) < 1e6


def draw_skeleton(img: np.ndarray, uv, *, colour=None, radius: int = 2, thickness: int = 1,
                  visible=None) -> np.ndarray:
    """Draws the 26-joint skeleton (pixels, (26, 2)) in place and returns ``img``.

    Bones are lines from parent to child in the child's side colour (or ``colour``), joints
    filled discs of ``radius`` drawn after all bones, so a joint's own pixel has its colour.
    Joints that are not finite are skipped with their bones; joints where ``visible`` is
    False are drawn as rings.
    """
    uv = np.asarray(uv, np.float64).reshape(sk.NUM_JOINTS, 2)
    cols = [tuple(int(c) for c in (colour if colour is not None else JOINT_COLOURS[j]))
            for j in range(sk.NUM_JOINTS)]
    for p, c in sk.EDGES:
        if _finite(uv[p]) and _finite(uv[c]):
            cv2.line(img, _pt(*uv[p]), _pt(*uv[c]), cols[c], thickness, cv2.LINE_8)
    for j in range(sk.NUM_JOINTS):
        if not _finite(uv[j]):
            continue
        filled = visible is None or bool(visible[j])
        cv2.circle(img, _pt(*uv[j]), radius, cols[j], -1 if filled else 1, cv2.LINE_8)
    return img


def joint_bbox(uv) -> tuple | None:
    """(u0, v0, u1, v1) of the finite joints, or None."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    ok = np.isfinite(uv).all(1)
    if not ok.any():
        return None
    lo, hi = uv[ok].min(0), uv[ok].max(0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def draw_bbox(img: np.ndarray, uv, colour=BBOX) -> np.ndarray:
    box = joint_bbox(uv)
    if box is not None and all(abs(x) < 1e6 for x in box):
        cv2.rectangle(img, _pt(box[0], box[1]), _pt(box[2], box[3]), colour, 1, cv2.LINE_8)
    return img


def caption(width: int, lines, colours=None) -> np.ndarray:
    """A (LINE_HEIGHT * len(lines), width, 3) dark bar with one text line per entry."""
    lines = list(lines)
    bar = np.empty((LINE_HEIGHT * len(lines), width, 3), np.uint8)
    bar[:] = CAPTION_BG
    for i, text in enumerate(lines):
        col = CAPTION_FG if colours is None or colours[i] is None else colours[i]
        cv2.putText(bar, str(text), (3, LINE_HEIGHT * (i + 1) - 4), FONT, 0.36,
                    tuple(int(c) for c in col), 1, cv2.LINE_AA)
    return bar


def grid(panels: list, cols: int, gap: int = 2, background=(0, 0, 0)) -> np.ndarray:
    """Tiles equally sized (h, w, 3) panels, `cols` per row, `gap` pixels apart."""
    if not panels:
        raise ValueError("nothing to draw: no panels")
    h, w = panels[0].shape[:2]
    if any(p.shape[:2] != (h, w) for p in panels):
        raise ValueError("grid: panels differ in size")
    cols = max(1, min(int(cols), len(panels)))
    rows = -(-len(panels) // cols)
    out = np.empty((rows * h + (rows - 1) * gap, cols * w + (cols - 1) * gap, 3), np.uint8)
    out[:] = background
    for i, p in enumerate(panels):
        r, c = divmod(i, cols)
        out[r * (h + gap): r * (h + gap) + h, c * (w + gap): c * (w + gap) + w] = p
    return out


def fit_transform(points, size: int, margin: float = 0.1) -> tuple:
    """(scale, offset) mapping the finite (…, 2) points into a `size` square panel,
    aspect kept, centred, with `margin` of the panel free on each side."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(1)]
    if not len(pts):
        return 1.0, np.zeros(2)
    lo, hi = pts.min(0), pts.max(0)
    extent = max(float((hi - lo).max()), 1e-6)
    scale = size * (1 - 2 * margin) / extent
    offset = size / 2 - scale * (lo + hi) / 2
    return scale, offset
