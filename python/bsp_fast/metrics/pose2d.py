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

__all__ = ["pck", "pck_counts", "PCKCounts", "pck_per_joint", "missing_joint_ratio",
           "masked_mse", "missing_joint_ratio_sums", "masked_mse_sums", "NORMS", "ALIGNS",
           "MIN_NORMALISER"]

NORMS = ("bbox", "hips_neck")
ALIGNS = (None, "hips")
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


def _check_options(alpha, norm, align=None) -> None:
    if norm not in NORMS:
        raise ValueError(f"norm must be one of {NORMS}, got {norm!r}")
    if align not in ALIGNS:
        raise ValueError(f"align must be one of {ALIGNS}, got {align!r}")
    if not (np.isscalar(alpha) and np.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a finite number > 0, got {alpha!r}")


def _pck_terms(pred, gt, alpha, norm, visible, select=None, align=None, per_joint=False):
    """(correct, total, frames, skipped) as arrays/tensors of the inputs' kind; with
    ``per_joint`` correct and total are ``(26,)``."""
    _check_options(alpha, norm, align)
    s = check_pair(pred, gt, 2, POSES2D, joints=NUM_JOINTS)
    for name, m in (("visible", visible), ("select", select)):
        if m is not None:
            expect(shape_of(m) == s[:-1], name, f"{s[:-1]} (bool, ..., {NUM_JOINTS})",
                   f"shape {shape_of(m)}")
    kind = Kind(pred, gt, visible, select)
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
    if select is not None:
        counted = counted & kind.boolean(select)
    if align == "hips":  # the prediction's hips onto the true hips; the hips then say nothing
        p = p - p[..., HIPS:HIPS + 1, :] + g[..., HIPS:HIPS + 1, :]
        not_hips = xp.ones_like(counted)
        not_hips[..., HIPS] = False
        counted = counted & not_hips
    e = p - g
    hit = xp.sqrt((e * e).sum(-1)) <= alpha * size[..., None]
    frames = scored.sum()
    if per_joint:
        return ((hit & counted).reshape(-1, NUM_JOINTS).sum(0),
                counted.reshape(-1, NUM_JOINTS).sum(0), frames, int(np.prod(s[:-2])) - frames)
    correct = (hit & counted).sum()
    return correct, counted.sum(), frames, int(np.prod(s[:-2])) - frames


def pck_counts(pred, gt, *, alpha: float = 0.05, norm: str = "bbox",
               visible=None, select=None, align=None) -> PCKCounts:
    """The counts behind :func:`pck` (correct, total, frames scored, frames skipped)."""
    return PCKCounts(*(int(v) for v in _pck_terms(pred, gt, alpha, norm, visible, select,
                                                  align)))


def pck_per_joint(pred, gt, *, alpha: float = 0.05, norm: str = "bbox", visible=None,
                  select=None, align=None) -> np.ndarray:
    """PCK of each of the 26 joints (``(26,)`` float64 NumPy, NaN where a joint is never
    counted), with :func:`pck`'s rules."""
    kind = Kind(pred, gt, visible, select)
    correct, total, _, _ = _pck_terms(pred, gt, alpha, norm, visible, select, align, True)
    c, t = (np.asarray(x.cpu() if kind.torch else x, np.float64) for x in (correct, total))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(t > 0, c / np.maximum(t, 1), np.nan)


def pck(pred, gt, *, alpha: float = 0.05, norm: str = "bbox", visible=None, select=None,
        align=None):
    """Percentage of correct keypoints, as a fraction in [0, 1].

    A counted joint is correct when ``|pred_j - gt_j| <= alpha * S``; S is the diagonal
    of the ground truth's bounding box over its counted joints (``norm="bbox"``, PCK@0.05)
    or ``|gt_neck - gt_hips|`` (``norm="hips_neck"``, PCKhn@0.1; a frame whose neck is
    absent is left out). ``pred``/``gt`` are ``(..., 26, 2)`` pixels, ``visible``
    ``(..., 26)`` bool marks the ground-truth joints present (default: not ``(0, 0)``).
    ``select`` ``(..., 26)`` bool counts only those of the present joints (the normaliser
    still comes from every present joint): e.g. the visible or the occluded ones.
    ``align="hips"`` translates the prediction so its hips lie on the true hips before
    comparing (the report's hips-aligned protocol); the hips are then not counted.
    NaN when no joint is counted; see :func:`pck_counts` for skipped frames.
    """
    kind = Kind(pred, gt, visible, select)
    correct, total, _, _ = _pck_terms(pred, gt, alpha, norm, visible, select, align)
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
