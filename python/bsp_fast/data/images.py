"""Pedestrian crops for pose estimation: float conversion with mean/std, and augmentation
that moves the joints with the pixels.

Crops are ``(..., S, S, 3)`` uint8 as stored (channels last); joints are ``(..., 26, 2)``
in crop pixels (pixel ``i`` covers ``[i, i + 1)``, so a horizontal flip maps ``u`` to
``S - u``). Everything runs in torch on whole batches.
"""
from __future__ import annotations

import numpy as np

from .._extras import require

torch = require("torch")
import torch.nn.functional as F  # noqa: E402

from .. import skeleton as _sk

__all__ = ["IMAGE_DTYPES", "ImageAugment", "to_float_images", "check_image_options",
           "BoxNoise", "recrop"]

IMAGE_DTYPES = ("uint8", "float32")
_FLIP = np.asarray(_sk.FLIP_PERMUTATION, dtype=np.intp)
_GREY = (0.299, 0.587, 0.114)


def check_image_options(image_dtype: str, mean, std) -> tuple:
    """Validates the image options; returns ``(dtype, mean, std)`` with mean/std as
    (3,) float32 arrays or None. Giving mean/std implies ``float32``."""
    if image_dtype not in IMAGE_DTYPES:
        raise ValueError(f"image_dtype must be one of {list(IMAGE_DTYPES)}, got {image_dtype!r}")
    if (mean is None) != (std is None):
        raise ValueError("mean and std go together (per channel, on the [0, 1] scale)")
    if mean is None:
        return image_dtype, None, None
    m = np.broadcast_to(np.asarray(mean, np.float32), (3,)).copy()
    s = np.broadcast_to(np.asarray(std, np.float32), (3,)).copy()
    if not (np.all(np.isfinite(m)) and np.all(s > 0)):
        raise ValueError(f"mean must be finite and std positive, got {mean!r}, {std!r}")
    return "float32", m, s


def to_float_images(rgb, channels_last: bool, mean=None, std=None) -> np.ndarray:
    """uint8 crops -> float32 channels-first ``(..., 3, S, S)`` on [0, 1], then
    ``(x - mean) / std`` per channel when given."""
    t = torch.as_tensor(rgb)
    if channels_last:
        t = t.movedim(-1, -3)
    x = t.to(torch.float32).div_(255.0)
    if mean is not None:
        m = torch.from_numpy(np.asarray(mean, np.float32)).view(3, 1, 1)
        s = torch.from_numpy(np.asarray(std, np.float32)).view(3, 1, 1)
        x = x.sub_(m).div_(s)
    return x.contiguous().numpy()


