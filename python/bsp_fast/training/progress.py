"""Training progress on stderr: Lightning's bar on a terminal; in a log file or a pipe
(``bsp-train ... 2> log``, a cluster job) one plain line every few seconds instead of a bar
redrawn with carriage returns (which filled a log with ~84 KB for 20 short epochs)."""
from __future__ import annotations

import sys
import time

from lightning.pytorch.callbacks import TQDMProgressBar
from lightning.pytorch.callbacks.progress.progress_bar import ProgressBar

__all__ = ["PlainProgress", "progress_callbacks", "is_terminal"]

#: seconds between two plain progress lines within an epoch
INTERVAL = 10.0


def is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class PlainProgress(ProgressBar):
    """One line per ``interval`` seconds of training (epoch, batch, loss, elapsed time) and
    one at the end of each epoch with its logged metrics; no carriage returns."""

    def __init__(self, interval: float = INTERVAL, stream=None):
        super().__init__()
        self.interval = float(interval)
        self.stream = stream
        self._enabled = True
        self._t0 = self._last = 0.0

    def disable(self) -> None:
        self._enabled = False

    def enable(self) -> None:
        self._enabled = True

    @property
    def is_enabled(self) -> bool:
        return self._enabled and self.trainer.is_global_zero

    def _say(self, text: str) -> None:
        if self.is_enabled:
            elapsed = time.perf_counter() - self._t0
            print(f"[{elapsed:7.1f} s] {text}", file=self.stream or sys.stderr, flush=True)

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
        if trainer.sanity_checking or trainer.state.fn != "fit":
            return
        shown = {k: float(v) for k, v in trainer.callback_metrics.items()
                 if k.startswith(("train/", "val/")) and k.count("/") == 1
                 and not k.endswith("_step") and getattr(v, "numel", lambda: 1)() == 1}
        values = ", ".join(f"{k} {v:.4g}" for k, v in sorted(shown.items()))
        self._last = time.perf_counter()
        self._say(f"{self._epoch(trainer)} done" + (f": {values}" if values else ""))


def progress_callbacks(quiet: bool, stream=None) -> list:
    """The progress callback of a run: none with ``quiet``, Lightning's bar when ``stream``
    (default stderr) is a terminal, :class:`PlainProgress` otherwise."""
    if quiet:
        return []
    stream = stream if stream is not None else sys.stderr
    return [TQDMProgressBar()] if is_terminal(stream) else [PlainProgress()]
