"""Dropout whose CPU mask costs a few bits per element instead of a per-element Bernoulli
draw.

PyTorch's CPU ``bernoulli_(p)`` (what ``nn.Dropout`` draws its mask with) takes MKL's
vectorised generator only on Intel CPUs; elsewhere (the AMD EPYC machines this project
runs on) it draws element by element: 31 ms for the 1.7 M activations of one
PedestrianGraph layer at batch 64, 40 % of the model's training step, 28 % of
SimpleTransformer's, 13 % of 3DPoseBaseline's (``benchmarks/bench_dropout.py``). Here the
mask comes from numpy's PCG64 stream, each raw 64-bit output cut into four 16-bit (or two
32-bit) uniform integers compared with a threshold, the stream seeded by one draw from
torch's generator, so ``torch.manual_seed`` (and Lightning's ``seed_everything``) still
fixes it, and it is the same on every (little-endian) CPU, thread count and vendor (MKL's
and the fallback's masks differ).

The keep probability is exactly ``1 - thr / 2**bits`` with ``thr = round(p * 2**bits)``:
``p`` itself when ``p * 65536`` is an integer (0.5, 0.25, ...), otherwise within
``2**-33`` of it (32 bits); kept values are scaled by its inverse, so the expectation is
the input's exactly, as ``nn.Dropout``'s. On other devices, under ``torch.compile`` and in
eval mode it is ``nn.Dropout``.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch
from torch import nn

__all__ = ["Dropout", "replace_dropout", "keep_mask"]


def keep_mask(shape, p: float) -> tuple[torch.Tensor, float]:
    """``(keep, scale)``: a bool tensor of ``shape``, True with probability ``1 - p``
    (quantised as the module docstring says), and ``1 / P(keep)``."""
    bits = 16 if float(p * 65536).is_integer() else 32
    thr = int(round(p * 2.0 ** bits))
    # one draw from torch's default generator seeds the stream: the mask is a function of
    # torch's RNG state, like nn.Dropout's
    seed = int(torch.randint(0, 2 ** 62, (1,)))
    n = int(np.prod(shape, dtype=np.int64))
    words = np.random.PCG64(seed).random_raw(-(-n * bits // 64))  # raw 64-bit outputs
    u = words.view(np.uint16 if bits == 16 else np.uint32)[:n]  # 4 or 2 lanes per word
    keep = torch.from_numpy(u >= thr).view(tuple(shape))
    return keep, 2.0 ** bits / (2.0 ** bits - thr)


class Dropout(nn.Dropout):
    """``nn.Dropout`` with the CPU mask drawn by :func:`keep_mask` (same parameters, same
    state dict: none)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if (not self.training or self.p == 0.0 or x.device.type != "cpu"
                or torch.compiler.is_compiling()):
            return super().forward(x)
        keep, scale = keep_mask(x.shape, self.p)
        if _holds(scale, x.dtype):
            mask = keep.to(x.dtype).mul_(scale)  # one scaled mask: the fastest form
            return x.mul_(mask) if self.inplace else x * mask
        # bf16 / fp16 cannot hold 1 / 0.9: scale in float32 as torch's own scalar product
        # (and nn.Dropout) does, not by a rounded 1.109 (a 0.16 % bias)
        kept = x.mul_(keep) if self.inplace else x * keep
        return kept.mul_(scale)


@lru_cache(maxsize=None)
def _holds(scale: float, dtype: torch.dtype) -> bool:
    """Whether a mask of ``dtype`` can hold ``scale`` as torch's scalar product applies it
    (float32 and float64 compute with it in float32 / float64 anyway); once per (p, dtype),
    not a tensor per forward."""
    return dtype in (torch.float32, torch.float64) or float(
        torch.tensor(scale, dtype=dtype)) == scale


def replace_dropout(module: nn.Module) -> nn.Module:
    """Swaps every plain ``nn.Dropout`` below ``module`` (e.g. inside
    ``nn.TransformerEncoderLayer``) for :class:`Dropout` of the same ``p``; returns
    ``module``."""
    for name, child in module.named_children():
        if type(child) is nn.Dropout:
            setattr(module, name, Dropout(child.p, inplace=child.inplace))
        else:
            replace_dropout(child)
    return module
