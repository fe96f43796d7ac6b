"""``FrameDataset``: single pedestrian crops for per-frame pose estimation.

The items are the frames of a split's frame table (``frames/*``, written by ``bsp-convert``
with media) that at least one clip uses, in table order; each comes with its 26 joints in
crop pixels (from the first clip that holds the frame), their visibility and the crop box.
"""
from __future__ import annotations

import numpy as np

from . import images as I
from .base import Rows, SplitDataset, plain
from .datasets import MEDIA_DATASETS, pose_crops

__all__ = ["FrameDataset"]

_META_STR = ("video_id", "pedestrian_id", "age", "gender")


class FrameDataset(SplitDataset):
    """One split's pedestrian crops, one frame per item.

    ``inputs`` (3, S, S) crop (uint8, or float32 with ``image_dtype``/``mean``/``std``),
    ``targets`` (26, 2) joints in crop pixels, ``visible`` (26,), ``crop_box`` (4,),
    ``mask`` (S, S) with ``with_mask``, ``pixels`` (26, 2) image pixels with
    ``with_pixels``; ``meta``: ``frame`` (row of the frame table), ``frame_idx``,
    ``clip_row`` and ``clip_frame`` (where the joints come from), ``video_id``,
    ``pedestrian_id``, ``age``, ``gender``. ``augment`` (default: True for ``train``) flips,
    zooms, shifts, rotates and colour-jitters each crop with its joints (``flip_p``,
    ``image_scale``, ``image_shift``, ``image_rotation`` (degrees, default 0),
    ``color_jitter``). Seeds, ``transform``/``target_transform``,
    ``ds[i]``/``ds[list]`` and ``loader()`` work as in :class:`ClipDataset`.
    """

    task = "pose_estimation"

    def __init__(self, h5_path, split: str = "train", *, augment: bool | None = None,
                 flip_p: float = 0.5, image_scale: float = 0.1, image_shift: float = 0.05,
                 color_jitter: float = 0.2, image_dtype: str = "uint8", mean=None, std=None,
                 seed: int | None = None, with_mask: bool = False, with_pixels: bool = False,
                 indices=None, transform=None, target_transform=None,
                 image_rotation: float = 0.0):
        self._init_common(h5_path, split, seed, transform, target_transform)
        self.image_dtype, self.mean, self.std = I.check_image_options(image_dtype, mean, std)
        self.augment = split == "train" if augment is None else bool(augment)
        self._augment = I.ImageAugment(flip_p, image_scale, image_shift, color_jitter,
                                       image_rotation)
        self.with_mask, self.with_pixels = bool(with_mask), bool(with_pixels)
        self._read_header(indices)

    def _read_header(self, indices) -> None:
        from ..conversion.vds import open_clip_file

        with open_clip_file(self.h5_path) as f:
            if int(f.attrs.get("schema_version", -1)) != 1 or self.split not in f:
                raise ValueError(f"{self.h5_path}: not a schema-1 bsp-convert file with "
                                 f"/{self.split}")
            g = f[self.split]
            need = list(MEDIA_DATASETS) + ["projection_2d", "frames/frame_idx"]
            need += [f"meta/{k}" for k in _META_STR] + (["frames/mask"] if self.with_mask else [])
            missing = [n for n in need if n not in g]
            if missing:
                raise ValueError(f"{self.h5_path}: /{self.split} lacks {missing} (convert with "
                                 "media=True, i.e. without --no-media)")
            self.attrs = {k: plain(v) for k, v in f.attrs.items()}
            clip_frames = g["clip_frames"][()]
            self._frame_idx = g["frames/frame_idx"][()].astype(np.int64)
            self._meta = {k: g[f"meta/{k}"].asstr()[()].astype(object) for k in _META_STR}
        # every used frame once, with the first (clip, position) that holds it
        flat = clip_frames.reshape(-1)
        frames, first = np.unique(flat, return_index=True)
        L = max(clip_frames.shape[1], 1)
        self._clip, self._pos = first // L, first % L
        n = len(frames)
        rows = np.arange(n) if indices is None else np.asarray(indices, np.int64)
        if rows.ndim != 1 or (len(rows) and (rows.min() < 0 or rows.max() >= n)):
            raise ValueError(f"indices must be a 1-D list of items in [0, {n}) of /{self.split}")
        self._frames, self._rows = frames, rows

    def __repr__(self) -> str:
        return (f"FrameDataset({self.h5_path!r}, split={self.split!r}, frames={len(self)}, "
                f"augment={self.augment}, image_dtype={self.image_dtype!r})")

    def _arrays(self, pos, rows, rng) -> tuple:
        frames = self._frames[rows]
        clips, at = self._clip[rows], self._pos[rows]
        fr = Rows(frames)
        rgb = fr.read(self._dataset("frames/rgb"))[:, None]  # (B, 1, S, S, 3)
        box = fr.read(self._dataset("frames/crop_box"))[:, None]
        vis = (fr.read(self._dataset("frames/joint_visible")) != 0)[:, None]
        mask = fr.read(self._dataset("frames/mask"))[:, None] if self.with_mask else None
        pixels = Rows(clips).read(self._dataset("projection_2d"))[np.arange(len(clips)), at]
        out, channels_last = pose_crops(rgb, box, pixels[:, None], vis, mask, self, rng)
        out = {k: v[:, 0] for k, v in out.items()}
        if self.with_pixels:
            out["pixels"] = pixels
        meta = dict(frame=frames, frame_idx=self._frame_idx[frames], clip_row=clips,
                    clip_frame=at)
        strings = {k: self._meta[k][clips].tolist() for k in _META_STR}
        return out, meta, strings, channels_last
