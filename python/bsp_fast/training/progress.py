"""Training progress on stderr: Lightning's bar on a terminal; in a log file or a pipe
(``bsp-train ... 2> log``, a cluster job) one plain line every few seconds instead of a bar
redrawn with carriage returns (which filled a log with ~84 KB for 20 short epochs)."""
from __future__ import annotations

import sys
import time

from lightning.pytorch.callbacks import TQDMProgressBar
from lightning.pytorch.callbacks.progress.progress_bar import ProgressBar

from .._plain_progress import INTERVAL, is_terminal, readable, stamp

__all__ = ["PlainProgress", "progress_callbacks", "is_terminal", "INTERVAL"]


class PlainProgress(ProgressBar):
    """One line per ``interval`` seconds of training (epoch, batch, loss, elapsed time) and
    one at the end of each epoch with its logged metrics (its own ``train/loss``, logged by
    the module's ``on_train_epoch_end`` after every callback's, and the ``val/`` metrics of
    its validation); no carriage returns."""

    def __init__(self, interval: float = INTERVAL, stream=None):
        super().__init__()
        self.interval = float(interval)
        self.stream = stream
        self._enabled = True
        self._t0 = self._last = 0.0
        self._pending = None  # the finished epoch whose line waits for its train/loss
        self._validated = False
        self._batches = 0  # of the predict loop

    def disable(self) -> None:
        self._enabled = False

    def enable(self) -> None:
        self._enabled = True

    @property
    def is_enabled(self) -> bool:
        return self._enabled and self.trainer.is_global_zero

    def _say(self, text: str) -> None:
        if self.is_enabled:
            print(stamp(self._t0, text), file=self.stream or sys.stderr, flush=True)

    def _epoch(self, trainer) -> str:
        total = trainer.max_epochs if trainer.max_epochs and trainer.max_epochs > 0 else "?"
        return f"epoch {trainer.current_epoch + 1}/{total}"

    def on_train_start(self, trainer, pl_module) -> None:
        self._t0 = self._last = time.perf_counter()

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        now = time.perf_counter()
        if now - self._last < self.interval:
            return
        self._last = now
        loss = trainer.callback_metrics.get("train/loss_step",
                                            trainer.callback_metrics.get("train/loss"))
        tail = f", loss {float(loss):.4g}" if loss is not None else ""
        self._say(f"{self._epoch(trainer)}, batch {batch_idx + 1}/"
                  f"{self.total_train_batches}{tail}")

    def on_validation_end(self, trainer, pl_module) -> None:
        if not trainer.sanity_checking and trainer.state.fn == "fit":
            self._validated = True  # this epoch's val/ metrics are the ones logged

    def on_train_epoch_end(self, trainer, pl_module) -> None:
        # the module logs the epoch's train/loss in its own on_train_epoch_end, which
        # Lightning calls after this one: the line is written once it is logged (when the
        # next epoch starts, or training ends)
        self._pending = self._epoch(trainer)

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        self._epoch_done(trainer)

    def on_train_end(self, trainer, pl_module) -> None:
        self._epoch_done(trainer)

    def _epoch_done(self, trainer) -> None:
        if self._pending is None:
            return
        prefixes = ("train/", "val/") if self._validated else ("train/",)
        shown = {k: float(v) for k, v in trainer.callback_metrics.items()
                 if k.startswith(prefixes) and k.count("/") == 1
                 and not k.endswith("_step") and getattr(v, "numel", lambda: 1)() == 1}
        values = ", ".join(f"{k} {v:.4g}" for k, v in sorted(readable(shown).items()))
        self._last = time.perf_counter()
        self._say(f"{self._pending} done" + (f": {values}" if values else ""))
        self._pending, self._validated = None, False


def progress_callbacks(quiet: bool, stream=None) -> list:
    """The progress callback of a run: none with ``quiet``, Lightning's bar when ``stream``
    (default stderr) is a terminal, :class:`PlainProgress` otherwise."""
    if quiet:
        return []
    stream = stream if stream is not None else sys.stderr
    return [TQDMProgressBar()] if is_terminal(stream) else [PlainProgress()]
