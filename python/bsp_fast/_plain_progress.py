"""Progress off a terminal, shared by the commands (no torch needed): in a log file or a pipe
(``bsp-synth ... 2> log``, CI, a cluster job) one plain line every few seconds,
``[  12.3 s] clips 5/20``, instead of a bar redrawn with carriage returns. bsp-train's
:class:`bsp_fast.training.progress.PlainProgress` writes its lines in the same style."""
from __future__ import annotations

import sys
import time

__all__ = ["INTERVAL", "is_terminal", "stamp", "PlainLines", "FALLBACK_NOTE", "readable"]

#: seconds between two plain progress lines
INTERVAL = 10.0


def is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def stamp(t0: float, text: str) -> str:
    """``[elapsed s] text``: one progress line, ``t0`` a ``time.perf_counter()`` value."""
    return f"[{time.perf_counter() - t0:7.1f} s] {text}"


class PlainLines:
    """A counter with tqdm's ``update``/``close`` that prints ``desc done/total`` at most
    once per ``interval`` seconds, and ``desc total/total done`` when closed complete."""

    def __init__(self, total: int, desc: str, interval: float = INTERVAL, stream=None):
        self.total, self.desc, self.interval = int(total), desc, float(interval)
        self.stream = stream
        self.n = 0
        self._t0 = self._last = time.perf_counter()
        self._closed = False

    def _say(self, text: str) -> None:
        print(stamp(self._t0, text), file=self.stream or sys.stderr, flush=True)

    def update(self, k: int = 1) -> None:
        self.n += k
        now = time.perf_counter()
        if self.n < self.total and now - self._last >= self.interval:
            self._last = now
            self._say(f"{self.desc} {self.n}/{self.total}")

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self.n >= self.total:
                self._say(f"{self.desc} {self.n}/{self.total} done")


#: what ``normaliser_fallback`` (a metric of every 2D-input task) means, for readers
FALLBACK_NOTE = ("normaliser_fallback: share of input frames normalised by their joint box "
                 "because the hips or neck were missing")


def readable(values: dict) -> dict:
    """Metrics as the progress lines and bsp-eval print them: ``normaliser_fallback`` only
    when some frames needed the fallback (0 says nothing a reader needs; metrics.json keeps
    it), and then named by :data:`FALLBACK_NOTE`."""
    return {k: v for k, v in values.items()
            if not (k.split("/")[-1] == "normaliser_fallback" and v == 0)}

