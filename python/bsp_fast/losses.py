"""Training losses of the 2D and 3D pose tasks (torch, differentiable).

See docs/metrics.md. Both are means over the selected coordinates of a batch, computed
in the inputs' dtype.
"""
from __future__ import annotations

import torch

from .skeleton import HIPS, NECK

__all__ = ["loc_2d", "loc_3d"]


def _check(pred, target, dims: int, expected: str) -> None:
    ok = (pred.ndim >= 2 and pred.shape == target.shape and pred.shape[-1] == dims
          and pred.numel() > 0)
    if not ok:
        raise ValueError(f"pred and target: expected the same non-empty shape {expected}, "
                         f"got pred {tuple(pred.shape)} and target {tuple(target.shape)}")


def loc_2d(pred: torch.Tensor, target: torch.Tensor, present=None) -> torch.Tensor:
    """MSE of normalised 2D joints ``(..., J, 2)`` over the joints present in the target.

    ``present`` ``(..., J)`` bool marks the target joints that exist (e.g. the target's
    ``visible``); the hips (joint 1) are always kept, since normalisation puts them at
    ``(0, 0)``, the missing-joint marker. ``None``: every joint. Squared errors are averaged
    over the kept coordinates; entries outside the mask never reach the result or its
    gradient (even NaN ones).
    """
    _check(pred, target, 2, "(..., J, 2)")
    if present is None:
        return torch.mean((pred - target) ** 2)
    present = torch.as_tensor(present, device=pred.device)
    if tuple(present.shape) != tuple(pred.shape[:-1]):
        raise ValueError(f"present: expected {tuple(pred.shape[:-1])} (bool, ..., J), "
                         f"got shape {tuple(present.shape)}")
    keep = present.to(torch.bool).clone()
    keep[..., HIPS] = True
    keep = keep[..., None].expand(pred.shape)
    diff = torch.where(keep, pred - torch.where(keep, target, pred.detach()), 0.0)
    return (diff * diff).sum() / keep.sum()


def loc_3d(pred: torch.Tensor, target: torch.Tensor, *, normalise: bool = True) -> torch.Tensor:
    """MSE of 3D joints ``(..., J, 3)``.

    ``normalise=True``: both poses are first expressed in the target's per-frame
    hips-neck frame, ``(p - target_hips) / |target_neck - target_hips|`` (the normaliser
    comes from the target only, so it carries no gradient). For targets that are already
    hips-neck normalised (the lifting dataset's ``targets``) this is the identity, so the
    loss is the plain MSE in normalised units; metre targets get the same normalised loss.
    ``normalise=False``: plain MSE on the given coordinates.
    """
    if not isinstance(normalise, bool):
        raise ValueError(f"normalise must be True or False, got {normalise!r}")
    _check(pred, target, 3, "(..., J, 3)")
    if normalise:
        hips = target[..., HIPS:HIPS + 1, :].detach()
        scale = torch.linalg.vector_norm(target[..., NECK, :] - target[..., HIPS, :], dim=-1)
        scale = torch.where(scale > 0, scale, torch.ones_like(scale)).detach()[..., None, None]
        pred, target = (pred - hips) / scale, (target - hips) / scale
    return torch.mean((pred - target) ** 2)
