"""What a model costs: parameters and floating-point operations per clip, counted by
PyTorch itself (``torch.utils.flop_counter.FlopCounterMode``: 2 FLOPs per
multiply-accumulate of matrix products and convolutions; element-wise work such as
normalisation and activations is not counted), for the tables' cost columns."""
from __future__ import annotations

import torch
from torch.utils.flop_counter import FlopCounterMode

__all__ = ["parameter_count", "flops_per_clip"]


def parameter_count(model: torch.nn.Module, trainable_only: bool = False) -> int:
    """Number of parameters (elements), each shared tensor counted once."""
    seen, n = set(), 0
    for p in model.parameters():
        if id(p) in seen or (trainable_only and not p.requires_grad):
            continue
        seen.add(id(p))
        n += p.numel()
    return n


@torch.no_grad()
def flops_per_clip(model: torch.nn.Module, batch: dict) -> float:
    """Forward FLOPs of ``model`` on ``batch`` (a batch dict as the data loaders give),
    divided by the number of clips in it. The model is put in eval mode for the count and
    its mode restored."""
    inputs = batch["inputs"]
    clips = int(inputs.shape[0])
    if clips == 0:
        raise ValueError("flops_per_clip: the batch holds no clip")
    was_training = model.training
    model.eval()
    try:
        with FlopCounterMode(display=False) as counter:
            if hasattr(model, "forward_batch"):
                model.forward_batch(batch)
            else:
                model(inputs)
    finally:
        model.train(was_training)
    return counter.get_total_flops() / clips
