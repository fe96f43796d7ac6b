"""``RunCheckpoint``: Lightning's ``ModelCheckpoint`` that survives its directory moving.

Runs are written under a temporary name and renamed when complete, and a resumed run is
trained in a fresh temporary copy; the stock callback would then forget its best score
("The dirpath has changed ...") and could overwrite ``best.ckpt`` with a worse model. This
one re-bases the saved paths onto the current directory instead.

It is also the last callback of every epoch's end: it then has ``Lifecycle`` save
``last.ckpt``, so that checkpoint holds this epoch's best score and early-stopping count.
"""
from __future__ import annotations

import os

from lightning.pytorch.callbacks import ModelCheckpoint

__all__ = ["RunCheckpoint"]


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
