"""Pose operations of docs/dataset-format.md, "8. What the loaders compute" as pure
functions: visibility, joint bounding boxes, hips-neck normalisation (2D and 3D), horizontal
flips and rotations.

They work on NumPy arrays (torch tensors are accepted and returned as tensors) of poses
``(..., J, 2)`` in pixels, vectorised over any leading dimensions. A **missing** joint is
exactly ``(0, 0)`` in pixel space (docs/dataset-format.md, "8. What the loaders compute");
the operations leave missing joints at ``(0, 0)`` and bounding boxes ignore them. The
callable, random versions that the datasets compose live in :mod:`bsp_fast.data.transforms`
(like torchvision's ``transforms`` and ``transforms.functional``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import skeleton as _sk

__all__ = [
    "HIPS", "NECK", "FALLBACK_SHIFT", "FALLBACK_SCALE", "NormalizedPose",
    "visible_joints", "joint_bbox", "normalize_hips_neck", "denormalize_hips_neck",
    "normalize_hips_neck_3d", "denormalize_hips_neck_3d", "flip_horizontal", "rotate",
    "flip_rotate",
]

HIPS, NECK = _sk.HIPS, _sk.NECK
#: Fallback normalisation when hips or neck is missing: shift = bbox centre +
#: (0, FALLBACK_SHIFT * s_b), scale = FALLBACK_SCALE * s_b, s_b = half the bbox height.
FALLBACK_SHIFT = -0.1059
FALLBACK_SCALE = 0.5748
FLIP = np.asarray(_sk.FLIP_PERMUTATION, dtype=np.intp)
_HUGE = 1e37  # penalty that keeps missing joints out of bbox minima/maxima


def to_numpy(x, dtype=np.float32):
    """(array, back): ``back`` turns a NumPy result into the caller's type (torch or NumPy)."""
    if type(x).__module__.startswith("torch"):
        import torch

        dev = x.device
        arr = x.detach().cpu().numpy()
        return np.asarray(arr, dtype=dtype), \
            (lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(dev))
    return np.asarray(x, dtype=dtype), (lambda a: a)


def check_points(p: np.ndarray, dims=(2,), name="points") -> None:
    if p.ndim < 2 or p.shape[-1] not in dims:
        want = " or ".join(f"(..., J, {d})" for d in dims)
        raise ValueError(f"{name}: expected shape {want}, got {p.shape}")


def clip_shape(p: np.ndarray) -> tuple:
    """Shape of the clip axes (one random decision each): all axes before (L, J, D)."""
    return p.shape[:-3] if p.ndim > 3 else ()


def _per_clip(values: np.ndarray, ndim: int) -> np.ndarray:
    """Appends unit axes to per-clip ``values`` so they broadcast against an array of
    ``ndim`` dimensions whose leading axes are the clip axes."""
    values = np.asarray(values)
    return values.reshape(values.shape + (1,) * (ndim - values.ndim))


