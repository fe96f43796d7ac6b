"""A training run that survives interruption (docs/training.md, "Interrupted runs").

* ``checkpoints/last.ckpt`` is saved at the first batch end or epoch end (``RunCheckpoint``)
  once ``--checkpoint-every`` has passed since the last save, at the end of the last epoch,
  and at every epoch end with ``--checkpoint-every 0`` (:class:`Lifecycle`), each time
  through :class:`AtomicCheckpointIO`: written under a temporary name and renamed, so a
  full disk or a kill leaves the previous checkpoint whole. (A save at every epoch end
  cost 7 % of a run of 0.9-second epochs: docs/performance.md.)
* SIGINT and SIGTERM during training finish the current batch, save ``last.ckpt`` and stop
  with :class:`Interrupted` (in an epoch's last batch or its validation: after the
  validation and the end-of-epoch ``last.ckpt``); ``bsp-train`` then leaves the run as an *incomplete* run
  directory (``incomplete.json`` holds the epoch and step reached, there is no
  ``metrics.json``) and exits 130 or 143. Outside training (data conversion, testing) the
  same signals stop at once.
* A resumed run continues from ``last.ckpt`` with the batches of the interrupted epoch it
  had not trained on (the sampler skips the others) and the random state saved with the
  checkpoint, so it ends with the same weights and metrics as an uninterrupted run.
"""
from __future__ import annotations

import io
import random
import signal
import sys
import time
from pathlib import Path

import numpy as np
import torch
from lightning.fabric.plugins.io.torch_io import TorchCheckpointIO
from lightning.pytorch.callbacks import Callback

from ..atomic import write_bytes
from .checkpoint_file import epoch_end_as_completed
from .runs import write_marker
from .stopping import CheckpointWriteError, Interrupted, Signals

__all__ = ["AtomicCheckpointIO", "Lifecycle", "epochs_note", "test_checkpoint"]

class AtomicCheckpointIO(TorchCheckpointIO):
    """Lightning's checkpoint writer through bsp_fast's one temp-then-rename helper; a
    failed write leaves the previous file as it was and raises
    :class:`CheckpointWriteError` naming the file."""

    def save_checkpoint(self, checkpoint, path, storage_options=None) -> None:
        if storage_options is not None:
            raise TypeError("storage_options are not supported")
        buffer = io.BytesIO()
        torch.save(checkpoint, buffer)
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes(path, buffer.getbuffer())  # a view: no second copy of the checkpoint
        except OSError as exc:
            raise CheckpointWriteError(exc.errno, f"{path}: cannot save the checkpoint "
                                       f"({exc.strerror or exc}); the previous one is "
                                       "intact") from None


# ---------------------------------------------------------------------- the callback
def _rng_state() -> dict:
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    version, internal, gauss_next = random.getstate()
    return {"torch": torch.get_rng_state(), "numpy": [kind, keys.tolist(), pos, has_gauss,
                                                      gauss],
            "python": [version, list(internal), gauss_next]}


def _set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    kind, keys, pos, has_gauss, gauss = state["numpy"]
    np.random.set_state((kind, np.asarray(keys, dtype=np.uint32), pos, has_gauss, gauss))
    version, internal, gauss_next = state["python"]
    random.setstate((version, tuple(internal), gauss_next))


