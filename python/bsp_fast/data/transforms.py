"""Pose transforms of docs/dataset-format.md, "8. What the loaders compute": normalisation,
deformation and augmentation.

Every transform is a small callable over NumPy arrays (torch tensors are accepted and
returned as tensors) of 2D poses ``(..., J, 2)`` in pixels, vectorised over any leading
dimensions, so the datasets apply them to whole batches ``(B, L, J, 2)`` at once and they
work the same on one frame ``(J, 2)`` or one clip ``(L, J, 2)``. The pure functions they
call (normalisation, flips, rotations, bounding boxes) live in
:mod:`bsp_fast.data.functional` and are re-exported here.

Conventions:

* A **missing** joint is exactly ``(0, 0)`` in pixel space (docs/dataset-format.md,
  "8. What the loaders compute"); transforms leave missing joints at ``(0, 0)`` and
  bounding boxes ignore them.
* Random transforms take ``rng`` (a :class:`numpy.random.Generator`, a fresh unseeded one
  when ``None``; the datasets pass a :class:`~bsp_fast.data.clip_random.ClipRandom`, one
  stream per clip of the batch) and draw one decision per **clip**: the clip axes are all dimensions
  before the last three, so ``(B, L, J, 2)`` gets B flips/angles and a single clip
  ``(L, J, 2)`` or frame ``(J, 2)`` gets one. Noise and missing joints are drawn per
  frame, joint (and axis).
* Every random transform also takes keyword context it may ignore (``width`` of the image
  for flips), so :class:`Compose` can pass the same context to all of them.
"""
from __future__ import annotations

import numpy as np

from .functional import (  # noqa: F401  (re-exported: the functional forms live there)
    FALLBACK_SCALE,
    FALLBACK_SHIFT,
    HIPS,
    NECK,
    NormalizedPose,
    FLIP,
    check_points,
    clip_shape,
    keep_visible,
    to_numpy,
    denormalize_hips_neck,
    flip_horizontal,
    flip_rotate,
    joint_bbox,
    normalize_hips_neck,
    normalize_hips_neck_3d,
    rotate,
    visible_joints,
)

__all__ = [
    "HIPS", "NECK", "FALLBACK_SHIFT", "FALLBACK_SCALE", "NormalizedPose",
    "visible_joints", "joint_bbox", "normalize_hips_neck", "denormalize_hips_neck",
    "normalize_hips_neck_3d", "flip_horizontal", "rotate",
    "HipsNeckNormalize", "HipsNeckDenormalize", "GaussianNoise", "MissingJoints", "Deform",
    "HorizontalFlip", "RandomRotation", "RandomFlipRotate", "flip_rotate", "Compose",
]


def _rng(rng) -> np.random.Generator:
    return np.random.default_rng() if rng is None else rng


def _torch():
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency of the loaders
        return None
    return torch


def _normal(rng: np.random.Generator, shape) -> np.ndarray:
    """float32 N(0, 1) of ``shape``, a function of ``rng``'s state. With torch installed the
    numbers come from a torch generator seeded from ``rng`` (2.2x faster than NumPy's
    float32 ziggurat; noise is the largest cost of a deformed batch)."""
    torch = _torch()
    if torch is None or not isinstance(rng, np.random.Generator):  # e.g. ClipRandom
        return rng.standard_normal(shape, dtype=np.float32)
    g = torch.Generator().manual_seed(int(rng.integers(0, 2**63 - 1)))
    return torch.randn(tuple(shape), generator=g, dtype=torch.float32).numpy()


class HipsNeckNormalize:
    """Callable form of :func:`normalize_hips_neck` (returns a :class:`NormalizedPose`)."""

    def __call__(self, points, rng=None, **context) -> NormalizedPose:
        return normalize_hips_neck(points, context.get("visible"))

    def __repr__(self) -> str:
        return "HipsNeckNormalize()"


class HipsNeckDenormalize:
    """Callable inverse: ``HipsNeckDenormalize()(normalized_pose)`` -> pixels."""

    def __call__(self, pose: NormalizedPose, rng=None, **context):
        return denormalize_hips_neck(pose.points, pose.shift, pose.scale, pose.visible)

    def __repr__(self) -> str:
        return "HipsNeckDenormalize()"


class GaussianNoise:
    """Adds N(0, sigma) pixels per frame, joint and axis to the visible joints."""

    def __init__(self, sigma: float = 5.0):
        if not (np.isscalar(sigma) and np.isfinite(sigma) and sigma >= 0):
            raise ValueError(f"sigma must be a finite number >= 0 (pixels), got {sigma!r}")
        self.sigma = float(sigma)

    def __call__(self, points, rng=None, **context):
        p, back = to_numpy(points)
        check_points(p)
        if self.sigma == 0:
            return back(p.copy())
        vis = visible_joints(p)
        noise = _normal(_rng(rng), p.shape)
        noise *= np.float32(self.sigma)
        out = keep_visible(np.add(p, noise, out=noise), vis)
        return back(out)

    def __repr__(self) -> str:
        return f"GaussianNoise(sigma={self.sigma})"


def _probabilities(p, n_joints: int) -> np.ndarray:
    arr = np.asarray(p, np.float64)
    if arr.ndim == 0:
        arr = np.full(n_joints, float(arr))
    if arr.shape != (n_joints,) or not np.all((arr >= 0) & (arr <= 1)):
        raise ValueError(f"missing-joint probability must be one number or {n_joints} numbers "
                         f"in [0, 1], got {p!r}")
    return arr


