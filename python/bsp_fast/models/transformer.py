"""SimpleTransformer pose autoencoder: one 52-d token per frame, a post-norm
TransformerEncoder, no input projection and no output head."""
from __future__ import annotations

import math

import torch
from torch import nn

from .. import skeleton as _sk
from .dropout import replace_dropout
from .base import AutoencoderModel, check_float, check_int
from .registry import register

__all__ = ["SimpleTransformer", "SimpleTransformerPE", "sinusoidal_encoding"]

J = _sk.NUM_JOINTS
D_MODEL = 2 * J  # 52


def sinusoidal_encoding(length: int, dim: int, device=None, dtype=torch.float32) -> torch.Tensor:
    """``(length, dim)`` sine/cosine positional encoding (Vaswani et al. 2017)."""
    pos = torch.arange(length, device=device, dtype=torch.float64).unsqueeze(1)
    freq = torch.exp(torch.arange(0, dim, 2, device=device, dtype=torch.float64)
                     * (-math.log(10000.0) / dim))
    pe = torch.zeros(length, dim, device=device, dtype=torch.float64)
    pe[:, 0::2] = torch.sin(pos * freq)
    pe[:, 1::2] = torch.cos(pos * freq[: dim // 2])
    return pe.to(dtype)


@register("autoencoder", "simple_transformer",
          "TransformerEncoder(d_model 52, 2 heads, 6 layers, ff 2048) over one token per "
          "frame, no positional encoding (the report's model, ~1.36 M parameters)")
class SimpleTransformer(AutoencoderModel):
    """Each frame's 26 x 2 normalised joints are one 52-d token; ``TransformerEncoder``
    (post-norm, ReLU, dropout 0.1) maps the clip's tokens to the output tokens, reshaped to
    ``(B, L, 26, 2)``. Without positional encoding the model is equivariant to frame order
    (as the report's). ``AdamW(1e-3, weight_decay 1e-2)`` with
    ``CosineAnnealingWarmRestarts(T_0 = 30 epochs, eta_min 1e-8)``.

    ``use_visible=True`` replaces missing joints by a learned per-joint 2-vector (a mask
    token) instead of the dataset's (0, 0), so the model can tell them from a joint at the
    hips without changing the 52-d token.
    """

    default_lr = 1e-3
    default_weight_decay = 1e-2
    positional_encoding = False
    cpu_bf16_faster = True  # training 160 -> 556 clips/s in bf16 autocast (docs/training.md)
    speed_revision = 1  # CPU dropout mask (models/dropout.py): cached probes re-run

    def __init__(self, *, num_layers: int = 6, nhead: int = 2, dim_feedforward: int = 2048,
                 dropout: float = 0.1, use_visible: bool = False):
        super().__init__(locals())
        check_int("num_layers", num_layers)
        check_int("dim_feedforward", dim_feedforward)
        check_float("dropout", dropout, 0.0, 1.0, hi_open=True)
        divisors = [d for d in range(1, D_MODEL + 1) if D_MODEL % d == 0]
        if nhead not in divisors:
            raise ValueError(f"nhead must divide d_model {D_MODEL}: one of {divisors}, "
                             f"got {nhead!r}")
        self._init_visible(use_visible)
        layer = nn.TransformerEncoderLayer(D_MODEL, nhead, dim_feedforward, dropout,
                                           activation="relu", batch_first=True,
                                           norm_first=False)
        self.encoder = nn.TransformerEncoder(layer, num_layers, enable_nested_tensor=False)
        replace_dropout(self.encoder)  # its FF and residual dropouts; attention's stays
        if use_visible:
            self.mask_token = nn.Parameter(torch.zeros(J, 2))

    def compute(self, inputs, visible):
        x = inputs
        if self.use_visible:
            if visible is None:
                raise ValueError(f"{self.name} was built with use_visible=True: pass visible")
            x = torch.where(visible.unsqueeze(-1), inputs, self.mask_token.to(inputs.dtype))
        B, L = x.shape[:2]
        tokens = x.reshape(B, L, D_MODEL)
        if self.positional_encoding:
            tokens = tokens + sinusoidal_encoding(L, D_MODEL, tokens.device, tokens.dtype)
        return self.encoder(tokens).view(B, L, J, 2)

    def scheduler(self, optimizer, total_steps=None):
        return (torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(optimizer, T_0=30,
                                                                     eta_min=1e-8), "epoch")


@register("autoencoder", "simple_transformer_pe",
          "simple_transformer with sinusoidal positional encoding added to the tokens")
class SimpleTransformerPE(SimpleTransformer):
    """:class:`SimpleTransformer` plus a fixed sinusoidal positional encoding of the frame
    index (no extra parameters), so the model can use frame order."""

    positional_encoding = True
