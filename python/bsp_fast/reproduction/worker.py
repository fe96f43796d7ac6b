"""One long-lived training process per job slot of ``bsp-reproduce --seeds N --jobs J``.

A fresh ``python -m bsp_fast train`` per run paid 4-5 s of imports every time (Lightning
pulls in ``torch._dynamo``, torchmetrics and ``scipy.signal``; docs/performance.md,
"Training"), a third of a quick LSTM run. A worker imports once and trains the runs it is
given one after the other, each exactly as ``bsp-train --config CFG --force`` (or
``--resume RUN``) would in a process of its own: every run seeds and sets its threads
itself, and a test checks that a run trained after another in the same worker is
identical to one trained alone (tests/python/test_reproduce_worker.py).

Protocol: one JSON object per line on stdin, ``{"config": PATH}`` or ``{"resume": RUN}``
(and ``"quiet"``); after each run one line ``{"code": N}`` (bsp-train's exit status) on
the file descriptor named by the first argument, so that a run's own output on stdout
cannot be mistaken for it. End of stdin: the worker exits 0. SIGINT/SIGTERM stop the
run at a batch end as for bsp-train (resumable), and the worker exits with its status.
"""
from __future__ import annotations

import json
import os
import sys

__all__ = ["command", "main"]

#: bsp-train's exit statuses of a run stopped by SIGINT / SIGTERM (training/lifecycle.py)
STOPPED = (130, 143)


def command(fd: int) -> list:
    """The worker's command line, answering on file descriptor ``fd``."""
    return [sys.executable, "-m", "bsp_fast.reproduction.worker", str(fd)]


def _argv(job: dict) -> list:
    what = ["--resume", str(job["resume"])] if job.get("resume") else \
        ["--config", str(job["config"]), "--force"]
    return what + (["--quiet"] if job.get("quiet", True) else [])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) != 1 or not argv[0].isdigit():
        print("usage: python -m bsp_fast.reproduction.worker FD (started by bsp-reproduce)",
              file=sys.stderr)
        return 2
    from ..training.train import main as train_main

    with os.fdopen(int(argv[0]), "w", buffering=1) as answer:
        for line in sys.stdin:
            if not line.strip():
                continue
            code = train_main(_argv(json.loads(line)))
            sys.stdout.flush()
            sys.stderr.flush()
            answer.write(json.dumps({"code": int(code)}) + "\n")
            if code in STOPPED:  # the signal was meant for the whole command
                return int(code)
    return 0


if __name__ == "__main__":
    sys.exit(main())
