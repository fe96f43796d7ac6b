"""How a command stops: SIGINT and SIGTERM as :class:`Interrupted` (at once, or deferred to
the end of a training batch by ``Lifecycle``), and the errors of a run's files that could
not be written. Torch-free, so a command installs its handlers before importing PyTorch
(docs/training.md, "Interrupted runs")."""
from __future__ import annotations

import contextlib
import signal

__all__ = ["Interrupted", "OutputWriteError", "CheckpointWriteError", "Signals", "signals"]

_EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}


class Interrupted(BaseException):
    """SIGINT or SIGTERM stopped the run (a BaseException: no ``except Exception`` of
    Lightning or ours swallows it). ``code``: the exit status, 128 + the signal."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        self.code = _EXIT.get(self.signum, 128 + self.signum)
        super().__init__(signal.Signals(self.signum).name)


class OutputWriteError(OSError):
    """A run's file could not be written (full disk, read-only or vanished folder); the
    message names the file and says what is intact."""


class CheckpointWriteError(OutputWriteError):
    """A checkpoint could not be written; the previous one is intact."""


class Signals:
    """SIGINT/SIGTERM: raise :class:`Interrupted` at once, or, while ``deferred`` (the
    training loop runs), remember the first one for :class:`Lifecycle` to act on at the end
    of the batch; a second SIGINT stops at once."""

    def __init__(self):
        self.received: int | None = None
        self.deferred = False

    def handler(self, signum, frame):
        if self.deferred and self.received is None:
            self.received = signum
            return
        if self.deferred and signum == signal.SIGTERM:
            return  # already stopping at the end of this batch
        raise Interrupted(signum)

    def install(self) -> None:
        import threading

        if threading.current_thread() is not threading.main_thread():
            return  # signal handlers can only be set from the main thread
        for s in _EXIT:
            signal.signal(s, self.handler)


@contextlib.contextmanager
def signals():
    """``with signals() as sig:`` SIGINT and SIGTERM raise :class:`Interrupted` (or are
    deferred, see :class:`Lifecycle`); the previous handlers come back after."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield Signals()  # signal handlers can only be set from the main thread
        return
    old = {s: signal.getsignal(s) for s in _EXIT}
    sig = Signals()
    sig.install()
    try:
        yield sig
    finally:
        for s, h in old.items():
            signal.signal(s, h)
