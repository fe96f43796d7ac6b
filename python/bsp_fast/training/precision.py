"""``--precision``: what ``auto`` picks (per model, from measurements: docs/training.md,
"Precision") and the warning for bf16 on a CPU without bf16 instructions."""
from __future__ import annotations

__all__ = ["resolve_precision", "native_bf16", "check_precision"]


def resolve_precision(precision: str, accelerator: str, model=None) -> str:
    """``auto`` -> bf16-mixed on a GPU that supports it; on a CPU with native bf16
    (AVX512-BF16/AMX) bf16-mixed for a ``model`` (class or instance) whose
    ``cpu_bf16_faster`` is set (measured faster there); else 32 (docs/training.md)."""
    if precision != "auto":
        return precision
    import torch

    gpu = accelerator == "gpu" or (accelerator == "auto" and torch.cuda.is_available())
    if gpu and torch.cuda.is_available() and torch.cuda.is_bf16_supported():
        return "bf16-mixed"
    if not gpu and getattr(model, "cpu_bf16_faster", False) and native_bf16("cpu"):
        return "bf16-mixed"
    return "32"


def native_bf16(accelerator: str) -> bool:
    """Whether bf16 arithmetic runs natively where ``accelerator`` trains: a CUDA device,
    or a CPU with AVX512-BF16/AMX."""
    import torch

    if accelerator != "cpu" and torch.cuda.is_available():
        return True
    from ..models import lstm

    return lstm.cpu_bf16()


def check_precision(precision: str, accelerator: str) -> None:
    """bf16 on a CPU without bf16 instructions (AVX512-BF16/AMX): allowed, with a warning.
    oneDNN then converts to and from bf16 around float32 arithmetic (measured 5-17x
    slower than 32 on an AVX2 CPU) and has no bf16 LSTM kernel, so the models' LSTM
    layers run in float32 inside autocast (``models.lstm``)."""
    import warnings

    if precision.startswith("bf16") and not native_bf16(accelerator):
        warnings.warn(f"--precision {precision} on a CPU without bf16 instructions "
                      "(AVX512-BF16/AMX): expect it to be several times slower than "
                      "--precision 32 (docs/training.md, Precision); LSTM layers run in "
                      "float32", UserWarning, stacklevel=2)
