"""PedestrianGraph (Cadena et al., ITSC 2019): a graph convolution over the skeleton,
batched with a dense adjacency matrix (no graph library)."""
from __future__ import annotations

import math

import torch
from torch import nn

from .. import skeleton as _sk
from .dropout import Dropout
from .base import ClassificationModel, check_float, check_int
from .registry import register

__all__ = ["PedestrianGraph", "skeleton_adjacency"]

J = _sk.NUM_JOINTS


def skeleton_adjacency() -> torch.Tensor:
    """``(26, 26)`` 0/1 adjacency of the skeleton's 25 bones in both directions, no
    self-loops."""
    A = torch.zeros(J, J)
    for p, c in _sk.EDGES:
        A[p, c] = A[c, p] = 1.0
    return A


class _DenseGCN(nn.Module):
    """``h_i = b + sum_{j in N(i)} W x_j`` (PyG ``GCNConv(normalize=False,
    add_self_loops=False)``: Glorot weights, zero bias)."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(in_channels, out_channels))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        bound = math.sqrt(6.0 / (in_channels + out_channels))
        nn.init.uniform_(self.weight, -bound, bound)

    def forward(self, x: torch.Tensor, adjacency: torch.Tensor) -> torch.Tensor:
        # (B, L, J, C): A (x W) = (A x) W, so the (J, J) neighbour sum runs on the narrower
        # side (2 channels, not 64, in the first layer: 1.3-1.4x the training step on one
        # AVX2 core, benchmarks/bench_dropout.py); broadcast matmul, no permuted copies
        if self.weight.shape[0] < self.weight.shape[1]:
            return torch.matmul(torch.matmul(adjacency, x), self.weight) + self.bias
        return torch.matmul(adjacency, x @ self.weight) + self.bias


@register("classification", "pedestrian_graph",
          "GCN(2 -> 64 -> 32) over the skeleton per frame, mean over frames and channels, "
          "Linear(26 -> 1)")
class PedestrianGraph(ClassificationModel):
    """``GCNConv(2 -> 64) -> Dropout(0.5) -> ReLU -> GCNConv(64 -> 32) -> Dropout(0.5) ->
    ReLU``, then per joint the mean over frames and channels ``(B, 26)`` and
    ``Linear(26 -> 1)``: one logit per clip (``sigmoid >= 0.5`` = crossing), trained with
    BCE-with-logits. The intended pooling of the original (whose ``view`` mixed joints and
    frames), batched."""

    num_logits = 1
    speed_revision = 1  # CPU dropout mask (models/dropout.py), narrower-side GCN sum

    def __init__(self, *, hidden_channels: int = 64, out_channels: int = 32,
                 dropout: float = 0.5, use_visible: bool = False):
        super().__init__(locals())
        check_int("hidden_channels", hidden_channels)
        check_int("out_channels", out_channels)
        check_float("dropout", dropout, 0.0, 1.0, hi_open=True)
        self._init_visible(use_visible)
        self.register_buffer("adjacency", skeleton_adjacency(), persistent=False)
        self.conv1 = _DenseGCN(self.in_channels, hidden_channels)
        self.conv2 = _DenseGCN(hidden_channels, out_channels)
        self.dropout = Dropout(dropout)
        self.fc = nn.Linear(J, 1)

    def compute(self, inputs, visible):
        x = self.pose_features(inputs, visible)
        h = torch.relu(self.dropout(self.conv1(x, self.adjacency)))
        h = torch.relu(self.dropout(self.conv2(h, self.adjacency)))
        return self.fc(h.mean(dim=(1, 3))).squeeze(-1)  # (B, J) -> (B,)

    def loss(self, output, batch):
        return nn.functional.binary_cross_entropy_with_logits(output.float(),
                                                              batch["targets"].float())
