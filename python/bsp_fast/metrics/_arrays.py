"""NumPy / torch plumbing shared by the metric functions.

Every metric takes NumPy arrays or torch tensors and answers in the same kind: a NumPy
float64 scalar for arrays, a 0-d float64 tensor (on the input's device) for tensors.
:class:`Kind` looks at the inputs once and converts them; when NumPy and torch inputs are
mixed, everything becomes a tensor on the device of the first tensor. Metrics never take
gradients: tensors are detached.
"""
from __future__ import annotations

import numpy as np


def is_torch(x) -> bool:
    return type(x).__module__.startswith("torch")


def shape_of(x) -> tuple:
    return tuple(np.shape(x)) if not is_torch(x) else tuple(x.shape)


class Kind:
    """The array library (``np`` or ``torch``) and device the inputs ``xs`` live on."""

    def __init__(self, *xs):
        first = next((x for x in xs if x is not None and is_torch(x)), None)
        self.torch = first is not None
        if self.torch:
            import torch

            self.xp = torch
            self.device = first.device
        else:
            self.xp = np
            self.device = None

    def f64(self, x):
        """``x`` as float64 of this kind (a detached copy only when needed)."""
        if not self.torch:
            return np.asarray(x, dtype=np.float64)
        torch = self.xp
        if is_torch(x):
            return x.detach().to(device=self.device, dtype=torch.float64)
        return torch.as_tensor(np.asarray(x, dtype=np.float64), device=self.device)

    def boolean(self, x):
        if not self.torch:
            return np.asarray(x, dtype=bool)
        torch = self.xp
        if is_torch(x):
            return x.detach().to(device=self.device, dtype=torch.bool)
        return torch.as_tensor(np.asarray(x, dtype=bool), device=self.device)

    def native(self, x):
        """``x`` of this kind without changing its dtype."""
        if not self.torch:
            return np.asarray(x)
        if is_torch(x):
            return x.detach().to(self.device)
        return self.xp.as_tensor(np.asarray(x), device=self.device)

    def scalar(self, value):
        """A float64 result of this kind from a 0-d array/tensor or a Python number."""
        if not self.torch:
            return np.float64(value)
        torch = self.xp
        if is_torch(value):
            return value.to(torch.float64)
        return torch.tensor(float(value), dtype=torch.float64, device=self.device)

    def planes(self, x, start: int = 0, stop: int | None = None):
        """Frames ``[start, stop)`` of ``x`` ``(F, J, D)`` as contiguous float64 coordinate
        planes ``(D, J, n)`` (frame axis last; one converting copy)."""
        part = x[start:stop]
        if not self.torch:
            out = np.empty((part.shape[2], part.shape[1], part.shape[0]))
            out[...] = part.transpose(2, 1, 0)
            return out
        return part.permute(2, 1, 0).to(self.xp.float64).contiguous()

    def dot(self, a, b):
        """Sum over the first axis of ``a * b`` (joints of ``(J, n)`` planes)."""
        if not self.torch:
            return np.einsum("j...,j...->...", a, b)
        return (a * b).sum(0)

    def sum(self, x):
        """Sum of all entries as a float64 0-d value."""
        return x.sum() if self.torch else np.sum(x, dtype=np.float64)

    def isfinite(self, x):
        return self.xp.isfinite(x)


def ratio(kind: Kind, total, count):
    """``total / count`` in float64 as a result of ``kind``; NaN when ``count`` is 0."""
    count = float(count)
    if count == 0:
        return kind.scalar(float("nan"))
    if is_torch(total):
        return kind.scalar(total.to(kind.xp.float64) / count)
    return kind.scalar(np.float64(total) / count)


def expect(cond: bool, what: str, expected: str, got) -> None:
    if not cond:
        raise ValueError(f"{what}: expected {expected}, got {got}")


def check_points(name: str, x, dims: int, expected: str, min_ndim: int = 2,
                 joints: int | None = None) -> tuple:
    """Shape of ``x`` after checking it is ``(..., J, dims)`` with at least ``min_ndim``
    axes, no empty axis and (optionally) ``joints`` joints."""
    s = shape_of(x)
    ok = len(s) >= min_ndim and s[-1] == dims and 0 not in s
    if joints is not None:
        ok = ok and s[-2] == joints
    expect(ok, name, expected, f"shape {s}")
    return s


def check_pair(pred, gt, dims: int, expected: str, min_ndim: int = 2,
               joints: int | None = None) -> tuple:
    """Checks ``pred`` and ``gt`` are both ``(..., J, dims)`` with the same shape."""
    s = check_points("pred", pred, dims, expected, min_ndim, joints)
    g = check_points("gt", gt, dims, expected, min_ndim, joints)
    expect(s == g, "pred and gt", f"the same shape {expected}",
           f"pred {s} and gt {g}")
    return s
