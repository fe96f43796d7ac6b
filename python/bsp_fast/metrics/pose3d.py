"""3D joint-position metrics (MPJPE, N-MPJPE, PA-MPJPE, MPJVE) and the lifting helpers.

Inputs are ``(..., J, 3)`` (MPJVE: ``(..., L, J, 3)``) in any length unit; results are in
that unit (the training code passes millimetres). Each ``*_sums`` function returns the
error sum and the number of terms, so a split's value is the ratio of global sums
(:mod:`bsp_fast.metrics.streaming`); the public functions return that ratio. A NaN in an
input makes the result NaN (nothing is silently dropped).
"""
from __future__ import annotations

import numpy as np

from ..skeleton import HIPS
from . import _procrustes
from ._arrays import Kind, check_pair, expect, ratio, shape_of

__all__ = ["mpjpe", "n_mpjpe", "pa_mpjpe", "mpjve", "root_align", "denormalise_lifting",
           "mpjpe_sums", "n_mpjpe_sums", "pa_mpjpe_sums", "mpjve_sums"]

POSES = "(..., J, 3)"
CLIPS = "(..., L, J, 3) with L >= 2"
#: frames per block of the batched Procrustes (NumPy; torch on a GPU takes larger blocks)
CHUNK = 8192


def _norms(kind, d):
    return kind.xp.sqrt((d * d).sum(-1))


def mpjpe_sums(pred, gt):
    """(sum of joint errors, number of joints) for :func:`mpjpe`."""
    s = check_pair(pred, gt, 3, POSES)
    kind = Kind(pred, gt)
    err = _norms(kind, kind.f64(pred) - kind.f64(gt))
    return kind.sum(err), int(np.prod(s[:-1]))


def mpjpe(pred, gt):
    """Mean per-joint position error: the mean Euclidean distance ``|pred_j - gt_j|``
    over all frames and joints."""
    return ratio(Kind(pred, gt), *mpjpe_sums(pred, gt))


def n_mpjpe_sums(pred, gt, root: int = HIPS):
    """(sum of joint errors, number of joints) for :func:`n_mpjpe`."""
    s = check_pair(pred, gt, 3, POSES)
    expect(-s[-2] <= root < s[-2], "root", f"a joint index in [0, {s[-2]})", root)
    kind = Kind(pred, gt)
    p, g = kind.f64(pred), kind.f64(gt)
    # root-relative first (each pose minus its own root): a scale fitted about any other
    # origin also absorbs part of the translation
    p = p - p[..., root:root + 1, :]
    g = g - g[..., root:root + 1, :]
    num, den = (p * g).sum((-1, -2)), (p * p).sum((-1, -2))
    xp = kind.xp
    scale = xp.where(den > 0, num / xp.where(den > 0, den, 1.0), 1.0)
    err = _norms(kind, p * scale[..., None, None] - g)
    return kind.sum(err), int(np.prod(s[:-1]))


def n_mpjpe(pred, gt, root: int = HIPS):
    """MPJPE of root-relative poses (each minus its own joint ``root``, default the hips,
    as VideoPose3D evaluates) after scaling each frame's prediction by the least-squares
    factor ``s = sum <pred_j, gt_j> / sum |pred_j|^2`` (no rotation). An all-zero
    root-relative predicted frame keeps s = 1."""
    return ratio(Kind(pred, gt), *n_mpjpe_sums(pred, gt, root))


def pa_mpjpe_sums(pred, gt, chunk: int | None = None):
    """(sum of joint errors, number of joints) for :func:`pa_mpjpe`."""
    s = check_pair(pred, gt, 3, POSES)
    kind = Kind(pred, gt)
    if kind.torch and kind.device.type == "cpu":  # NumPy is faster on these array sizes
        np_kind = Kind(None)
        p, g = (x.detach().numpy() if hasattr(x, "detach") else np.asarray(x)
                for x in (pred, gt))
        return kind.scalar(_pa_total(np_kind, p, g, chunk or CHUNK)), int(np.prod(s[:-1]))
    return _pa_total(kind, pred, gt, chunk or (CHUNK if not kind.torch else 1 << 18)), \
        int(np.prod(s[:-1]))