class ImageAugment:
    """Random flip, scale, shift and colour jitter of crops, with the joints moved along.

    Per clip (all frames alike): a horizontal flip with probability ``flip_p`` (pixels
    mirrored, ``u -> S - u``, joints permuted left/right, visibility with them); a zoom by
    a factor uniform in ``[1 - scale, 1 + scale]`` about the crop centre; a shift uniform
    in ``[-shift, shift] * S`` per axis; brightness, contrast and saturation factors uniform
    in ``[1 - color_jitter, 1 + color_jitter]``; a rotation about the crop centre by an
    angle uniform in ``[-rotation, rotation]`` degrees (positive: from +u towards +v, as
    :func:`~bsp_fast.data.functional.rotate`; drawn last and only when ``rotation > 0``, so
    the other draws of a clip do not change with it). Pixels are resampled bilinearly
    (masks: nearest), what falls outside the crop is zero; joints that leave the crop
    become invisible.
    """

    def __init__(self, flip_p: float = 0.5, scale: float = 0.1, shift: float = 0.05,
                 color_jitter: float = 0.2, rotation: float = 0.0):
        for name, v, hi in (("flip_p", flip_p, 1.0), ("scale", scale, 0.9),
                            ("shift", shift, 0.5), ("color_jitter", color_jitter, 1.0),
                            ("rotation", rotation, 180.0)):
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and 0 <= v <= hi):
                raise ValueError(f"{name} must lie in [0, {hi}], got {v!r}")
        self.flip_p, self.scale, self.shift = float(flip_p), float(scale), float(shift)
        self.color_jitter, self.rotation = float(color_jitter), float(rotation)

    def __repr__(self) -> str:
        return (f"ImageAugment(flip_p={self.flip_p}, scale={self.scale}, shift={self.shift}, "
                f"color_jitter={self.color_jitter}, rotation={self.rotation})")

    def __call__(self, rgb, joints, visible, mask=None, *, rng: np.random.Generator):
        """``rgb`` (N, K, S, S, 3) uint8 (N clips of K frames), ``joints`` (N, K, J, 2),
        ``visible`` (N, K, J), ``mask`` (N, K, S, S) or None. Returns ``(rgb, joints,
        visible, mask)`` with ``rgb`` as float32 CHANNELS-FIRST (N, K, 3, S, S) on the 0-255
        scale (round it for uint8)."""
        N, K, S = rgb.shape[0], rgb.shape[1], rgb.shape[2]
        flip = rng.random(N) < self.flip_p
        zoom = 1 + rng.uniform(-self.scale, self.scale, N)
        move = rng.uniform(-self.shift, self.shift, (N, 2)) * S
        jitter = 1 + rng.uniform(-self.color_jitter, self.color_jitter, (N, 3))
        angle = (np.deg2rad(rng.uniform(-self.rotation, self.rotation, N)) if self.rotation
                 else np.zeros(N))
        cos, sin = np.cos(angle), np.sin(angle)
        # joints: q' = zoom * R (flip(q) - c + move) + c; pixels, in [-1, 1] units, the
        # inverse: output p maps to input flip(R^T (p - c) / zoom + c - move)
        theta = np.zeros((N, 2, 3), np.float32)
        sign = np.where(flip, -1.0, 1.0)
        theta[:, 0, 0] = sign * cos / zoom
        theta[:, 0, 1] = sign * sin / zoom
        theta[:, 0, 2] = -sign * 2 * move[:, 0] / S
        theta[:, 1, 0] = -sin / zoom
        theta[:, 1, 1] = cos / zoom
        theta[:, 1, 2] = -2 * move[:, 1] / S
        grid = F.affine_grid(torch.from_numpy(np.repeat(theta, K, 0)), (N * K, 3, S, S),
                             align_corners=False)
        x = torch.from_numpy(np.ascontiguousarray(rgb)).reshape(N * K, S, S, 3)
        x = F.grid_sample(x.permute(0, 3, 1, 2).float(), grid, mode="bilinear",
                          padding_mode="zeros", align_corners=False)
        if self.color_jitter > 0:
            x = _jitter(x, torch.from_numpy(np.repeat(jitter, K, 0).astype(np.float32)))
        if mask is not None:
            m = torch.from_numpy(np.ascontiguousarray(mask)).reshape(N * K, 1, S, S).float()
            m = F.grid_sample(m, grid, mode="nearest", padding_mode="zeros", align_corners=False)
            mask = m.reshape(N, K, S, S).round().to(torch.uint8).numpy()
        j = np.array(joints, np.float32, copy=True)
        v = np.array(visible, bool, copy=True)
        j[flip], v[flip] = j[flip][..., _FLIP, :], v[flip][..., _FLIP]
        j[flip, ..., 0] = S - j[flip, ..., 0]
        c = S / 2
        j = (j - c + move[:, None, None, :].astype(np.float32)) \
            * zoom[:, None, None, None].astype(np.float32)
        if self.rotation:
            r = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], -2)
            j = np.einsum("nab,nkjb->nkja", r.astype(np.float32), j)
        j = j + c
        v &= np.all((j >= 0) & (j <= S), -1)
        return x.reshape(N, K, 3, S, S).numpy(), j, v, mask