def keep_visible(out: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Zeroes (in place) the joints where ``keep`` is False. Works plane by plane: NumPy
    broadcasting against the trailing axis of length 2 is ~10x slower."""
    for k in range(out.shape[-1]):
        np.multiply(out[..., k], keep, out=out[..., k])
    return out


def _affine(p: np.ndarray, shift: np.ndarray, factor: np.ndarray, inverse: bool) -> np.ndarray:
    """Per coordinate plane: ``(p - shift) * factor`` or ``p * factor + shift``, with
    ``shift`` ``(..., D)`` per frame and ``factor`` per frame ``(...)`` or joint ``(..., J)``."""
    out = np.empty(p.shape, np.float32)
    f = factor if factor.ndim == p.ndim - 1 else factor[..., None]
    for k in range(p.shape[-1]):
        if inverse:
            np.add(p[..., k] * f, shift[..., k, None], out=out[..., k])
        else:
            np.multiply(p[..., k] - shift[..., k, None], f, out=out[..., k])
    return out


def visible_joints(points) -> np.ndarray:
    """``(..., J)`` bool: True where a joint is not missing (not exactly ``(0, 0)``)."""
    p, _ = to_numpy(points)
    check_points(p)
    return (p[..., 0] != 0) | (p[..., 1] != 0)


def joint_bbox(points, visible=None, per: str = "frame"):
    """``(lo, hi)`` corners ``(..., 2)`` of the visible joints, one box per frame
    (``per="frame"``, boxes ``points.shape[:-2]``) or per clip (``per="clip"``, reduced over
    the frame axis too). Boxes without any visible joint are ``(0, 0)``-``(0, 0)``.
    """
    p, _ = to_numpy(points)
    check_points(p)
    if per not in ("frame", "clip"):
        raise ValueError(f"per must be 'frame' or 'clip', got {per!r}")
    vis = visible_joints(p) if visible is None else np.asarray(visible, bool)
    keep = p.shape[:-2] if per == "frame" else p.shape[:-3]
    # (..., J) planes reduced over their last axis (~20x faster than reducing (..., J, 2)
    # over the joint axis); missing joints pushed out of the way by a huge finite penalty,
    # which is cheaper than np.where(vis, u, inf)
    pen = None if vis.all() else np.multiply(~vis, np.float32(_HUGE), dtype=np.float32)
    corners = []
    for sign, reduce in ((1, np.min), (-1, np.max)):
        c = []
        for k in (0, 1):
            plane = p[..., k] if pen is None else p[..., k] + sign * pen
            c.append(reduce(plane.reshape(keep + (-1,)), axis=-1))
        corners.append(np.stack(c, -1))
    lo, hi = corners
    empty = lo[..., 0] > _HUGE / 2
    lo[empty] = 0
    hi[empty] = 0
    return lo, hi


@dataclass
class NormalizedPose:
    """Result of :func:`normalize_hips_neck`; pixels = ``points * scale + shift``."""

    points: np.ndarray  #: (..., J, 2) normalised; missing joints are (0, 0)
    shift: np.ndarray  #: (..., 2) per-frame shift (hips, or the bbox fallback) in pixels
    scale: np.ndarray  #: (...) per-frame scale in pixels
    visible: np.ndarray  #: (..., J) bool, False for missing joints
    fallback: np.ndarray  #: (...) bool, True where the bbox fallback was used


def normalize_hips_neck(points, visible=None) -> NormalizedPose:
    """Per-frame hips-neck normalisation ``(p - hips) / ||neck - hips||``
    (docs/dataset-format.md, "8. What the loaders compute").

    When hips or neck is missing (or they coincide) the frame falls back to its joint
    bounding box (visible joints only): shift = bbox centre + (0, -0.1059 s_b), scale =
    0.5748 s_b with s_b half the bbox height. A frame without any visible joint, or whose
    fallback box has zero height, gets scale 1 so nothing divides by zero. Missing joints
    stay exactly (0, 0) in the output; :func:`denormalize_hips_neck` with ``visible``
    restores them.
    """
    p, back = to_numpy(points)
    check_points(p)
    vis = visible_joints(p) if visible is None else np.asarray(visible, bool)
    hips, neck = p[..., HIPS, :], p[..., NECK, :]
    dist = np.linalg.norm(neck - hips, axis=-1)
    direct = vis[..., HIPS] & vis[..., NECK] & (dist > 0)
    shift = hips.copy()
    scale = np.array(dist, np.float32)  # an array even for one frame
    fallback = ~direct
    if fallback.any():  # the bbox only for frames that need it
        lo, hi = joint_bbox(p[fallback], vis[fallback])
        s_b = (hi[:, 1] - lo[:, 1]) / 2
        centre = (lo + hi) / 2
        centre[:, 1] += FALLBACK_SHIFT * s_b
        shift[fallback] = centre
        scale[fallback] = FALLBACK_SCALE * s_b
    scale[~(scale > 0)] = 1.0
    inv = np.multiply(vis, (1 / scale)[..., None], dtype=np.float32)  # 0 zeroes missing joints
    out = _affine(p, shift, inv, inverse=False)
    return NormalizedPose(back(out), back(shift), back(scale), back(vis), back(fallback))


def denormalize_hips_neck(points, shift, scale, visible=None):
    """Inverse of :func:`normalize_hips_neck`: ``points * scale + shift``.

    Joints where ``visible`` is False are returned as exactly (0, 0) (missing).
    """
    p, back = to_numpy(points)
    check_points(p)
    s, _ = to_numpy(shift)
    k, _ = to_numpy(scale)
    out = _affine(p, s, k, inverse=True)
    if visible is not None:
        keep_visible(out, to_numpy(visible, bool)[0])
    return back(out)


def normalize_hips_neck_3d(points):
    """3D per-frame ``(p - hips) / ||neck - hips||`` -> ``(normalised, shift, scale)``.

    ``points`` is ``(..., J, 3)`` (metres); 3D targets have no missing joints. A frame with
    coincident hips and neck gets scale 1.
    """
    p, back = to_numpy(points)
    check_points(p, (3,))
    shift = p[..., HIPS, :]
    scale = np.linalg.norm(p[..., NECK, :] - shift, axis=-1)
    scale[~(scale > 0)] = 1.0
    out = _affine(p, shift, (1 / scale).astype(np.float32), inverse=False)
    return back(out), back(shift), back(scale)


def denormalize_hips_neck_3d(points, shift, scale):
    """The inverse of :func:`normalize_hips_neck_3d`: ``points * scale + shift`` per frame.

    ``points`` ``(..., J, 3)``; ``shift`` ``(..., 3)`` (the hips, metres) and ``scale``
    ``(...)`` (the hips-neck length, metres) as returned with the normalised pose, e.g. a
    lifting batch's ``target_shift`` and ``target_scale``. To score a prediction without
    the ground truth's own scale, pass the reference skeleton's length
    (``bsp_fast.skeleton.hips_neck_length``) instead.
    """
    p, back = to_numpy(points)
    check_points(p, (3,))
    shift = np.asarray(to_numpy(shift)[0], np.float32)
    scale = np.asarray(to_numpy(scale)[0], np.float32)
    if shift.shape != p.shape[:-2] + (3,) or scale.shape != p.shape[:-2]:
        raise ValueError(f"shift must have shape {p.shape[:-2] + (3,)} and scale "
                         f"{p.shape[:-2]} for points {p.shape}, got {shift.shape} and "
                         f"{scale.shape}")
    return back(_affine(p, shift, scale, inverse=True))


def flip_horizontal(points, width):
    """Mirror about the image centre (``u -> width - u``) with the joint permutation.

    ``width`` is a number or per-clip array (shape of the clip axes). Missing joints stay
    (0, 0). Flipping twice returns the input.
    """
    p, back = to_numpy(points)
    check_points(p)
    if p.shape[-2] != len(FLIP):
        raise ValueError(f"points: flipping needs {len(FLIP)} joints, got {p.shape[-2]}")
    w = _per_clip(np.asarray(width, np.float32), p.ndim - 1)
    out = np.take(p, FLIP, axis=-2)  # a new array; ~8x faster than p[..., FLIP, :]
    vis = (out[..., 0] != 0) | (out[..., 1] != 0)
    out[..., 0] = np.where(vis, w - out[..., 0], 0)
    return back(out)


def rotate(points, degrees, centre=None):
    """Rotates clips by ``degrees`` (per clip) about ``centre`` (per clip ``(..., 2)``).

    The centre defaults to the clip's joint bbox centre (visible joints of all its frames).
    Positive angles turn from +u towards +v (clockwise on screen, v points down). Missing
    joints stay (0, 0).
    """
    p, back = to_numpy(points)
    check_points(p)
    vis = visible_joints(p)
    if centre is None:
        lo, hi = joint_bbox(p, vis, "clip" if p.ndim >= 3 else "frame")
        centre = (lo + hi) / 2
    c = np.asarray(centre, np.float32)
    c = c.reshape(c.shape[:-1] + (1,) * (p.ndim - c.ndim) + (2,))
    a = np.deg2rad(np.asarray(degrees, np.float64))
    cos = _per_clip(np.cos(a).astype(np.float32), p.ndim - 1)
    sin = _per_clip(np.sin(a).astype(np.float32), p.ndim - 1)
    du, dv = p[..., 0] - c[..., 0], p[..., 1] - c[..., 1]
    out = np.empty_like(p)
    out[..., 0] = c[..., 0] + cos * du - sin * dv
    out[..., 1] = c[..., 1] + sin * du + cos * dv
    keep_visible(out, vis)  # missing joints back to (0, 0)
    return back(out)


def flip_rotate(points, flip, degrees, width):
    """``rotate(flip_horizontal(points, width) if flip else points, degrees)`` per clip, in
    one affine pass (the training augmentation of docs/dataset-format.md,
    "8. What the loaders compute").

    ``flip`` (bool), ``degrees`` and ``width`` are per clip (shape of the clip axes, i.e.
    ``points.shape[:-3]``); the rotation centre is the joint bbox centre of the (flipped)
    clip, which is the mirror of the unflipped clip's centre.
    """
    p, back = to_numpy(points)
    check_points(p)
    clips = clip_shape(p)
    flip = np.broadcast_to(np.asarray(flip, bool), clips)
    w = np.broadcast_to(np.asarray(width, np.float32), clips)
    vis = visible_joints(p)
    lo, hi = joint_bbox(p, vis, "clip" if p.ndim >= 3 else "frame")
    c = (lo + hi) / 2
    c[..., 0] = np.where(flip, w - c[..., 0], c[..., 0])
    if flip.any():  # np.take: ~8x faster than fancy indexing of the joint axis
        if flip.ndim:
            p = p.copy()
            p[flip] = np.take(p[flip], FLIP, axis=-2)
            vis = vis.copy()
            vis[flip] = np.take(vis[flip], FLIP, axis=-1)
        else:
            p, vis = np.take(p, FLIP, axis=-2), np.take(vis, FLIP, axis=-1)
    a = np.deg2rad(np.asarray(degrees, np.float64))
    sign = np.where(flip, -1.0, 1.0)  # mirror u -> w - u folded into the linear part
    cos, sin = np.cos(a), np.sin(a)
    # x' = M (x - c_orig') + c with x' of the flipped point: u_f - c_u = sign * (u - c_u0)
    c0u = np.where(flip, w - c[..., 0], c[..., 0])  # the centre in unflipped coordinates
    m = [sign * cos, -sin, sign * sin, cos]
    t = [c[..., 0] - m[0] * c0u - m[1] * c[..., 1], c[..., 1] - m[2] * c0u - m[3] * c[..., 1]]
    nd = p.ndim - 1
    m = [_per_clip(x.astype(np.float32), nd) for x in m]
    t = [_per_clip(x.astype(np.float32), nd) for x in t]
    out = np.empty_like(p)
    u, v = p[..., 0], p[..., 1]
    out[..., 0] = m[0] * u + m[1] * v + t[0]
    out[..., 1] = m[2] * u + m[3] * v + t[1]
    if not vis.all():
        keep_visible(out, vis)
    return back(out)
