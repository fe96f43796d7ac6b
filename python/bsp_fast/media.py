"""MP4 (H.264) and segmentation APNG: writers for the dataset generator, readers for loaders.

The pixel index of a segmentation APNG is the CARLA 0.9.13 semantic tag; the palette holds
the Cityscapes colours (SPEC section 1), so viewers show colours while readers get tags.
"""
from __future__ import annotations

import os

import numpy as np

from ._native import core as _core

#: Names of the CARLA 0.9.13 semantic tags; index = tag.
TAG_NAMES: tuple = tuple(_core.TAG_NAMES)
#: (23, 3) uint8 Cityscapes colour of each tag; index = tag.
CITYSCAPES_PALETTE: np.ndarray = np.asarray(_core.CITYSCAPES_COLORS, dtype=np.uint8)
CITYSCAPES_PALETTE.setflags(write=False)

_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow",
            "slower", "veryslow", "placebo")


def _check_size(width, height, even: bool) -> tuple:
    w, h = int(width), int(height)
    if w <= 0 or h <= 0 or (even and (w % 2 or h % 2)):
        need = "positive even" if even else "positive"
        raise ValueError(f"width and height must be {need} integers, got {width}x{height}")
    return w, h


def _check_fps(fps) -> float:
    fps = float(fps)
    if not (fps > 0 and np.isfinite(fps)):
        raise ValueError(f"fps must be a positive number, got {fps}")
    return fps


def _frames(frames, shape: tuple, what: str) -> np.ndarray:
    """(*shape) or (K, *shape) uint8, C-contiguous."""
    a = np.asarray(frames)
    if a.dtype != np.uint8:
        raise ValueError(f"{what}: expected dtype uint8, got {a.dtype}")
    if a.shape == shape:
        a = a[None]
    if a.ndim != len(shape) + 1 or a.shape[1:] != shape:
        raise ValueError(f"{what}: expected shape {shape} or (K, *{shape}), got {a.shape}")
    return np.ascontiguousarray(a)


class VideoWriter:
    """H.264 (High profile, yuv420p) MP4 writer, x264 in average-bitrate mode.

    Frames are (H, W, 3) or (K, H, W, 3) uint8 RGB. The file appears at `path` only when
    `close()` succeeds (it is written to a temporary name first). Identical frames give
    byte-identical files.
    """

    def __init__(self, path, width: int, height: int, fps: float = 30,
                 bitrate: int = 1_000_000, preset: str = "veryfast"):
        w, h = _check_size(width, height, even=True)
        if preset not in _PRESETS:
            raise ValueError(f"preset must be one of {', '.join(_PRESETS)}; got {preset!r}")
        if int(bitrate) <= 0:
            raise ValueError(f"bitrate must be a positive number of bits/s, got {bitrate}")
        self.path = os.fspath(path)
        self.width, self.height, self.fps = w, h, _check_fps(fps)
        self._w = _core.VideoWriter(self.path, w, h, self.fps, int(bitrate), preset, 1)

    def write(self, frames) -> None:
        """Encodes (H, W, 3) or (K, H, W, 3) uint8 RGB frames."""
        self._w.write(_frames(frames, (self.height, self.width, 3), "frames"))

    @property
    def frames_written(self) -> int:
        return self._w.frames_written

    def close(self) -> None:
        """Flushes the encoder and moves the finished file to `path`. Safe to call twice."""
        self._w.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            del self._w  # an interrupted file is deleted, never left half-written
        return False


def _palette(palette) -> np.ndarray:
    if palette is None:
        palette = CITYSCAPES_PALETTE
    p = np.asarray(palette)
    if p.ndim != 2 or p.shape[1] != 3 or not 1 <= p.shape[0] <= 256:
        raise ValueError(f"palette: expected shape (N, 3) with N <= 256, got {p.shape}")
    if p.dtype != np.uint8 and (p.min() < 0 or p.max() > 255):
        raise ValueError("palette: colours must be in 0..255")
    full = np.zeros((256, 3), np.uint8)
    full[: len(p)] = p
    return full


class ApngWriter:
    """8-bit palette-indexed APNG writer; pixel values are CARLA semantic tags.

    Frames are (H, W) or (K, H, W) uint8. Later frames store only the rectangle that
    changed. With `drop_duplicates`, a frame equal to the previous one is not stored and
    the previous frame's delay grows instead (so timing stays right). `palette` is (N, 3),
    N <= 256, padded with black; default: the Cityscapes colours indexed by tag.
    """

    def __init__(self, path, width: int, height: int, palette=None, fps: float = 30,
                 drop_duplicates: bool = False):
        w, h = _check_size(width, height, even=False)
        self.path = os.fspath(path)
        self.width, self.height, self.fps = w, h, _check_fps(fps)
        self.palette = _palette(palette)
        self._w = _core.ApngWriter(self.path, w, h, self.palette, self.fps,
                                   bool(drop_duplicates), 6)

    def write(self, frames) -> None:
        """Appends (H, W) or (K, H, W) uint8 tag frames."""
        self._w.write(_frames(frames, (self.height, self.width), "frames"))

    @property
    def frames_written(self) -> int:
        return self._w.frames_written

    @property
    def frames_stored(self) -> int:
        return self._w.frames_stored

    def close(self) -> None:
        """Stores the last frame, fixes the frame count and moves the file to `path`."""
        self._w.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            del self._w
        return False