class Lifecycle(Callback):
    """Periodic ``last.ckpt``, signal handling at batch ends, and an exact continuation of
    a run resumed mid-epoch (see the module docstring).

    ``run_dir``: the run's (temporary) directory; ``every``: seconds between checkpoints
    (0: at every epoch end and never within one); ``sig``: the :func:`.stopping.signals` state;
    ``marker``: fields written into ``incomplete.json`` with every save."""

    def __init__(self, run_dir, every: float, sig: Signals, marker: dict | None = None):
        self.run_dir, self.every, self.sig = Path(run_dir), float(every), sig
        self.marker = dict(marker or {})
        self.epoch, self.batches_done, self.step = 0, 0, 0
        #: the position of the last save, what incomplete.json describes
        self._saved = (0, 0, 0)
        self._last_save = time.monotonic()
        self._resume_rng = None
        self._skip = None
        self.trained = False
        #: (wall, CPU) seconds of fit of the processes before this one, up to the save of
        #: the checkpoint it continues from; ``_clock``: this process's fit start
        self.carried, self._clock, self.partial = (0.0, 0.0), None, False

    @property
    def state_key(self) -> str:
        return "BSPLifecycle"

    @property
    def last_ckpt(self) -> Path:
        return self.run_dir / "checkpoints" / "last.ckpt"

    # position and random state travel in every checkpoint Lightning writes
    def state_dict(self) -> dict:
        return {"epoch": self.epoch, "batches_done": self.batches_done, "step": self.step,
                "rng": _rng_state(), "fit_seconds": list(self.fit_seconds())}

    def load_state_dict(self, state: dict) -> None:
        self.epoch, self.step = int(state["epoch"]), int(state["step"])
        self.batches_done = int(state["batches_done"])
        # checkpoints written before fit_seconds was saved carry none: their earlier
        # processes' seconds are unknown, and the run's record says so (``partial``)
        self.carried = tuple(float(x) for x in state.get("fit_seconds", (0.0, 0.0)))
        self.partial = "fit_seconds" not in state
        self._skip = (self.epoch, self.batches_done)
        self._saved = (self.epoch, self.step, self.batches_done)
        # now, before the train loader's first iterator draws its seed from the global
        # generator (as it did after the save in the uninterrupted run); again at the first
        # batch of a run resumed mid-epoch (see on_train_start)
        _set_rng_state(state["rng"])
        self._resume_rng = state["rng"]

    def start_clock(self) -> None:
        """Starts this process's fit clocks (wall and CPU)."""
        self._clock = (time.perf_counter(), time.process_time())

    def fit_seconds(self) -> tuple:
        """``(wall, CPU)`` seconds of fit over every process of a resumed run: what the
        continued checkpoint carried plus this process's since :meth:`start_clock`. Work a
        killed process did after its last checkpoint is redone and counted once."""
        if self._clock is None:
            return self.carried
        return (self.carried[0] + time.perf_counter() - self._clock[0],
                self.carried[1] + time.process_time() - self._clock[1])

    def on_save_checkpoint(self, trainer, pl_module, checkpoint) -> None:
        # the running train-loss mean of the epoch (torchmetrics states are not saved)
        loss = getattr(pl_module, "train_loss", None)
        if loss is not None:
            checkpoint["bsp_train_loss"] = {k: v.clone() for k, v in loss.metric_state.items()}

    def on_load_checkpoint(self, trainer, pl_module, checkpoint) -> None:
        # before Lightning restores its loops from the same dict (callbacks load first)
        epoch_end_as_completed(checkpoint)
        loss = getattr(pl_module, "train_loss", None)
        for k, v in (checkpoint.get("bsp_train_loss") or {}).items():
            if loss is not None:
                setattr(loss, k, v.clone())
                loss._update_count = 1 if float(v.sum()) else 0

    def on_train_start(self, trainer, pl_module) -> None:
        self.trained = True  # fit did not return at once (its epochs were already done)
        sampler = getattr(trainer.train_dataloader, "sampler", None)
        total = trainer.num_training_batches
        mid_epoch = self._skip is not None and 0 < self._skip[1] < total
        if mid_epoch:
            if not hasattr(sampler, "skip_batches"):
                raise RuntimeError("resuming mid-epoch needs bsp_fast's batch sampler")
            sampler.skip_batches(*self._skip)  # the batches trained before the interruption
        else:
            self._resume_rng = None  # an epoch-end checkpoint: restored at load
        self._skip = None
        self.sig.deferred = True  # from here on a signal stops at the end of the batch
        self.sig.install()  # over Lightning's SIGTERM handler, which stops mid-validation
        self._last_save = time.monotonic()

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        if self._resume_rng is not None:  # mid-epoch: dropout continues where it was
            _set_rng_state(self._resume_rng)
            self._resume_rng = None

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        self.epoch, self.batches_done = trainer.current_epoch, batch_idx + 1
        self.step = trainer.global_step
        stop = self.sig.received
        # never a checkpoint after an epoch's last batch: Lightning resumes one as a finished
        # epoch and skips its validation (a run stopped in epoch 1 then had no best.ckpt).
        # A signal there stops after the epoch's validation and end-of-epoch checkpoint, as
        # one during validation does (on_train_epoch_start, or bsp-train after fit)
        last = self.batches_done >= trainer.num_training_batches
        due = bool(self.every) and self._elapsed() and not last
        if trainer.world_size > 1:  # every process saves (a collective) or none: rank 0 decides
            stop, due = trainer.strategy.broadcast((stop, due), src=0)
        if stop is not None and not last:
            self.save(trainer, state="interrupted", signal=signal.Signals(stop).name)
            raise Interrupted(stop)
        if due:
            self.save(trainer, state="running")

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        # a signal during validation: the epoch-end checkpoint is already written (epoch_end
        # saves when a signal has come), stop before the next epoch. One in the moment after
        # epoch_end's check, when that saved nothing (--checkpoint-every not yet passed):
        # train on to this epoch's first batch end, which saves and stops (or, in an epoch
        # of one batch, to its end), so the work since the last save is not lost
        stop = self.sig.received
        saved_here = self._saved[1] == trainer.global_step  # nothing trained since the save
        if trainer.world_size > 1:
            stop = trainer.strategy.broadcast(stop, src=0)
        if stop is not None and saved_here:
            if trainer.is_global_zero:
                self.write_marker(state="interrupted", signal=signal.Signals(stop).name)
            raise Interrupted(stop)

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        # Lightning calls this before the monitoring callbacks' hook, where RunCheckpoint
        # writes best.ckpt and EarlyStopping counts: RunCheckpoint calls epoch_end after its
        # own, so last.ckpt holds this epoch's best score (a run resumed from it tests the
        # right best.ckpt, and never replaces it with a worse one). A callback that says so
        # (``calls_epoch_end``) calls it; no import of it here, it imports nothing of ours
        if not any(getattr(c, "calls_epoch_end", False) for c in trainer.callbacks):
            self.epoch_end(trainer)

    def epoch_end(self, trainer) -> None:
        """Saves the state a next epoch starts from (after validation, best.ckpt and early
        stopping; Lightning's save_last writes last.ckpt only when best.ckpt changes) when
        a save is due, the run stops after this epoch, or a signal has come. A skipped
        save costs nothing in exactness: a run continued from an older checkpoint trains
        the same epochs again to the same weights, ``best.ckpt`` included."""
        due = not self.every or self._elapsed()
        stop = self.sig.received is not None
        if trainer.world_size > 1:  # time and signals differ by rank: rank 0 decides
            due, stop = trainer.strategy.broadcast((due, stop), src=0)
        if due or stop or _last_epoch(trainer):
            self.save(trainer, state="running")

    def on_train_end(self, trainer, pl_module) -> None:
        self.sig.deferred = False

    def on_exception(self, trainer, pl_module, exception) -> None:
        self.sig.deferred = False

    def _elapsed(self) -> bool:
        """Whether ``every`` seconds have passed since the last save."""
        return time.monotonic() - self._last_save >= self.every

    def save(self, trainer, **fields) -> None:
        trainer.save_checkpoint(self.last_ckpt)  # written by rank 0 only
        self._last_save = time.monotonic()
        self._saved = (self.epoch, self.step, self.batches_done)
        if trainer.is_global_zero:
            self.write_marker(**fields)

    def write_marker(self, **fields) -> None:
        # the last save's position; epoch: 1-based, the epoch in progress (or just
        # finished) at that checkpoint
        epoch, step, batches = self._saved
        write_marker(self.run_dir, **self.marker, epoch=epoch + 1, step=step,
                     batches_done=batches, checkpoint="checkpoints/last.ckpt", **fields)


