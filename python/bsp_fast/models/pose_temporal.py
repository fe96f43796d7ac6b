"""``pose_temporal``: a heatmap network for small pedestrian crops that sees the clip's
neighbouring frames, with sub-pixel decoding by soft-argmax or DARK (issue #38).

Per frame, one encoder-decoder with skip connections (an hourglass: SimpleBaseline's
upsampling path with U-Net skips) turns a uint8 crop ``S x S`` into 26 heatmaps at
``S/2 x S/2``; the only place frames meet is a residual temporal convolution over the
clip at the bottleneck (``temporal="conv"``), so ``temporal="none"`` is exactly the
per-frame network. Decoding (``decode``): the soft-argmax (expected cell centre under a
spatial softmax) or DARK (Zhang et al., CVPR 2020: the heatmap smoothed by a Gaussian,
its logarithm expanded to second order at the maximum and the Newton step taken).

Losses (``loss``): ``integral`` (Sun et al., ECCV 2018: L1 in crop pixels between the
soft-argmax of the heatmaps and the target, whatever ``decode`` is, so that the two
decodings can be compared on one trained network) or ``heatmap`` (MSE against Gaussian
targets centred on the exact sub-pixel joint, DARK's unbiased encoding). Every joint of a
frame with a crop is supervised (the table's protocol scores every joint), the ones its
``visible`` mask hides with weight ``occluded_weight``.

``flip_test`` (evaluation only, off by default): the crops are also decoded mirrored
(``u -> S - u``, the convention of the training flips) and the two predictions averaged
after the mirrored one is mapped back and its left/right joints swapped; the test-time
flip of SimpleBaseline and HRNet, averaged in joint coordinates rather than heatmaps so
that no half-cell shift between mirrored maps needs correcting.
"""
from __future__ import annotations

import math

import torch
from torch import nn
from torch.nn import functional as F

from .. import skeleton as _sk
from .base import (PoseEstimationModel, activation_layout, check_choice, check_float,
                   check_int)
from .pose_cnn import soft_argmax
from .registry import register

__all__ = ["PoseTemporal", "dark_decode", "gaussian_heatmaps", "soft_argmax"]

J = _sk.NUM_JOINTS
_FLIP = tuple(_sk.FLIP_PERMUTATION)  # joint k of a mirrored crop is joint _FLIP[k] here
DECODES = ("soft_argmax", "dark")
LOSSES = ("integral", "heatmap")
TEMPORAL = ("conv", "none")
NORMS = ("group", "batch")
LR_SCHEDULES = ("constant", "cosine")
#: the activations' layout; None: NCHW under bf16 autocast, channels_last otherwise. On
#: CPU GroupNorm's channels_last kernels took 4-14x longer in bf16 (forward + backward)
#: and made a bf16 training step 1.5x slower than NCHW, while in float32 channels_last is
#: ~10 % faster (benchmarks/bench_memory_format.py; docs/performance.md)
MEMORY_FORMAT = None
_MEAN, _STD = 0.45, 0.25  # as pose_cnn: crops scaled to [0, 1], then (x - mean) / std


def _norm2d(kind: str, c: int) -> nn.Module:
    return nn.BatchNorm2d(c) if kind == "batch" else nn.GroupNorm(min(8, c), c)


def _conv_norm(cin: int, cout: int, stride: int, norm: str) -> list:
    return [nn.Conv2d(cin, cout, 3, stride, 1, bias=False), _norm2d(norm, cout),
            nn.ReLU(inplace=True)]


class _Residual(nn.Module):
    """ResNet's basic block: two 3x3 convolutions and the identity."""

    def __init__(self, c: int, norm: str):
        super().__init__()
        self.body = nn.Sequential(*_conv_norm(c, c, 1, norm),
                                  nn.Conv2d(c, c, 3, 1, 1, bias=False), _norm2d(norm, c))

    def forward(self, x):
        return torch.relu(x + self.body(x))


