"""MP4 (H.264) and segmentation APNG: writers for the dataset generator, readers for loaders.

The pixel index of a segmentation APNG is the CARLA 0.9.13 semantic tag; the palette holds
the Cityscapes colours (docs/dataset-format.md, "3. Media"), so viewers show colours while
readers get tags.
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


class _Writer:
    """Shared life cycle of the writers: the file appears under `path` only on close()."""

    _w = None  # the core writer

    @property
    def frames_written(self) -> int:
        return self._w.frames_written

    def close(self) -> None:
        """Finishes the file and moves it to `path`. Safe to call twice."""
        self._w.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            del self._w  # an interrupted file is deleted, never left half-written
        return False


class VideoWriter(_Writer):
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


class ApngWriter(_Writer):
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
    def frames_stored(self) -> int:
        return self._w.frames_stored


# ---------------------------------------------------------------- readers


def _indices(indices, n: int) -> np.ndarray:
    """1-D int64 frame indices; range errors are left to the core, which names the file."""
    if isinstance(indices, slice):
        return np.arange(n, dtype=np.int64)[indices]
    a = np.asarray(indices)
    if a.ndim > 1:
        raise ValueError(f"indices: expected a 1-D sequence of frame numbers, got shape {a.shape}")
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"indices: expected integers, got dtype {a.dtype}")
    return np.ascontiguousarray(a.reshape(-1), dtype=np.int64)


class VideoReader:
    """Threaded H.264/MP4 decoder returning RGB frames.

    ``len(reader)`` is the exact number of shown frames; frame k is the k-th frame displayed.
    ``read(indices)`` returns (K, H, W, 3) uint8 in the order asked (repeats allowed),
    decoding forward and converting only the requested frames; ``crop=(x, y, w, h)`` cuts
    the picture before the colour conversion. Iterating yields (H, W, 3) frames in order.
    Errors raise ``bsp_fast.VideoDecodeError`` naming the file and the frame.
    """

    def __init__(self, path, threads: int = 0):
        if int(threads) < 0:
            raise ValueError(f"threads must be >= 0 (0 = one per core), got {threads}")
        self.path = os.fspath(path)
        self._r = _core.VideoReader(self.path, int(threads))

    def __len__(self) -> int:
        return self._r.frame_count

    @property
    def fps(self) -> float:
        return self._r.fps

    @property
    def size(self) -> tuple:
        """(width, height) in pixels."""
        return (self._r.width, self._r.height)

    @property
    def codec(self) -> str:
        return self._r.codec

    def read(self, indices, crop=None) -> np.ndarray:
        """Frames `indices` as (K, H, W, 3) uint8 RGB; `crop` = (x, y, width, height)."""
        if crop is not None:
            crop = tuple(int(v) for v in crop)
            if len(crop) != 4:
                raise ValueError(f"crop must be (x, y, width, height), got {crop}")
        return self._r.read(_indices(indices, len(self)), crop)

    def read_crops(self, indices, crops) -> np.ndarray:
        """One crop per frame, all of the same size: crops is (K, 4) of (x, y, w, h)."""
        idx = _indices(indices, len(self))
        boxes = np.asarray(crops, dtype=np.int64).reshape(-1, 4)
        if len(boxes) != len(idx) or (len(boxes) and (boxes[:, 2:] != boxes[0, 2:]).any()):
            raise ValueError("read_crops: need one (x, y, w, h) per index, all the same size")
        if not len(idx):
            return np.empty((0, 0, 0, 3), np.uint8)
        out = np.empty((len(idx), int(boxes[0, 3]), int(boxes[0, 2]), 3), np.uint8)
        for i in np.argsort(idx, kind="stable"):  # forward order: one decoding pass
            out[i] = self._r.read(idx[i:i + 1], tuple(int(v) for v in boxes[i]))[0]
        return out

    def __getitem__(self, k: int) -> np.ndarray:
        return self._r.read(_indices([k], len(self)), None)[0]

    def __iter__(self):
        # Batches overlap decoding with conversion; 8 frames keep the result in cache.
        n, step = len(self), 8
        for start in range(0, n, step):
            yield from self._r.read(np.arange(start, min(start + step, n)), None)


class ApngReader:
    """Our APNG decoder: exact frames of animated (and plain) 8-bit PNGs.

    For palette files (all CARLA-BSP segmentations) ``read`` returns the palette INDICES,
    i.e. the semantic tags, as (K, H, W) uint8; grey files give (K, H, W), RGB/RGBA and grey
    with alpha (K, H, W, C). Frames are composited with their dispose and blend ops.
    ``delays`` are the seconds each frame is shown; ``video_to_apng_frames`` maps video frame
    numbers to APNG frames for files that dropped duplicate frames.
    Errors raise ``bsp_fast.ApngError`` naming the file, the frame and the reason.
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self._r = _core.ApngReader(self.path)

    def __len__(self) -> int:
        return self._r.frame_count

    @property
    def size(self) -> tuple:
        """(width, height) in pixels."""
        return (self._r.width, self._r.height)

    @property
    def indexed(self) -> bool:
        return self._r.indexed

    @property
    def channels(self) -> int:
        return self._r.channels

    @property
    def palette(self):
        """(N, 3) uint8 palette, or None."""
        return self._r.palette

    @property
    def delays(self) -> np.ndarray:
        """Seconds each frame is shown (fcTL delay_num / delay_den)."""
        return np.asarray(self._r.delays, dtype=np.float64)

    @property
    def dispose_ops(self) -> np.ndarray:
        """fcTL dispose_op per frame: 0 NONE, 1 BACKGROUND, 2 PREVIOUS."""
        return np.asarray(self._r.dispose_ops, dtype=np.uint8)

    @property
    def blend_ops(self) -> np.ndarray:
        """fcTL blend_op per frame: 0 SOURCE, 1 OVER."""
        return np.asarray(self._r.blend_ops, dtype=np.uint8)

    def read(self, indices) -> np.ndarray:
        return self._r.read(_indices(indices, len(self)))

    def __getitem__(self, k: int) -> np.ndarray:
        return self._r.read(_indices([k], len(self)))[0]

    def __iter__(self):
        # Batches let decoding run ahead on a second thread; ~8 MB keeps them in cache.
        w, h = self.size
        n, step = len(self), max(1, (8 << 20) // (w * h * self.channels))
        for start in range(0, n, step):
            yield from self._r.read(np.arange(start, min(start + step, n)))

    def video_to_apng_frames(self, n_video_frames: int, fps: float) -> np.ndarray:
        """(n_video_frames,) int64: the APNG frame on screen at time k / fps, by cumulative
        delays; -1 for video frames after the animation's total duration."""
        if int(n_video_frames) < 0:
            raise ValueError(f"n_video_frames must be >= 0, got {n_video_frames}")
        return np.asarray(self._r.video_to_apng_frames(int(n_video_frames), _check_fps(fps)),
                          dtype=np.int64)


def video_to_apng_frames(apng, n_video_frames: int, fps: float) -> np.ndarray:
    """Module-level form of :meth:`ApngReader.video_to_apng_frames` (path or reader)."""
    reader = apng if isinstance(apng, ApngReader) else ApngReader(apng)
    return reader.video_to_apng_frames(n_video_frames, fps)


__all__ = ["TAG_NAMES", "CITYSCAPES_PALETTE", "VideoWriter", "ApngWriter", "VideoReader",
           "ApngReader", "video_to_apng_frames"]