def _last_epoch(trainer) -> bool:
    """Whether fit ends after this epoch: early stopping, ``--epochs`` or ``--max-steps``
    reached (so the finished run's ``last.ckpt`` is its final state)."""
    epochs, steps = trainer.max_epochs, trainer.max_steps
    return bool(trainer.should_stop
                or (epochs is not None and 0 <= epochs <= trainer.current_epoch + 1)
                or (steps is not None and 0 < steps <= trainer.global_step))


# ---------------------------------------------------------------------- the end of a resumed run
def epochs_note(cfg: dict, trainer, trained: bool) -> dict:
    """A resumed run whose ``--epochs`` were already done: fit returned at once. Says so;
    with ``--epochs`` below the epochs already completed, the run keeps those (it cannot
    shed them): its ``epochs`` becomes that count, in config.yaml and metrics.json."""
    done = int(trainer.current_epoch)
    if trained or done < cfg["epochs"] or (cfg.get("max_steps") and
                                          trainer.global_step >= cfg["max_steps"]):
        return cfg
    if done > cfg["epochs"]:
        print(f"bsp-train: note: --epochs {cfg['epochs']} is below the {done} epochs this "
              f"run had already completed: no more training, it ends with {done} epochs",
              file=sys.stderr)
        return dict(cfg, epochs=done)
    print(f"bsp-train: note: the run had already completed its {done} epoch"
          f"{'s' if done != 1 else ''}: no more training", file=sys.stderr)
    return cfg


def test_checkpoint(trainer, module, dm, tmp: Path) -> str:
    """Tests the run's best checkpoint -> ``"best"``. When no validation ever ran, so there
    is none (the run stopped before the end of its first epoch: ``--max-steps``, or resumed
    from a checkpoint taken after the last batch of its first epoch, which Lightning
    continues as a finished epoch), validates (for metrics.json's ``val``; not logged as an
    epoch) and tests ``last.ckpt`` -> ``"last"``. Every process decides the same."""
    best = trainer.checkpoint_callback
    if best is not None and best.best_model_path:
        trainer.test(module, datamodule=dm, ckpt_path="best", verbose=False)
        return "best"
    last = tmp / "checkpoints" / "last.ckpt"
    if not last.is_file():
        trainer.save_checkpoint(last)
    loggers = trainer.loggers
    trainer.loggers = []
    try:
        trainer.validate(module, datamodule=dm, ckpt_path=str(last), verbose=False,
                         weights_only=True)
    finally:
        trainer.loggers = loggers
    trainer.test(module, datamodule=dm, ckpt_path=str(last), verbose=False, weights_only=True)
    return "last"
