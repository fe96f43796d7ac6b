"""Test data for the pose-estimation models: paints each frame's joints into the crops of a
small HDF5 file, so that a short fit has something to learn.

:func:`bsp_fast.data.testing.write_clip_file` (``media=True``) stores crops that encode the
frame index, not a pedestrian. :func:`paint_joint_crops` overwrites ``frames/rgb`` of a
split with a coloured Gaussian blob per joint (one colour per joint, drawn where the
joint's crop-pixel position is, over a noisy background), consistent with the
``pose_estimation`` targets of :class:`bsp_fast.data.ClipDataset`.
"""
from __future__ import annotations

import colorsys

import numpy as np

from .. import skeleton as _sk

__all__ = ["paint_joint_crops", "JOINT_COLOURS"]

#: One RGB colour per joint (hues around the wheel).
JOINT_COLOURS = np.array([colorsys.hsv_to_rgb(j / _sk.NUM_JOINTS, 0.9, 1.0)
                          for j in range(_sk.NUM_JOINTS)]) * 255


def paint_joint_crops(path, splits=("train", "val", "test"), sigma: float | None = None,
                      noise: float = 12.0, seed: int = 0) -> dict:
    """Rewrites ``frames/rgb`` of ``splits`` in the HDF5 file at ``path`` in place; returns
    ``{split: frames painted}``. ``sigma`` (blob radius, pixels) defaults to S / 24."""
    import h5py

    rng = np.random.default_rng(seed)
    done = {}
    with h5py.File(path, "r+") as f:
        for split in splits:
            g = f[split]
            rgb = g["frames/rgb"]
            F, S = rgb.shape[0], rgb.shape[1]
            uv = g["projection_2d"][()]  # (N, L, J, 2) image pixels
            frames = g["clip_frames"][()]  # (N, L) rows of the frame table
            box = g["frames/crop_box"][()]  # (F, 4)
            pix = np.full((F, _sk.NUM_JOINTS, 2), np.nan)
            pix[frames.reshape(-1)] = uv.reshape(-1, _sk.NUM_JOINTS, 2)
            size = np.stack([box[:, 2] - box[:, 0], box[:, 3] - box[:, 1]], -1)
            crop = (pix - box[:, None, :2]) * (S / size)[:, None, :]
            out = _paint(crop, S, sigma or S / 24, noise, rng)
            rgb[...] = out
            done[split] = F
    return done


def _paint(crop: np.ndarray, S: int, sigma: float, noise: float, rng) -> np.ndarray:
    F = crop.shape[0]
    img = np.full((F, S, S, 3), 60.0) + rng.normal(0, noise, (F, S, S, 3))
    grid = np.arange(S) + 0.5
    for j in range(_sk.NUM_JOINTS):
        x, y = crop[:, j, 0], crop[:, j, 1]
        ok = np.isfinite(x) & np.isfinite(y)
        gx = np.exp(-0.5 * ((grid[None] - np.where(ok, x, -1e3)[:, None]) / sigma) ** 2)
        gy = np.exp(-0.5 * ((grid[None] - np.where(ok, y, -1e3)[:, None]) / sigma) ** 2)
        blob = gy[:, :, None] * gx[:, None, :]  # (F, S, S)
        img = np.maximum(img, blob[..., None] * JOINT_COLOURS[j])
    return np.clip(img, 0, 255).astype(np.uint8)