def _pa_total(kind, pred, gt, chunk: int):
    """Sum of the Procrustes-aligned joint errors, in blocks of ``chunk`` frames."""
    J = pred.shape[-2]
    p, g = kind.native(pred).reshape(-1, J, 3), kind.native(gt).reshape(-1, J, 3)
    total = None
    for start in range(0, p.shape[0], chunk):
        err = _procrustes.aligned_errors(kind, kind.planes(g, start, start + chunk),
                                         kind.planes(p, start, start + chunk))
        part = kind.sum(err)
        total = part if total is None else total + part
    return total


def pa_mpjpe(pred, gt):
    """MPJPE after the per-frame similarity transform (translation, rotation, uniform
    scale) that best maps the prediction onto the ground truth in the least-squares sense,
    rotations restricted to proper ones (no mirroring). Batched over frames."""
    return ratio(Kind(pred, gt), *pa_mpjpe_sums(pred, gt))


def mpjve_sums(pred, gt):
    """(sum of velocity errors, number of terms) for :func:`mpjve`."""
    s = check_pair(pred, gt, 3, CLIPS, min_ndim=3)
    expect(s[-3] >= 2, "pred and gt", CLIPS, f"shape {s}")
    kind = Kind(pred, gt)
    d = kind.f64(pred) - kind.f64(gt)  # velocity error = first difference of the error
    err = _norms(kind, d[..., 1:, :, :] - d[..., :-1, :, :])
    return kind.sum(err), int(np.prod(s[:-3])) * (s[-3] - 1) * s[-2]


def mpjve(pred, gt):
    """Mean per-joint velocity error: mean ``|dpred_j - dgt_j|`` with ``d`` the first
    difference along the frame axis L, taken inside each clip (the leading axes are
    separate clips; nothing is differenced across them)."""
    return ratio(Kind(pred, gt), *mpjve_sums(pred, gt))


def root_align(pred, gt, root: int = HIPS):
    """``pred`` translated per frame so that its joint ``root`` sits on ``gt``'s
    (``(..., J, D)``; the kind and float dtype of ``pred``; default root: the hips)."""
    s = check_pair(pred, gt, shape_of(pred)[-1] if shape_of(pred) else 3, "(..., J, D)")
    expect(-s[-2] <= root < s[-2], "root", f"a joint index in [0, {s[-2]})", root)
    kind = Kind(pred, gt)
    p, g = kind.native(pred), kind.native(gt)
    if kind.torch:
        p = p if p.is_floating_point() else p.double()
        g = g.to(p.dtype)
    else:
        p = p if np.issubdtype(p.dtype, np.floating) else p.astype(np.float64)
        g = g.astype(p.dtype, copy=False)
    return p - p[..., root:root + 1, :] + g[..., root:root + 1, :]


def denormalise_lifting(pred_norm, gt_m, hips_neck):
    """Lifting output in metres, root-aligned: ``pred_norm`` ``(..., J, 3)`` is
    hips-neck normalised; it is scaled by ``hips_neck`` (metres; per clip ``(B,)`` or per
    frame ``(B, L)``, a prefix of the leading axes, e.g. from
    :func:`bsp_fast.skeleton.hips_neck_length`) and translated so its hips lie on
    ``gt_m``'s hips. Returns the kind of ``pred_norm``."""
    s = check_pair(pred_norm, gt_m, 3, POSES)
    h = shape_of(hips_neck)
    expect(h == s[:len(h)] and len(h) <= len(s) - 2, "hips_neck",
           f"a prefix of the leading axes {s[:-2]} (e.g. (B,) or (B, L))", f"shape {h}")
    kind = Kind(pred_norm, gt_m, hips_neck)
    p, g = kind.native(pred_norm), kind.native(gt_m)
    hn = kind.native(hips_neck)
    if kind.torch:
        hn = hn.to(p.dtype if p.is_floating_point() else kind.xp.float64)
    else:
        hn = hn.astype(np.result_type(p.dtype, np.float32))
    hn = hn.reshape(h + (1,) * (len(s) - len(h)))
    return root_align(p * hn, g, HIPS)
