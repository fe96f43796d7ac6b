"""What a bsp-train checkpoint says, read without Lightning: the saved hyper-parameters
(:func:`checkpoint_info`), the whole file (:func:`read_checkpoint`) and the position
Lightning restores, an epoch-end ``last.ckpt`` marked as a completed epoch
(:func:`epoch_end_as_completed`). bsp-eval and bsp-predict score checkpoints with these
and plain PyTorch; importing Lightning would cost them seconds."""
from __future__ import annotations

from pathlib import Path

__all__ = ["read_checkpoint", "checkpoint_info", "epoch_end_as_completed"]


def epoch_end_as_completed(checkpoint: dict) -> bool:
    """Marks a ``last.ckpt`` written at an epoch's end (``epoch_end``: after the epoch's
    validation, best.ckpt and early stopping) as a completed epoch; True if it was one.

    Lightning resumes such a checkpoint by running the epoch's end hooks again when the run
    has ``max_steps`` (it then always counts as restarting). Their validation metrics are
    not in the checkpoint, so EarlyStopping raised ("val/loss ... not available") and no
    run with both ``--max-steps`` and ``--early-stop`` could be resumed; it would also have
    counted the epoch twice. Without ``max_steps`` Lightning already treats it as completed.
    With the epoch completed and the batch counters of the epoch in progress at zero, both
    cases start the next epoch exactly as the uninterrupted run did."""
    loops = (checkpoint.get("loops") or {}).get("fit_loop")
    if not loops or "epoch_progress" not in loops:
        return False
    epochs = loops["epoch_progress"]
    t = epochs["total"]
    if not (t["ready"] == t["started"] == t["processed"] == t["completed"] + 1):
        return False  # saved mid-epoch, or an epoch already completed
    batches = loops.get("epoch_loop.batch_progress") or {}
    if not batches.get("is_last_batch"):
        return False  # not our epoch-end save: leave it to Lightning
    for part in ("total", "current"):
        epochs[part]["completed"] = epochs[part]["processed"]
    # what Lightning's reset at the start of an epoch does (reset_on_run); the totals stay
    for key in ("epoch_loop.batch_progress", "epoch_loop.scheduler_progress"):
        if key in loops:
            loops[key]["current"] = dict.fromkeys(loops[key]["current"], 0)
    batches["is_last_batch"] = False
    optim = loops.get("epoch_loop.automatic_optimization.optim_progress")
    if optim:
        for tracker in optim["optimizer"].values():
            tracker["current"] = dict.fromkeys(tracker["current"], 0)
    val = loops.get("epoch_loop.val_loop.batch_progress")
    if val:
        val["total"] = dict.fromkeys(val["total"], 0)
    return True


def read_checkpoint(ckpt_path, map_location="cpu") -> dict:
    """The checkpoint file as a dict (``weights_only``: a checkpoint is untrusted input);
    ValueError naming the file when it is not a bsp-train checkpoint."""
    import torch

    from .tasks import TASKS

    path = Path(ckpt_path)
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=True, mmap=True)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") \
            from None
    hp = ckpt.get("hyper_parameters") if isinstance(ckpt, dict) else None
    if not isinstance(hp, dict) or hp.get("task") not in TASKS or "model" not in hp:
        raise ValueError(f"{path}: not a bsp-train checkpoint (no task/model hyper-parameters)")
    return ckpt


def checkpoint_info(ckpt_path, ckpt: dict | None = None) -> dict:
    """The saved hyper-parameters of a bsp-train checkpoint (task, model, hparams, lr,
    config) and its position, read without building the model (``ckpt``: the file
    already read by :func:`read_checkpoint`)."""
    ckpt = read_checkpoint(ckpt_path) if ckpt is None else ckpt
    info = dict(ckpt["hyper_parameters"])
    info["epoch"] = ckpt.get("epoch")
    info["global_step"] = ckpt.get("global_step")
    # Lightning's current_epoch once --resume restores it: an epoch-end last.ckpt counts its
    # epoch as completed (marked on a copy: the caller's dict stays as read)
    epoch_end_as_completed(ckpt := {**ckpt, "loops": _copy(ckpt.get("loops"))})
    progress = ((ckpt.get("loops") or {}).get("fit_loop") or {}).get("epoch_progress")
    info["restored_epoch"] = progress["current"]["completed"] if progress else info["epoch"]
    return info


def _copy(value):
    """A copy of the nested dicts of a checkpoint's loop state (marking changes it)."""
    return {k: _copy(v) for k, v in value.items()} if isinstance(value, dict) else value
