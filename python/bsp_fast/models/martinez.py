"""3DPoseBaseline (Martinez et al., ICCV 2017): a residual MLP lifting each frame."""
from __future__ import annotations

from torch import nn

from .. import skeleton as _sk
from .dropout import Dropout
from .base import LiftingModel, check_float, check_int
from .registry import register

__all__ = ["Baseline3D"]

J = _sk.NUM_JOINTS


def _unit(size: int, dropout: float) -> list:
    return [nn.Linear(size, size), nn.BatchNorm1d(size), nn.ReLU(), Dropout(dropout)]


class _Residual(nn.Module):
    def __init__(self, size: int, dropout: float):
        super().__init__()
        self.layers = nn.Sequential(*_unit(size, dropout), *_unit(size, dropout))

    def forward(self, x):
        return x + self.layers(x)


@register("lifting", "baseline_3d",
          "Martinez 3DPoseBaseline per frame: Linear(52 -> 1024), 2 residual blocks, "
          "Linear(1024 -> 78)")
class Baseline3D(LiftingModel):
    """``Linear(52 -> 1024) -> BN -> ReLU -> Dropout(0.5)``, ``num_blocks`` residual blocks
    of ``[Linear(1024, 1024) -> BN -> ReLU -> Dropout] x 2 + skip``, ``Linear(1024 -> 78)``;
    Kaiming-normal weights. Frames are independent (BatchNorm over all frames of the
    batch)."""

    cpu_bf16_faster = True  # training 206 -> 533 clips/s in bf16 autocast (docs/training.md)
    speed_revision = 1  # CPU dropout mask (models/dropout.py): cached probes re-run

    def __init__(self, *, linear_size: int = 1024, num_blocks: int = 2, dropout: float = 0.5,
                 use_visible: bool = False):
        super().__init__(locals())
        check_int("linear_size", linear_size)
        check_int("num_blocks", num_blocks, minimum=0)
        check_float("dropout", dropout, 0.0, 1.0, hi_open=True)
        self._init_visible(use_visible)
        self.net = nn.Sequential(
            nn.Linear(J * self.in_channels, linear_size), nn.BatchNorm1d(linear_size),
            nn.ReLU(), Dropout(dropout),
            *[_Residual(linear_size, dropout) for _ in range(num_blocks)],
            nn.Linear(linear_size, J * 3))
        for m in self.modules():
            if isinstance(m, nn.Linear):
                nn.init.kaiming_normal_(m.weight)

    def compute(self, inputs, visible):
        x = self.pose_features(inputs, visible)
        B, L = x.shape[:2]
        return self.net(x.reshape(B * L, -1)).view(B, L, J, 3)
