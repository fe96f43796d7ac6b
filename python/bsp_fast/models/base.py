"""``BaseModel``: the shared base of every model (shape checks, task, hyper-parameters,
the report's loss and optimiser defaults) and the per-task bases.

A model is a plain ``torch.nn.Module``: ``model(inputs, visible=None, **context)`` checks
the input shapes, calls :meth:`BaseModel.compute` and checks the output shape.
"""
from __future__ import annotations

import inspect

import torch
from torch import nn

from .. import skeleton as _sk

__all__ = ["BaseModel", "ClassificationModel", "AutoencoderModel", "LiftingModel",
           "PoseEstimationModel", "check_choice", "check_int", "check_float", "present_joints"]

J = _sk.NUM_JOINTS


def check_choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")


def check_int(name: str, value, minimum: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")


def check_float(name: str, value, lo: float = 0.0, hi: float = float("inf"),
                hi_open: bool = False) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    ok = ok and lo <= value and (value < hi if hi_open else value <= hi)
    if not ok:
        rng = f"[{lo}, {hi})" if hi_open else f"[{lo}, {hi}]"
        raise ValueError(f"{name} must be a number in {rng}, got {value!r}")


def present_joints(targets: torch.Tensor) -> torch.Tensor:
    """``(B, L, J)`` joints present in a normalised 2D target: not exactly (0, 0) (how the
    datasets mark a missing joint), the hips (the origin) always counted."""
    present = (targets != 0).any(-1)
    present[..., _sk.HIPS] = True
    return present


def activation_layout(fmt=None):
    """The memory layout an image network's activations take: ``fmt`` (a module's
    ``MEMORY_FORMAT``), or for None NCHW under CPU bf16 autocast and channels_last
    otherwise (GroupNorm's channels_last CPU kernels are slow in bf16; docs/performance.md,
    "The pose networks' activation layout")."""
    if fmt is not None:
        return fmt
    return torch.contiguous_format if torch.is_autocast_enabled("cpu") else torch.channels_last


class BaseModel(nn.Module):
    """Base of all models. Subclasses are registered with
    :func:`bsp_fast.models.register`, declare their hyper-parameters as keyword-only
    ``__init__`` arguments (call ``super().__init__(locals())`` first) and implement
    :meth:`compute`.

    Attributes: ``task``, ``name``, ``hparams`` (a JSON-able dict of every
    hyper-parameter). Class attributes ``default_lr`` / ``default_weight_decay`` are the
    report's AdamW settings (1e-4 and 1e-8 unless a model says otherwise).
    """

    task: str = ""
    name: str = ""
    description: str = ""
    default_lr: float = 1e-4
    default_weight_decay: float = 1e-8
    #: does forward need the batch's per-clip context (e.g. age/gender)?
    context_keys: tuple = ()
    #: ``--precision auto`` on a CPU with native bf16 (AVX512-BF16 or AMX): bf16-mixed where
    #: measured faster for this model (docs/training.md, "Precision"), float32 otherwise;
    #: the one place that per-model decision lives
    cpu_bf16_faster: bool = False
    #: raised when a code change alters this model's float32/bf16 step times: part of the
    #: precision probe's cache key, so answers measured before are not reused
    speed_revision: int = 0

    def __init__(self, values: dict | None = None):
        super().__init__()
        names = [p.name for p in inspect.signature(type(self).__init__).parameters.values()
                 if p.kind is inspect.Parameter.KEYWORD_ONLY]
        values = values or {}
        self.hparams = {k: values[k] for k in names if k in values}

    # ----------------------------------------------------------------- calling
    def forward(self, inputs: torch.Tensor, visible: torch.Tensor | None = None, **context):
        B, L = self.check_inputs(inputs, visible)
        out = self.compute(inputs, visible, **context)
        want = self.output_shape(B, L)
        if tuple(out.shape) != want:  # a bug in a model, not a user error
            raise RuntimeError(f"{self.task}/{self.name}: output {tuple(out.shape)}, "
                               f"expected {want}")
        return out

    def compute(self, inputs, visible, **context) -> torch.Tensor:
        raise NotImplementedError

    def forward_batch(self, batch: dict) -> torch.Tensor:
        """Runs the model on a ``ClipDataset`` batch dict (``inputs``, ``visible``,
        ``meta`` ...), passing the context this model needs."""
        meta = batch.get("meta", {})
        context = {k: meta[k] for k in self.context_keys}
        return self(batch["inputs"], batch.get("visible"), **context)

    def check_inputs(self, inputs, visible) -> tuple:
        if not torch.is_tensor(inputs) or inputs.ndim != 4 or tuple(inputs.shape[2:]) != (J, 2):
            raise ValueError(f"{self.name}: inputs must be a (B, L, {J}, 2) tensor of "
                             f"normalised 2D poses, got {_shape(inputs)}")
        if not inputs.is_floating_point():
            raise ValueError(f"{self.name}: inputs must be floating point, got {inputs.dtype}")
        B, L = inputs.shape[:2]
        self._check_visible(visible, B, L)
        if L < self.min_length:
            raise ValueError(f"{self.name}: clips must have at least {self.min_length} "
                             f"frames, got L={L}")
        return B, L

    def _check_visible(self, visible, B, L) -> None:
        if visible is not None and (not torch.is_tensor(visible)
                                    or tuple(visible.shape) != (B, L, J)):
            raise ValueError(f"{self.name}: visible must be a ({B}, {L}, {J}) tensor, got "
                             f"{_shape(visible)}")

    min_length = 1

    def output_shape(self, B: int, L: int) -> tuple:
        raise NotImplementedError

    def frame_slice(self, L: int) -> slice:
        """The input frames that the per-frame outputs correspond to."""
        return slice(0, L)

    # ----------------------------------------------------------------- training
    def loss(self, output: torch.Tensor, batch: dict) -> torch.Tensor:
        """The report's training loss of this model for a batch dict."""
        raise NotImplementedError

    def scheduler(self, optimizer, total_steps: int | None = None):
        """``(scheduler, "epoch" | "step")`` or ``(None, "epoch")``; ``total_steps``: the
        run's optimiser updates, for schedules that end with the budget (None: unknown)."""
        return None, "epoch"

    def configure_optimizers(self, lr: float | None = None,
                             total_steps: int | None = None) -> dict:
        """The report's defaults in Lightning's format: ``{"optimizer": AdamW}``, plus
        ``"lr_scheduler": {"scheduler": ..., "interval": "epoch" | "step"}`` when the
        model has a scheduler (a ``LightningModule.configure_optimizers`` can return it
        as is). ``total_steps``: the run's optimiser updates (``bsp-train`` passes
        Lightning's estimate: ``max_steps`` or epochs x batches, whichever ends first)."""
        opt = torch.optim.AdamW(self.parameters(), lr=self.default_lr if lr is None else lr,
                                weight_decay=self.default_weight_decay)
        sched, interval = self.scheduler(opt, total_steps)
        if sched is None:
            return {"optimizer": opt}
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": interval}}

    def init_from_baseline(self, baseline) -> None:
        """Starts the model from its task's fitted trivial baseline where that helps (called
        by ``bsp-train`` after the "initial metrics"); most models ignore it."""

    def extra_repr(self) -> str:
        return f"task={self.task!r}, name={self.name!r}, hparams={self.hparams}"


def _shape(x) -> str:
    return str(tuple(x.shape)) if torch.is_tensor(x) else type(x).__name__


class _PoseInput:
    """Mixin: 2D pose inputs and the optional use of the ``visible`` mask."""

    def _init_visible(self, use_visible: bool) -> None:
        if not isinstance(use_visible, bool):
            raise ValueError(f"use_visible must be True or False, got {use_visible!r}")
        self.use_visible = use_visible
        self.in_channels = 3 if use_visible else 2

    def pose_features(self, inputs: torch.Tensor, visible) -> torch.Tensor:
        """``(B, L, J, C)``: the inputs as given (C = 2, the original), or with
        ``use_visible`` missing joints zeroed and the mask as a third channel."""
        if not self.use_visible:
            return inputs
        if visible is None:
            raise ValueError(f"{self.name} was built with use_visible=True: pass visible "
                             "(B, L, 26)")
        v = visible.to(inputs.dtype).unsqueeze(-1)
        return torch.cat([inputs * v, v], -1)


class ClassificationModel(_PoseInput, BaseModel):
    """Crossing classifiers: ``(B, L, 26, 2)`` -> logits ``(B, 2)``; cross-entropy."""

    num_logits = 2

    def output_shape(self, B, L):
        return (B, 2) if self.num_logits == 2 else (B,)

    def loss(self, output, batch):
        return nn.functional.cross_entropy(output.float(), batch["targets"].long())


class AutoencoderModel(_PoseInput, BaseModel):
    """Pose autoencoders: deformed ``(B, L, 26, 2)`` -> clean ``(B, L, 26, 2)``, both
    normalised; loss ``losses.loc_2d`` over the joints present in the target."""

    def output_shape(self, B, L):
        return (B, L, J, 2)

    def loss(self, output, batch):
        from .. import losses

        target = batch["targets"]
        return losses.loc_2d(output.float(), target, present_joints(target))


class LiftingModel(_PoseInput, BaseModel):
    """2D -> 3D lifting: ``(B, L, 26, 2)`` -> hips-neck normalised ``(B, L', 26, 3)`` for the
    frames ``frame_slice(L)``; loss ``losses.loc_3d`` on normalised 3D."""

    def output_shape(self, B, L):
        s = self.frame_slice(L)
        return (B, s.stop - s.start, J, 3)

    def loss(self, output, batch):
        from .. import losses

        target = batch["targets"][:, self.frame_slice(batch["targets"].shape[1])]
        return losses.loc_3d(output.float(), target, normalise=False)


class PoseEstimationModel(BaseModel):
    """Pose estimation from crops: uint8 ``(B, L, 3, S, S)`` -> ``(B, L, 26, 2)`` joints in
    crop pixels; loss: MSE over the visible joints (pixels^2)."""

    def check_inputs(self, inputs, visible):
        ok = torch.is_tensor(inputs) and inputs.ndim == 5 and inputs.shape[2] == 3
        if not ok or inputs.shape[3] != inputs.shape[4]:
            raise ValueError(f"{self.name}: inputs must be (B, L, 3, S, S) crops, got "
                             f"{_shape(inputs)}")
        if inputs.shape[3] < 16:
            raise ValueError(f"{self.name}: crops must be at least 16 pixels, got "
                             f"{inputs.shape[3]}")
        B, L = inputs.shape[:2]
        self._check_visible(visible, B, L)
        return B, L

    def output_shape(self, B, L):
        return (B, L, J, 2)

    def loss(self, output, batch):
        return masked_mse(output.float(), batch["targets"], batch.get("visible"))


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask=None) -> torch.Tensor:
    """Mean squared error over the coordinates of the joints where ``mask (..., J)``;
    masked-out joints reach neither the value nor the gradient, even when NaN (a frame
    without a crop has NaN targets)."""
    if mask is None:
        return (pred - target).pow(2).sum(-1).mean() / pred.shape[-1]
    # a joint is kept only where its target is finite too; masked targets are replaced
    # before the subtraction: torch.where after it would keep the value finite but give
    # NaN gradients (0 x NaN in pow's backward), and one such batch ruins the weights
    keep = mask.bool() & torch.isfinite(target).all(-1)
    safe = torch.where(keep[..., None], target, pred.detach())
    err = (pred - safe).pow(2).sum(-1)
    err = torch.where(keep, err, torch.zeros((), dtype=err.dtype, device=err.device))
    return err.sum() / (keep.sum() * pred.shape[-1]).clamp_min(1)
