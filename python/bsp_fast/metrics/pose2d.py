"""2D metrics: PCK (bbox or hips-neck normaliser), missing-joint ratio, masked MSE.

PCK works on ``(..., 26, 2)`` poses in **pixels**. A ground-truth joint counts when it is
present (``visible``, or by default: not exactly ``(0, 0)``, the missing-joint marker) and
finite; the hips (joint 1) always count. A frame whose normaliser is not a finite number
>= 1e-5 pixels is left out and reported in ``PCKCounts.skipped``. A predicted joint that is
NaN/inf is simply not correct.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..skeleton import HIPS, NECK, NUM_JOINTS
from ._arrays import Kind, check_pair, check_points, expect, ratio, shape_of

__all__ = ["pck", "pck_counts", "PCKCounts", "missing_joint_ratio", "masked_mse",
           "missing_joint_ratio_sums", "masked_mse_sums", "NORMS", "MIN_NORMALISER"]

NORMS = ("bbox", "hips_neck")
MIN_NORMALISER = 1e-5
POSES2D = f"(..., {NUM_JOINTS}, 2) in pixels"


class PCKCounts(NamedTuple):
    """Counts behind a PCK value: ``correct / total``."""

    correct: int  #: counted joints within alpha * S of the ground truth
    total: int  #: counted joints (present in the ground truth, in scored frames)
    frames: int  #: frames scored
    skipped: int  #: frames left out (normaliser below 1e-5 px, or undefined)

    @property
    def value(self) -> float:
        return self.correct / self.total if self.total else float("nan")


def _check_options(alpha, norm) -> None:
    if norm not in NORMS:
        raise ValueError(f"norm must be one of {NORMS}, got {norm!r}")
    if not (np.isscalar(alpha) and np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a finite number > 0, got {alpha!r}")


def _pck_terms(pred, gt, alpha, norm, visible):
    """(correct, total, frames, skipped) as arrays/tensors of the inputs' kind."""
    _check_options(alpha, norm)
    s = check_pair(pred, gt, 2, POSES2D, joints=NUM_JOINTS)
    if visible is not None:
        expect(shape_of(visible) == s[:-1], "visible", f"{s[:-1]} (bool, ..., {NUM_JOINTS})",
               f"shape {shape_of(visible)}")
    kind = Kind(pred, gt, visible)
    xp = kind.xp
    p, g = kind.f64(pred), kind.f64(gt)
    present = ((g[..., 0] != 0) | (g[..., 1] != 0)) if visible is None else kind.boolean(visible)
    present = present & kind.isfinite(g).all(-1)
    hips = xp.zeros_like(present)
    hips[..., HIPS] = True
    present = present | hips
    if norm == "bbox":
        inf = float("inf")
        m = present[..., None]
        lo = xp.where(m, g, inf).min(-2) if not kind.torch else xp.where(m, g, inf).amin(-2)
        hi = xp.where(m, g, -inf).max(-2) if not kind.torch else xp.where(m, g, -inf).amax(-2)
        d = hi - lo
        size = xp.sqrt((d * d).sum(-1))
    else:
        d = g[..., NECK, :] - g[..., HIPS, :]
        size = xp.where(present[..., NECK], xp.sqrt((d * d).sum(-1)), float("nan"))
    scored = size >= MIN_NORMALISER  # False for NaN
    counted = present & scored[..., None]
    e = p - g
    hit = xp.sqrt((e * e).sum(-1)) <= alpha * size[..., None]
    correct = (hit & counted).sum()
    frames = scored.sum()
    return correct, counted.sum(), frames, int(np.prod(s[:-2])) - frames


def pck_counts(pred, gt, *, alpha: float = 0.05, norm: str = "bbox",
               visible=None) -> PCKCounts:
    """The counts behind :func:`pck` (correct, total, frames scored, frames skipped)."""
    return PCKCounts(*(int(v) for v in _pck_terms(pred, gt, alpha, norm, visible)))


def pck(pred, gt, *, alpha: float = 0.05, norm: str = "bbox", visible=None):
    """Percentage of correct keypoints, as a fraction in [0, 1].

    A counted joint is correct when ``|pred_j - gt_j| <= alpha * S``; S is the diagonal
    of the ground truth's bounding box over its counted joints (``norm="bbox"``, PCK@0.05)
    or ``|gt_neck - gt_hips|`` (``norm="hips_neck"``, PCKhn@0.1; a frame whose neck is
    absent is left out). ``pred``/``gt`` are ``(..., 26, 2)`` pixels, ``visible``
    ``(..., 26)`` bool marks the ground-truth joints present (default: not ``(0, 0)``).
    NaN when no joint is counted; see :func:`pck_counts` for skipped frames.
    """
    kind = Kind(pred, gt, visible)
    correct, total, _, _ = _pck_terms(pred, gt, alpha, norm, visible)
    return ratio(kind, correct, total)


def missing_joint_ratio_sums(visible):
    """(missing entries, all entries) for :func:`missing_joint_ratio`."""
    s = check_points("visible", visible, shape_of(visible)[-1] if shape_of(visible) else 1,
                     "(..., J) bool", min_ndim=1)
    kind = Kind(visible)
    return (~kind.boolean(visible)).sum(), int(np.prod(s))


def missing_joint_ratio(visible):
    """MJR: the share of (frame, joint) entries of ``visible`` ``(..., J)`` that are
    False, i.e. the missing-joint probability actually realised in a deformed input."""
    kind = Kind(visible)
    missing, total = missing_joint_ratio_sums(visible)
    return ratio(kind, missing, total)


def masked_mse_sums(pred, target, mask=None):
    """(sum of squared errors, number of coordinates) for :func:`masked_mse`."""
    s = shape_of(pred)
    expect(len(s) >= 1 and 0 not in s and shape_of(target) == s, "pred and target",
           "the same non-empty shape (..., J, D)", f"pred {s} and target {shape_of(target)}")
    kind = Kind(pred, target, mask)
    e = kind.f64(pred) - kind.f64(target)
    sq = e * e
    if mask is None:
        return kind.sum(sq), int(np.prod(s))
    m = shape_of(mask)
    expect(m in (s, s[:-1]), "mask", f"{s[:-1]} (per joint) or {s} (per coordinate), bool",
           f"shape {m}")
    keep = kind.boolean(mask)
    if m != s:
        keep = kind.xp.broadcast_to(keep[..., None], tuple(sq.shape))
    return kind.sum(kind.xp.where(keep, sq, 0.0)), int(keep.sum())


def masked_mse(pred, target, mask=None):
    """Mean squared error over the coordinates selected by ``mask`` (per joint
    ``(..., J)`` or per coordinate, bool; None: all). Entries outside the mask are ignored
    even when NaN. NaN when the mask selects nothing."""
    kind = Kind(pred, target, mask)
    return ratio(kind, *masked_mse_sums(pred, target, mask))
