"""``RunCheckpoint``: Lightning's ``ModelCheckpoint`` that survives its directory moving.

Runs are written under a temporary name and renamed when complete, and a resumed run is
trained in a fresh temporary copy; the stock callback would then forget its best score
("The dirpath has changed ...") and could overwrite ``best.ckpt`` with a worse model. This
one re-bases the saved paths onto the current directory instead.

It is also the last callback of every epoch's end: it then has ``Lifecycle`` save
``last.ckpt``, so that checkpoint holds this epoch's best score and early-stopping count.

Also what a checkpoint says without building its model: the saved hyper-parameters
(:func:`checkpoint_info`) and the position Lightning restores, an epoch-end ``last.ckpt``
marked as a completed epoch (:func:`epoch_end_as_completed`).
"""
from __future__ import annotations

import os
from pathlib import Path

from lightning.pytorch.callbacks import ModelCheckpoint

__all__ = ["RunCheckpoint", "epoch_end_as_completed", "checkpoint_info"]


def _rebase(path, old: str, new: str):
    if not path:
        return path
    return os.path.join(new, os.path.basename(path)) if os.path.dirname(path) == old else path


class RunCheckpoint(ModelCheckpoint):
    #: Lifecycle leaves its end-of-epoch save to this callback (see on_train_epoch_end)
    calls_epoch_end = True

    @property
    def state_key(self) -> str:  # stable across versions of the keyword arguments
        return "RunCheckpoint"

    def load_state_dict(self, state_dict: dict) -> None:
        old = state_dict.get("dirpath")
        if old and old != self.dirpath:
            state = dict(state_dict)
            for key in ("best_model_path", "kth_best_model_path", "last_model_path"):
                state[key] = _rebase(state.get(key), old, self.dirpath)
            state["best_k_models"] = {_rebase(k, old, self.dirpath): v
                                      for k, v in (state.get("best_k_models") or {}).items()}
            state["dirpath"] = self.dirpath
            state_dict = state
        super().load_state_dict(state_dict)

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        super().on_train_epoch_end(trainer, pl_module)  # best.ckpt (after validation)
        # the last callback of an epoch's end (Lightning runs checkpoint callbacks after the
        # others, EarlyStopping included): now Lifecycle's last.ckpt holds their final state
        for callback in trainer.callbacks:
            if callback is not self and callable(getattr(callback, "epoch_end", None)):
                callback.epoch_end(trainer)


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


def checkpoint_info(ckpt_path) -> dict:
    """The saved hyper-parameters of a bsp-train checkpoint (task, model, hparams, lr,
    config), read without building the model."""
    import torch

    from .tasks import TASKS

    path = Path(ckpt_path)
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") \
            from None
    hp = ckpt.get("hyper_parameters") if isinstance(ckpt, dict) else None
    if not isinstance(hp, dict) or hp.get("task") not in TASKS or "model" not in hp:
        raise ValueError(f"{path}: not a bsp-train checkpoint (no task/model hyper-parameters)")
    info = dict(hp)
    info["epoch"] = ckpt.get("epoch")
    info["global_step"] = ckpt.get("global_step")
    # Lightning's current_epoch once --resume restores it: an epoch-end last.ckpt counts its
    # epoch as completed (the dict here is a copy)
    epoch_end_as_completed(ckpt)
    progress = ((ckpt.get("loops") or {}).get("fit_loop") or {}).get("epoch_progress")
    info["restored_epoch"] = progress["current"]["completed"] if progress else info["epoch"]
    return info
