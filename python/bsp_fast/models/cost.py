"""What a model costs: parameters and floating-point operations per clip, counted by
PyTorch itself (``torch.utils.flop_counter.FlopCounterMode``: 2 FLOPs per
multiply-accumulate of matrix products and convolutions; element-wise work such as
normalisation and activations is not counted), for the tables' cost columns.

Two gaps of the counter are closed here: the fused CPU kernels of ``nn.LSTM``/``nn.GRU``
are invisible to it (counted 0), so their matrix products are added from the layer shapes
(2 FLOPs x gates x hidden x (input + hidden) per step, layer and direction); and
``nn.TransformerEncoderLayer``'s inference fast path is counted 0, so it is switched off
while counting (the same products run on the ordinary path), and the CPU attention kernel
gets the counter's own attention formula."""
from __future__ import annotations

import torch
from torch.utils.flop_counter import FlopCounterMode, sdpa_flop_count

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
    recurrent = [0]
    hooks = [m.register_forward_hook(_recurrent_flops(recurrent)) for m in model.modules()
             if isinstance(m, (torch.nn.LSTM, torch.nn.GRU))]
    fastpath = torch.backends.mha.get_fastpath_enabled()
    torch.backends.mha.set_fastpath_enabled(False)
    try:
        with FlopCounterMode(display=False, custom_mapping=_CPU_ATTENTION) as counter:
            if hasattr(model, "forward_batch"):
                model.forward_batch(batch)
            else:
                model(inputs)
    finally:
        torch.backends.mha.set_fastpath_enabled(fastpath)
        for h in hooks:
            h.remove()
        model.train(was_training)
    return (counter.get_total_flops() + recurrent[0]) / clips


def _cpu_attention_flops(query_shape, key_shape, value_shape, *args, out_shape=None,
                         **kwargs) -> int:
    """The CPU attention kernel, which the counter has no formula for: its two products."""
    return sdpa_flop_count(query_shape, key_shape, value_shape)


_CPU_ATTENTION = {torch.ops.aten._scaled_dot_product_flash_attention_for_cpu:
                  _cpu_attention_flops}


def _recurrent_flops(total: list):
    """A forward hook adding an LSTM's/GRU's matrix-product FLOPs to ``total[0]``."""
    def hook(module, args, output):
        x = args[0]
        if isinstance(x, torch.nn.utils.rnn.PackedSequence):
            steps = int(x.data.shape[0])  # every (clip, step) pair once
        else:
            x = x if x.dim() == 3 else x.unsqueeze(1 if module.batch_first else 0)
            steps = int(x.shape[0] * x.shape[1])
        gates = 4 if isinstance(module, torch.nn.LSTM) else 3
        H, dirs = module.hidden_size, 2 if module.bidirectional else 1
        out = getattr(module, "proj_size", 0) or H
        flops = 0
        for layer in range(module.num_layers):
            inp = module.input_size if layer == 0 else out * dirs
            flops += dirs * 2 * gates * H * (inp + out)
            if out != H:  # the projection of the hidden state
                flops += dirs * 2 * H * out
        total[0] += steps * flops
    return hook