class MissingJoints:
    """Each joint of each frame goes missing (set to (0, 0)) with probability ``p``.

    ``p`` is one probability for all joints or one per joint (26 numbers).
    """

    def __init__(self, p=0.0, n_joints: int = len(FLIP)):
        self.p = _probabilities(p, n_joints)

    def __call__(self, points, rng=None, **context):
        p, back = to_numpy(points)
        check_points(p)
        if p.shape[-2] != len(self.p):
            raise ValueError(f"points: expected {len(self.p)} joints, got {p.shape[-2]}")
        out = p.copy()
        if np.any(self.p > 0):
            drop = _rng(rng).random(p.shape[:-1], dtype=np.float32) < self.p.astype(np.float32)
            keep_visible(out, ~drop)
        return back(out)

    def __repr__(self) -> str:
        p = self.p[0] if np.all(self.p == self.p[0]) else self.p.tolist()
        return f"MissingJoints(p={p})"


class Compose:
    """Applies transforms in order, passing the same ``rng`` and context to each."""

    def __init__(self, transforms):
        self.transforms = list(transforms)
        for t in self.transforms:
            if not callable(t):
                raise ValueError(f"Compose: {t!r} is not callable")

    def __call__(self, points, rng=None, **context):
        rng = _rng(rng)
        for t in self.transforms:
            points = t(points, rng=rng, **context)
        return points

    def __repr__(self) -> str:
        return f"Compose({self.transforms!r})"


class Deform(Compose):
    """Input deformation of docs/dataset-format.md, "8. What the loaders compute": Gaussian
    noise, then missing joints.

    Same draws and result as ``Compose([GaussianNoise(sigma), MissingJoints(p)])``, with
    one masking pass instead of two.
    """

    def __init__(self, sigma: float = 0.0, p=0.0):
        super().__init__([GaussianNoise(sigma), MissingJoints(p)])

    def __call__(self, points, rng=None, **context):
        p, back = to_numpy(points)
        out, _ = self.apply(p, rng)
        return back(out)

    def apply(self, p: np.ndarray, rng=None, visible=None) -> tuple:
        """NumPy ``(deformed, visible)``; ``visible`` of the input may be given to save a
        pass (the datasets know their stored clips have no missing joint)."""
        noise, missing = self.transforms
        check_points(p)
        if p.shape[-2] != len(missing.p):
            raise ValueError(f"points: expected {len(missing.p)} joints, got {p.shape[-2]}")
        rng = _rng(rng)
        keep = visible_joints(p) if visible is None else np.array(visible, bool)
        if noise.sigma > 0:
            out = _normal(rng, p.shape)
            out *= np.float32(noise.sigma)
            out += p
        else:
            out = p.copy()
        if np.any(missing.p > 0):
            keep &= rng.random(p.shape[:-1], dtype=np.float32) >= missing.p.astype(np.float32)
        return keep_visible(out, keep), keep


class HorizontalFlip:
    """Flips each clip with probability ``p`` about its image centre (see
    :func:`flip_horizontal`). The image ``width`` is fixed here or given per call/clip."""

    def __init__(self, p: float = 0.5, width=None):
        if not 0 <= p <= 1:
            raise ValueError(f"flip probability must lie in [0, 1], got {p!r}")
        self.p, self.width = float(p), width

    def __call__(self, points, rng=None, width=None, **context):
        p, back = to_numpy(points)
        check_points(p)
        w = self.width if width is None else width
        if w is None:
            raise ValueError("HorizontalFlip: the image width is needed (width=...)")
        w = np.broadcast_to(np.asarray(w, np.float32), clip_shape(p))
        flip = _rng(rng).random(clip_shape(p)) < self.p
        if flip.ndim == 0:
            return back(flip_horizontal(p, w) if flip else p.copy())
        out = p.copy()
        if flip.any():  # only the chosen clips
            out[flip] = flip_horizontal(p[flip], w[flip])
        return back(out)

    def __repr__(self) -> str:
        return f"HorizontalFlip(p={self.p}, width={self.width})"


class RandomFlipRotate:
    """``Compose([HorizontalFlip(p), RandomRotation(degrees)])`` in one pass (same
    distribution, ~3x faster): see :func:`flip_rotate`."""

    def __init__(self, p: float = 0.5, degrees: float = 10.0, width=None):
        self.flip = HorizontalFlip(p, width)
        self.rotation = RandomRotation(degrees)

    def __call__(self, points, rng=None, width=None, **context):
        p, back = to_numpy(points)
        check_points(p)
        w = self.flip.width if width is None else width
        if w is None:
            raise ValueError("RandomFlipRotate: the image width is needed (width=...)")
        rng = _rng(rng)
        flip = rng.random(clip_shape(p)) < self.flip.p
        degrees = rng.uniform(-self.rotation.degrees, self.rotation.degrees, clip_shape(p))
        return back(flip_rotate(p, flip, degrees, w))

    def __repr__(self) -> str:
        return f"RandomFlipRotate(p={self.flip.p}, degrees={self.rotation.degrees})"


class RandomRotation:
    """Rotates each clip by an angle uniform in ``[-degrees, degrees]`` about its joint
    bbox centre (docs/dataset-format.md, "8. What the loaders compute": +-10 degrees)."""

    def __init__(self, degrees: float = 10.0):
        if not (np.isfinite(degrees) and degrees >= 0):
            raise ValueError(f"degrees must be a finite number >= 0, got {degrees!r}")
        self.degrees = float(degrees)

    def __call__(self, points, rng=None, **context):
        p, back = to_numpy(points)
        check_points(p)
        angles = _rng(rng).uniform(-self.degrees, self.degrees, clip_shape(p))
        return back(rotate(p, angles))

    def __repr__(self) -> str:
        return f"RandomRotation(degrees={self.degrees})"
