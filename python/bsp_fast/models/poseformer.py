"""PoseFormer (Zheng et al., ICCV 2021): a spatial transformer over the joints of each
frame and a temporal transformer over a window of R frames predicting the centre frame."""
from __future__ import annotations

import torch
from torch import nn

from .. import skeleton as _sk
from .dropout import Dropout
from .base import LiftingModel, check_float, check_int
from .registry import register

__all__ = ["PoseFormer"]

J = _sk.NUM_JOINTS


class DropPath(nn.Module):
    """Stochastic depth: drops a residual branch per sample with probability ``p``."""

    def __init__(self, p: float):
        super().__init__()
        self.p = float(p)

    def forward(self, x):
        if self.p == 0.0 or not self.training:
            return x
        keep = 1.0 - self.p
        mask = x.new_empty((x.shape[0],) + (1,) * (x.ndim - 1)).bernoulli_(keep)
        return x * mask / keep


class _Attention(nn.Module):
    def __init__(self, dim: int, heads: int, attn_drop: float, proj_drop: float):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, dim * 3, bias=True)
        self.proj = nn.Linear(dim, dim)
        self.attn_drop, self.proj_drop = attn_drop, Dropout(proj_drop)

    def forward(self, x):
        B, N, C = x.shape
        q, k, v = self.qkv(x).view(B, N, 3, self.heads, C // self.heads).permute(2, 0, 3, 1, 4)
        out = nn.functional.scaled_dot_product_attention(
            q, k, v, dropout_p=self.attn_drop if self.training else 0.0)
        return self.proj_drop(self.proj(out.transpose(1, 2).reshape(B, N, C)))


class Block(nn.Module):
    """Pre-norm transformer block (timm ``Block``): attention and a GELU MLP, each with
    stochastic depth; LayerNorm eps 1e-6."""

    def __init__(self, dim, heads, mlp_ratio, drop, attn_drop, drop_path):
        super().__init__()
        hidden = int(dim * mlp_ratio)
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = _Attention(dim, heads, attn_drop, drop)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = nn.Sequential(nn.Linear(dim, hidden), nn.GELU(), Dropout(drop),
                                 nn.Linear(hidden, dim), Dropout(drop))
        self.drop_path = DropPath(drop_path)

    def forward(self, x):
        x = x + self.drop_path(self.attn(self.norm1(x)))
        return x + self.drop_path(self.mlp(self.norm2(x)))


@register("lifting", "poseformer",
          "PoseFormer, receptive field 9: spatial transformer (dim 32) per frame, temporal "
          "transformer (dim 832) per window, centre-frame 3D pose; clip edges padded")
class PoseFormer(LiftingModel):
    """Spatial transformer over the 26 joint tokens of a frame (``Linear(2 -> 32)`` + a
    learned joint embedding, ``depth`` blocks, 8 heads, MLP ratio 2), flattened to one
    832-d token per frame; temporal transformer over a window of ``receptive_field`` frames
    (learned frame embedding, ``depth`` blocks of dim 832); stochastic depth 0 -> 0.2;
    ``Conv1d(R -> 1, k=1)`` over the window; head ``LayerNorm -> Linear(832 -> 78)``: the 3D
    pose of the window's centre frame.

    Over a clip of L frames, frame t is predicted from the window centred on it; the clip
    is padded at its edges by replicating its first and last frame ``R//2`` times (as
    VideoPose3D does at test time), so every frame of the clip is predicted and scored like
    every other model's. ``centre_slice(L) = [R//2, L - R//2)`` are the frames whose window
    needs no padding (the only frames the original scored). The spatial transformer runs
    once per frame and the padding replicates its features, identical to padding the 2D
    input (it sees one frame at a time). ``AdamW(4e-4, weight_decay 0.1)`` and
    ``ExponentialLR(0.99)`` per epoch.
    """

    default_lr = 4e-4
    default_weight_decay = 0.1

    def __init__(self, *, receptive_field: int = 9, embed_dim_ratio: int = 32, depth: int = 4,
                 num_heads: int = 8, mlp_ratio: float = 2.0, drop_path_rate: float = 0.2,
                 drop_rate: float = 0.0, attn_drop_rate: float = 0.0, use_visible: bool = False):
        super().__init__(locals())
        check_int("receptive_field", receptive_field)
        if receptive_field % 2 == 0:
            raise ValueError(f"receptive_field must be odd (a centre frame), got "
                             f"{receptive_field}")
        check_int("embed_dim_ratio", embed_dim_ratio)
        check_int("depth", depth)
        check_int("num_heads", num_heads)
        if embed_dim_ratio % num_heads:
            divisors = [d for d in range(1, embed_dim_ratio + 1) if embed_dim_ratio % d == 0]
            raise ValueError(f"num_heads must divide embed_dim_ratio {embed_dim_ratio}: one "
                             f"of {divisors}, got {num_heads}")
        check_float("mlp_ratio", mlp_ratio, 0.0)
        for name in ("drop_path_rate", "drop_rate", "attn_drop_rate"):
            check_float(name, locals()[name], 0.0, 1.0, hi_open=True)
        self._init_visible(use_visible)
        self.receptive_field = R = receptive_field
        c, d = embed_dim_ratio, embed_dim_ratio * J
        self.spatial_embed = nn.Linear(self.in_channels, c)
        self.spatial_pos = nn.Parameter(torch.zeros(1, J, c))
        self.temporal_pos = nn.Parameter(torch.zeros(1, R, d))
        self.pos_drop = Dropout(drop_rate)
        dpr = torch.linspace(0, drop_path_rate, depth).tolist()
        self.spatial_blocks = nn.ModuleList(
            Block(c, num_heads, mlp_ratio, drop_rate, attn_drop_rate, p) for p in dpr)
        self.temporal_blocks = nn.ModuleList(
            Block(d, num_heads, mlp_ratio, drop_rate, attn_drop_rate, p) for p in dpr)
        self.spatial_norm = nn.LayerNorm(c, eps=1e-6)
        self.temporal_norm = nn.LayerNorm(d, eps=1e-6)
        self.weighted_mean = nn.Conv1d(R, 1, kernel_size=1)
        self.head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, J * 3))

    def centre_slice(self, L: int) -> slice:
        """The frames of an L-frame clip whose receptive window lies inside the clip."""
        h = self.receptive_field // 2
        return slice(min(h, L), max(min(h, L), L - h))

    def compute(self, inputs, visible):
        x = self.pose_features(inputs, visible)
        B, L = x.shape[:2]
        R = self.receptive_field
        # spatial: one sequence of J joint tokens per frame
        s = self.pos_drop(self.spatial_embed(x.reshape(B * L, J, -1)) + self.spatial_pos)
        for blk in self.spatial_blocks:
            s = blk(s)
        f = self.spatial_norm(s).reshape(B, L, -1)  # (B, L, J*c)
        h = R // 2  # edge padding: the first / last frame replicated
        f = torch.cat([f[:, :1].expand(B, h, -1), f, f[:, -1:].expand(B, h, -1)], 1)
        # temporal: one window of R frames per predicted frame
        t = f.unfold(1, R, 1).transpose(2, 3).reshape(B * L, R, -1)
        t = self.pos_drop(t + self.temporal_pos)
        for blk in self.temporal_blocks:
            t = blk(t)
        t = self.weighted_mean(self.temporal_norm(t))  # (B*L, 1, d)
        return self.head(t).view(B, L, J, 3)

    def scheduler(self, optimizer, total_steps=None):
        return torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.99), "epoch"
