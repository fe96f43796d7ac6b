"""A small CNN trained from scratch on the converter's pedestrian crops: per-frame
features -> a temporal GRU -> 26 x 2 joints in crop pixels."""
from __future__ import annotations

import torch
from torch import nn

from .. import skeleton as _sk
from .dropout import Dropout
from .base import (PoseEstimationModel, activation_layout, check_choice, check_float,
                   check_int)
from .registry import register

__all__ = ["PoseCNN", "soft_argmax"]

J = _sk.NUM_JOINTS
HEADS = ("regression", "heatmap")
NORMS = ("group", "batch")
TEMPORAL = ("gru", "none")
#: the activations' layout: channels_last, as the table's runs were trained (NCHW measured
#: x1.08 faster in bf16 here, against pose_temporal's x1.53: benchmarks/bench_memory_format.py)
MEMORY_FORMAT = torch.channels_last
_MEAN, _STD = 0.45, 0.25  # crops are scaled to [0, 1], then (x - mean) / std


def _conv(cin: int, cout: int, stride: int = 1, norm: str = "group") -> list:
    layer = (nn.GroupNorm(min(8, cout), cout) if norm == "group" else nn.BatchNorm2d(cout))
    return [nn.Conv2d(cin, cout, 3, stride, 1, bias=False), layer, nn.ReLU(inplace=True)]


def soft_argmax(heatmaps: torch.Tensor, beta: torch.Tensor | float = 1.0) -> torch.Tensor:
    """``(N, K, H, W)`` scores -> ``(N, K, 2)`` expected (x, y) in heatmap cells under a
    spatial softmax (``beta`` = inverse temperature); cell centres at ``i + 0.5``."""
    N, K, H, W = heatmaps.shape
    p = torch.softmax((heatmaps * beta).float().flatten(2), -1).view(N, K, H, W)
    xs = torch.arange(W, device=p.device, dtype=p.dtype) + 0.5
    ys = torch.arange(H, device=p.device, dtype=p.dtype) + 0.5
    return torch.stack([(p.sum(2) * xs).sum(-1), (p.sum(3) * ys).sum(-1)], -1)


@register("pose_estimation", "pose_cnn",
          "From-scratch CNN on 128x128 crops (4 stride-2 stages), per-frame features -> "
          "bidirectional GRU -> 26 x 2 joints in crop pixels")
class PoseCNN(PoseEstimationModel):
    """uint8 crops ``(B, L, 3, S, S)`` (normalised inside) -> joints ``(B, L, 26, 2)`` in crop
    pixels (x right, y down, origin at the crop's top-left corner).

    Backbone per frame: a stride-2 3x3 stem (``width`` channels) and three stages of
    ``[3x3 stride 2, 3x3]`` convolutions with GroupNorm (``norm="batch"``: BatchNorm) and
    ReLU (2, 4, 8 x ``width`` channels; S/16 at the end). Heads:

    * ``regression``: the last stage pooled to 4 x 4, flattened, ``Linear ->
      hidden``; a bidirectional GRU over the clip's frames (residual) and ``Linear(hidden ->
      52)``, coordinates as fractions of the crop added to an anchor (the crop centre, or
      the mean training skeleton after ``init_from_baseline``);
    * ``heatmap`` (default: it learnt faster, docs/models.md): a 1x1 convolution of the
      stride-8 stage to 26 heatmaps, a soft-argmax (learned temperature) per joint; the GRU adds a per-frame correction (near zero at
      initialisation) from the pooled features and the soft-argmax coordinates.

    ``temporal="none"`` drops the GRU (frames independent). Loss: MSE in crop pixels over
    the visible joints (``batch["visible"]``).
    """

    def __init__(self, *, width: int = 32, hidden: int = 256, head: str = "heatmap",
                 temporal: str = "gru", norm: str = "group", dropout: float = 0.0):
        super().__init__(locals())
        check_int("width", width)
        check_int("hidden", hidden, minimum=2)
        check_choice("head", head, HEADS)
        check_choice("temporal", temporal, TEMPORAL)
        check_choice("norm", norm, NORMS)
        check_float("dropout", dropout, 0.0, 1.0, hi_open=True)
        w = width
        self.head_kind, self.temporal_kind = head, temporal
        self.stem = nn.Sequential(*_conv(3, w, 2, norm))
        self.stage1 = nn.Sequential(*_conv(w, 2 * w, 2, norm), *_conv(2 * w, 2 * w, 1, norm))
        self.stage2 = nn.Sequential(*_conv(2 * w, 4 * w, 2, norm), *_conv(4 * w, 4 * w, 1, norm))
        self.stage3 = nn.Sequential(*_conv(4 * w, 8 * w, 2, norm), *_conv(8 * w, 8 * w, 1, norm))
        self.pool = nn.AdaptiveAvgPool2d(4)
        self.embed = nn.Sequential(nn.Flatten(), Dropout(dropout),
                                   nn.Linear(8 * w * 16, hidden), nn.ReLU(inplace=True))
        if head == "heatmap":
            self.heatmap = nn.Conv2d(4 * w, J, 1)
            self.log_beta = nn.Parameter(torch.zeros(()))
            self.mix = nn.Linear(hidden + 2 * J, hidden)
        if temporal == "gru":
            self.gru = nn.GRU(hidden, hidden // 2, batch_first=True, bidirectional=True)
        self.out = nn.Linear(hidden, 2 * J)
        # small, not zero: the heatmap head's correction starts near zero and gradients
        # still reach the layers before it from the first step
        nn.init.normal_(self.out.weight, std=1e-3)
        nn.init.zeros_(self.out.bias)
        # where the regression head starts, as fractions of the crop: the centre, or the
        # mean training skeleton once init_from_baseline has seen it
        self.register_buffer("anchor", torch.full((J, 2), 0.5))

    def init_from_baseline(self, baseline) -> None:
        """Regression head: start at the mean training crop skeleton (the trivial baseline,
        PCK@0.05 about 0.5 on CARLA-BSP crops) instead of the crop centre."""
        S = getattr(baseline, "crop_size", 0)
        if self.head_kind == "regression" and S and getattr(baseline, "fitted", False):
            self.anchor.copy_(baseline.pose / S)

    def compute(self, inputs, visible):
        B, L, _, S, _ = inputs.shape
        x = inputs.reshape(B * L, 3, S, S)  # a view for the datasets' channels-last crops
        x = x.contiguous(memory_format=activation_layout(MEMORY_FORMAT))
        x = (x.to(torch.get_autocast_dtype("cpu") if torch.is_autocast_enabled("cpu")
                  else torch.float32) * (1.0 / (255 * _STD)) - _MEAN / _STD)
        f2 = self.stage2(self.stage1(self.stem(x)))
        feats = self.embed(self.pool(self.stage3(f2)))  # (B*L, hidden)
        if self.head_kind == "heatmap":
            beta = self.log_beta.exp()
            uv = soft_argmax(self.heatmap(f2), beta) / f2.shape[-1]  # fractions of the crop
            feats = torch.relu(self.mix(torch.cat([feats, uv.flatten(1).to(feats.dtype)], 1)))
        h = feats.view(B, L, -1)
        if self.temporal_kind == "gru":
            h = h + self.gru(h)[0]
        out = self.out(h).view(B, L, J, 2).float()
        out = out + (uv.view(B, L, J, 2) if self.head_kind == "heatmap" else self.anchor)
        return out * S