def _jitter(x: torch.Tensor, f: torch.Tensor) -> torch.Tensor:
    """Brightness, contrast, saturation factors ``f`` (M, 3) on (M, 3, S, S) 0-255 images."""
    w = torch.tensor(_GREY).view(1, 3, 1, 1)
    x = x * f[:, 0].view(-1, 1, 1, 1)
    grey_mean = (x * w).sum(1, keepdim=True).mean((2, 3), keepdim=True)
    x = (x - grey_mean) * f[:, 1].view(-1, 1, 1, 1) + grey_mean
    grey = (x * w).sum(1, keepdim=True)
    x = grey + (x - grey) * f[:, 2].view(-1, 1, 1, 1)
    return x.clamp_(0, 255)


class BoxNoise:
    """Detector-like errors of a crop box: its side times a factor uniform in
    ``[1 - scale, 1 + scale]`` and its centre moved by ``[-shift, shift]`` times the
    (original) side per axis, independently per frame (docs/data.md, "Box noise").
    ``BoxNoise(0.1, 0.05)`` is the evaluation's stated size. Boxes are ``(..., 4)``
    ``[u0, v0, u1, v1]`` squares in image pixels; NaN boxes (no crop) stay NaN."""

    def __init__(self, scale: float = 0.0, shift: float = 0.0):
        for name, v, hi in (("scale", scale, 0.5), ("shift", shift, 0.5)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= hi:
                raise ValueError(f"box noise {name} must lie in [0, {hi}], got {v!r}")
        self.scale, self.shift = float(scale), float(shift)

    def __bool__(self) -> bool:
        return self.scale > 0 or self.shift > 0

    def __repr__(self) -> str:
        return f"BoxNoise(scale={self.scale}, shift={self.shift})"

    def __call__(self, boxes, rng: np.random.Generator) -> np.ndarray:
        """Noisy copies of ``boxes`` (float64), drawn from ``rng`` (3 uniforms per box, in
        box order: scale, shift u, shift v)."""
        b = np.asarray(boxes, np.float64)
        u = rng.uniform(-1.0, 1.0, b.shape[:-1] + (3,))
        side = b[..., 2] - b[..., 0]
        centre = (b[..., :2] + b[..., 2:]) / 2 + u[..., 1:] * self.shift * side[..., None]
        half = side * (1 + u[..., 0] * self.scale) / 2
        return np.concatenate([centre - half[..., None], centre + half[..., None]], -1)


def recrop(context, context_box, boxes, size: int) -> np.ndarray:
    """Cuts ``boxes`` ``(N, 4)`` (image pixels, any real square) out of the stored context
    crops ``context`` ``(N, C, C, 3)`` uint8 whose boxes are ``context_box`` ``(N, 4)``:
    bilinear resampling to ``size`` x ``size``, zeros outside the context (as outside the
    image). Returns ``(N, size, size, 3)`` uint8."""
    c = torch.from_numpy(np.ascontiguousarray(context)).permute(0, 3, 1, 2).float()
    cb = torch.as_tensor(np.asarray(context_box, np.float64))
    b = torch.as_tensor(np.asarray(boxes, np.float64))
    # output pixel centre (i + 0.5) / size of the box -> image -> context pixels -> [-1, 1]
    t = (torch.arange(size, dtype=torch.float64) + 0.5) / size
    side, cside = b[:, 2] - b[:, 0], cb[:, 2] - cb[:, 0]
    x = (b[:, :1] + t * side[:, None] - cb[:, :1]) / cside[:, None] * 2 - 1  # (N, size)
    y = (b[:, 1:2] + t * side[:, None] - cb[:, 1:2]) / cside[:, None] * 2 - 1
    grid = torch.stack([x[:, None, :].expand(-1, size, -1), y[:, :, None].expand(-1, -1, size)], -1)
    out = F.grid_sample(c, grid.float(), mode="bilinear", padding_mode="zeros", align_corners=False)
    return out.round_().clamp_(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