class _TemporalConv(nn.Module):
    """Residual ``[Conv1d(k), norm, ReLU, Conv1d(k)]`` over the frames of each clip at every
    position of a ``(B*L, C, h, w)`` feature map. Clip edges are padded by replicating the
    first and last frame (VideoPose3D's test-time padding), so every frame has a full
    window and frame t sees frames ``t - (k - 1) .. t + (k - 1)`` only. GroupNorm works per
    frame (over the whole clip it would let every frame move every other). The last
    convolution starts small, not zero: the block starts close to the identity and
    gradients still reach its first convolution."""

    def __init__(self, c: int, kernel: int, norm: str):
        super().__init__()
        pad = kernel // 2
        self.conv1 = nn.Conv1d(c, c, kernel, padding=pad, padding_mode="replicate", bias=False)
        self.norm = nn.BatchNorm1d(c) if norm == "batch" else nn.GroupNorm(min(8, c), c)
        self.conv2 = nn.Conv1d(c, c, kernel, padding=pad, padding_mode="replicate")
        nn.init.normal_(self.conv2.weight, std=1e-3)
        nn.init.zeros_(self.conv2.bias)

    def _normalise(self, t: torch.Tensor) -> torch.Tensor:
        if isinstance(self.norm, nn.BatchNorm1d):
            return self.norm(t)
        N, C, L = t.shape
        return self.norm(t.transpose(1, 2).reshape(N * L, C)).view(N, L, C).transpose(1, 2)

    def forward(self, x: torch.Tensor, B: int, L: int) -> torch.Tensor:
        _, C, h, w = x.shape
        t = x.reshape(B, L, C, h * w).permute(0, 3, 2, 1).reshape(B * h * w, C, L)
        y = self.conv2(torch.relu(self._normalise(self.conv1(t))))
        y = y.reshape(B, h * w, C, L).permute(0, 3, 2, 1).reshape(B * L, C, h, w)
        return x + y


def gaussian_heatmaps(centres: torch.Tensor, H: int, W: int, sigma: float) -> torch.Tensor:
    """``(..., 2)`` centres (x, y) in heatmap cells -> ``(..., H, W)`` unnormalised
    Gaussians ``exp(-d^2 / (2 sigma^2))`` of the distance from each cell's centre
    ``(i + 0.5, j + 0.5)`` to the exact, unrounded centre (DARK's unbiased encoding)."""
    xs = torch.arange(W, dtype=centres.dtype, device=centres.device) + 0.5
    ys = torch.arange(H, dtype=centres.dtype, device=centres.device) + 0.5
    gx = torch.exp(-(xs - centres[..., :1]) ** 2 / (2 * sigma ** 2))  # (..., W)
    gy = torch.exp(-(ys - centres[..., 1:]) ** 2 / (2 * sigma ** 2))  # (..., H)
    return gy[..., :, None] * gx[..., None, :]


def _blur_matrix(n: int, sigma: float, dtype, device) -> torch.Tensor:
    """``(n, n)`` matrix of a 1-D Gaussian blur (radius ceil(3 sigma), weights summing to 1)
    with the border replicated: ``M[i, j]`` sums the weights of the taps of output ``i``
    that land on (or are clamped to) input ``j``."""
    r = max(1, math.ceil(3 * sigma))
    t = torch.arange(-r, r + 1, dtype=torch.float64)
    k = torch.exp(-t ** 2 / (2 * sigma ** 2))
    k = k / k.sum()
    src = (torch.arange(n)[:, None] + torch.arange(-r, r + 1)[None, :]).clamp(0, n - 1)
    m = torch.zeros(n, n, dtype=torch.float64).scatter_add_(1, src, k.expand(n, -1).contiguous())
    return m.to(dtype=dtype, device=device)


def _blur(h: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur of ``(N, K, H, W)``, borders replicated (a zero border would
    pull peaks near the edge inwards), as two matrix products: measured 18x faster on a
    CPU than single-channel convolutions of every map (120 frames of 26 maps, 32 x 32)."""
    H, W = h.shape[-2:]
    return (_blur_matrix(H, sigma, h.dtype, h.device) @ h
            @ _blur_matrix(W, sigma, h.dtype, h.device).T)


def dark_decode(heatmaps: torch.Tensor, sigma: float | None = 1.5,
                eps: float = 1e-10) -> torch.Tensor:
    """DARK decoding of ``(N, K, H, W)`` non-negative heatmaps -> ``(N, K, 2)`` (x, y) in
    heatmap cells (cell centres at ``i + 0.5``, as :func:`soft_argmax`).

    The map is smoothed by a Gaussian of ``sigma`` cells (None: not smoothed), its log
    taken, and at the maximum cell the log-map's gradient ``g`` and Hessian ``Hs`` (central
    differences) give the Newton step ``-Hs^-1 g``: exact for a Gaussian peak, whose log is
    a quadratic. Where the Hessian is not negative definite (a flat or saddle-shaped
    maximum) the step is 0, and it is clipped to one cell, so a nearly flat map cannot send
    a joint away from its maximum cell. No gradient flows through the argmax."""
    N, K, H, W = heatmaps.shape
    h = heatmaps.detach().float()
    if sigma:
        h = _blur(h, sigma)
    logh = torch.log(h.clamp_min(eps))
    at = logh.flatten(2).argmax(-1)  # (N, K)
    y0, x0 = at // W, at % W
    # replicated borders: at a maximum on the edge, the missing neighbour repeats it
    pad = F.pad(logh.reshape(N * K, 1, H, W), (1, 1, 1, 1), mode="replicate")
    pad = pad.view(N, K, (H + 2) * (W + 2))

    def val(dy: int, dx: int) -> torch.Tensor:
        idx = (y0 + 1 + dy) * (W + 2) + (x0 + 1 + dx)
        return pad.gather(-1, idx[..., None])[..., 0]

    c = val(0, 0)
    dx, dy = (val(0, 1) - val(0, -1)) / 2, (val(1, 0) - val(-1, 0)) / 2
    dxx, dyy = val(0, 1) - 2 * c + val(0, -1), val(1, 0) - 2 * c + val(-1, 0)
    dxy = (val(1, 1) - val(1, -1) - val(-1, 1) + val(-1, -1)) / 4
    det = dxx * dyy - dxy * dxy
    ok = (dxx < 0) & (det > 1e-12)
    safe = torch.where(ok, det, torch.ones_like(det))
    ox = torch.where(ok, -(dyy * dx - dxy * dy) / safe, torch.zeros_like(det)).clamp(-1, 1)
    oy = torch.where(ok, -(dxx * dy - dxy * dx) / safe, torch.zeros_like(det)).clamp(-1, 1)
    return torch.stack([x0 + 0.5 + ox, y0 + 0.5 + oy], -1)


@register("pose_estimation", "pose_temporal",
          "Hourglass heatmap net for small crops (heatmaps at S/2), temporal convolution "
          "over the clip's frames at the bottleneck, soft-argmax or DARK decoding")
class PoseTemporal(PoseEstimationModel):
    """uint8 crops ``(B, L, 3, S, S)`` (normalised inside) -> joints ``(B, L, 26, 2)`` in
    crop pixels (x right, y down, origin at the crop's top-left corner); S must be a
    multiple of ``2 ** depth``.

    Encoder: a 3x3 stride-2 stem and a residual block (``width`` channels, S/2), then
    ``depth - 1`` stages of a 3x3 stride-2 convolution and a residual block, doubling the
    channels. ``temporal="conv"``: a residual temporal convolution of ``temporal_kernel``
    frames at the bottleneck. Decoder: per stage a 1x1 projection, x2 bilinear upsampling,
    the encoder's feature map of that scale added, a residual block; a 1x1 convolution to
    26 heatmaps at S/2. ``norm``: GroupNorm (default: per frame, so training and evaluation
    compute the same function and frames of a batch never mix) or BatchNorm.
    ``lr_schedule``: ``constant`` (AdamW at its rate throughout) or ``cosine`` (per update,
    from the rate to 0 at the run's last update: ``CosineAnnealingLR`` over the budget).
    """

    default_lr = 1e-3  # Adam's usual rate for heatmap nets trained from scratch
    speed_revision = 1  # NCHW under bf16 (ebfbec9): x1.5 faster bf16 steps than probed before

    def __init__(self, *, width: int = 16, depth: int = 4, temporal: str = "conv",
                 temporal_kernel: int = 5, decode: str = "soft_argmax",
                 loss: str = "integral", sigma: float = 1.5, occluded_weight: float = 1.0,
                 norm: str = "group", lr_schedule: str = "constant", flip_test: bool = False):
        super().__init__(locals())
        check_int("width", width)
        check_int("depth", depth, minimum=2)
        if depth > 6:
            raise ValueError(f"depth must be an integer in [2, 6], got {depth!r}")
        check_choice("temporal", temporal, TEMPORAL)
        check_int("temporal_kernel", temporal_kernel, minimum=1)
        if temporal_kernel % 2 == 0:
            raise ValueError(f"temporal_kernel must be odd (a window centred on each frame), "
                             f"got {temporal_kernel!r}")
        check_choice("decode", decode, DECODES)
        check_choice("loss", loss, LOSSES)
        check_float("sigma", sigma, 0.25, 8.0)
        check_float("occluded_weight", occluded_weight, 0.0, 1.0)
        check_choice("norm", norm, NORMS)
        check_choice("lr_schedule", lr_schedule, LR_SCHEDULES)
        if not isinstance(flip_test, bool):
            raise ValueError(f"flip_test must be true or false, got {flip_test!r}")
        self.lr_schedule, self.flip_test = lr_schedule, flip_test
        self.depth, self.sigma = depth, float(sigma)
        self.decode, self.loss_kind = decode, loss
        self.occluded_weight = float(occluded_weight)
        ch = [width * 2 ** k for k in range(depth)]
        self.stem = nn.Sequential(*_conv_norm(3, ch[0], 2, norm), _Residual(ch[0], norm))
        self.down = nn.ModuleList(
            nn.Sequential(*_conv_norm(ch[k - 1], ch[k], 2, norm), _Residual(ch[k], norm))
            for k in range(1, depth))
        self.temporal = _TemporalConv(ch[-1], temporal_kernel, norm) if temporal == "conv" \
            else None
        self.project = nn.ModuleList(
            nn.Sequential(nn.Conv2d(ch[k], ch[k - 1], 1, bias=False), _norm2d(norm, ch[k - 1]))
            for k in range(depth - 1, 0, -1))
        self.fuse = nn.ModuleList(_Residual(ch[k - 1], norm) for k in range(depth - 1, 0, -1))
        self.head = nn.Conv2d(ch[0], J, 1)
        if loss == "integral":  # the soft-argmax's inverse temperature, learned
            self.log_beta = nn.Parameter(torch.zeros(()))
        self._last = None  # (output, heatmaps, soft-argmax pixels) of the latest forward

    def __getstate__(self):
        # copies and pickles leave out the latest forward's tensors (deepcopy refuses
        # non-leaf tensors, e.g. the precision probe's copy after a training step)
        return dict(self.__dict__, _last=None)

    def scheduler(self, optimizer, total_steps=None):
        if self.lr_schedule == "constant":
            return None, "epoch"
        if not total_steps or total_steps < 1:
            raise ValueError(f"{self.name}: lr_schedule='cosine' ends with the run's budget, "
                             f"which is not known here (total_steps={total_steps!r}): give "
                             "max_steps or a number of epochs")
        return torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=int(total_steps)), \
            "step"

    # ----------------------------------------------------------------- forward
    def heatmaps(self, inputs: torch.Tensor) -> torch.Tensor:
        """``(B, L, 3, S, S)`` uint8 crops -> ``(B*L, 26, S/2, S/2)`` heatmap logits."""
        B, L, _, S, _ = inputs.shape
        if S % 2 ** self.depth:
            raise ValueError(f"{self.name}: the crop size {S} must be a multiple of "
                             f"2**depth = {2 ** self.depth} (depth={self.depth}); e.g. "
                             "crop sizes 64, 96 and 128 with depth 4 or 5")
        x = inputs.reshape(B * L, 3, S, S).contiguous(
            memory_format=activation_layout(MEMORY_FORMAT))
        x = (x.to(torch.get_autocast_dtype("cpu") if torch.is_autocast_enabled("cpu")
                  else torch.float32) * (1.0 / (255 * _STD)) - _MEAN / _STD)
        skips = [self.stem(x)]
        for stage in self.down:
            skips.append(stage(skips[-1]))
        y = skips.pop()
        if self.temporal is not None:
            y = self.temporal(y, B, L)
        for project, fuse, skip in zip(self.project, self.fuse, reversed(skips)):
            y = F.interpolate(project(y), scale_factor=2, mode="bilinear", align_corners=False)
            y = fuse(y + skip)
        return self.head(y)

    def _decode(self, inputs):
        """``(B, L, 3, S, S)`` crops -> (joints ``(B*L, J, 2)`` in crop pixels, heatmap
        logits, the soft-argmax joints or None)."""
        S = inputs.shape[-1]
        logits = self.heatmaps(inputs).float()
        scale = S / logits.shape[-1]  # heatmap cells -> crop pixels
        soft = None
        if self.loss_kind == "integral":
            soft = soft_argmax(logits, self.log_beta.exp()) * scale
        if self.decode == "soft_argmax":
            # a heatmap-loss map is a Gaussian of height ~1, not log-probabilities: its
            # expectation is taken under p ~ max(h, 0) (log, then the softmax undoes it)
            out = soft if soft is not None else \
                soft_argmax(torch.log(logits.clamp_min(1e-6))) * scale
        else:  # DARK on the distribution the network predicts
            maps = (torch.softmax(logits.flatten(2) * self.log_beta.exp(), -1).view_as(logits)
                    if self.loss_kind == "integral" else logits)
            out = dark_decode(maps, self.sigma) * scale
        return out, logits, soft

    def compute(self, inputs, visible):
        B, L, _, S, _ = inputs.shape
        out, logits, soft = self._decode(inputs)
        if self.flip_test and not self.training:
            back = torch.as_tensor(_FLIP, device=out.device)
            mirror = torch.tensor([-1.0, 1.0], device=out.device)
            shift = torch.tensor([float(S), 0.0], device=out.device)

            def unflip(p):  # mirrored-crop joints -> this crop's, left/right swapped back
                return p[:, back] * mirror + shift

            f_out, _, f_soft = self._decode(inputs.flip(-1))
            out = (out + unflip(f_out)) / 2
            if soft is not None:  # the validation loss scores what is reported
                soft = (soft + unflip(f_soft)) / 2
        out = out.view(B, L, J, 2)
        self._last = (out, logits, soft)
        return out

    # ----------------------------------------------------------------- loss
    def _weights(self, target: torch.Tensor, visible) -> torch.Tensor:
        """``(B, L, J)`` per-joint weights: 0 where the target is not finite (a frame
        without a crop), 1 where ``visible``, ``occluded_weight`` elsewhere."""
        present = torch.isfinite(target).all(-1)
        w = present.to(torch.float32)
        if visible is not None:
            w = w * torch.where(visible.bool(), 1.0, self.occluded_weight)
        return w

    def loss(self, output, batch):
        """``integral``: weighted L1 in crop pixels of the soft-argmax joints; ``heatmap``:
        weighted per-joint MSE of the heatmaps against :func:`gaussian_heatmaps` of
        ``sigma`` cells. Needs the forward pass that returned ``output`` (it keeps its
        heatmaps)."""
        if self._last is None or output is not self._last[0]:
            raise ValueError(f"{self.name}: loss(output, batch) needs the output of this "
                             "model's latest forward pass (its heatmaps are kept with it)")
        _, logits, soft = self._last
        target = batch["targets"].float()
        w = self._weights(target, batch.get("visible"))
        # masked targets replaced before any arithmetic: NaN x 0 would poison the gradients
        safe = torch.where(torch.isfinite(target), target, torch.zeros_like(target))
        if self.loss_kind == "integral":
            err = (soft.view_as(safe) - safe).abs().sum(-1)  # (B, L, J) pixels
            return (err * w).sum() / (2 * w.sum()).clamp_min(1)
        H, W = logits.shape[-2:]
        cells = safe * (H / batch["inputs"].shape[-1])
        want = gaussian_heatmaps(cells.view(-1, J, 2), H, W, self.sigma)
        err = (logits - want).pow(2).mean((-2, -1)).view_as(w)
        return (err * w).sum() / w.sum().clamp_min(1)
