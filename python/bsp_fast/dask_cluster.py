"""Dask plumbing shared by ``bsp-convert`` and ``bsp-synth`` ``--scheduler dask[:ADDRESS]``.

``dask`` and ``distributed`` are the optional ``distributed`` extra
(``pip install 'bsp_fast[distributed]'``); nothing here imports them before a Dask
scheduler is asked for. See docs/distributed.md.
"""
from __future__ import annotations

import contextlib
import os

from ._extras import require

__all__ = ["parse_scheduler", "open_client", "run_on_scheduler", "worker_threads", "test_hook",
           "heap_for_media"]

SCHEDULER_HELP = ("threads (default: this process, C++ threads), dask (a local Dask cluster "
                  "with one single-threaded worker process per core) or dask:ADDRESS (an "
                  "existing Dask scheduler, e.g. dask:tcp://10.0.0.5:8786; the output and "
                  "the dataset must be on a filesystem every worker sees)")


def parse_scheduler(text: str):
    """``'threads'`` -> None; ``'dask'`` -> ``''`` (a LocalCluster);
    ``'dask:ADDRESS'`` -> ``'ADDRESS'``. Raises ValueError for anything else."""
    if text == "threads":
        return None
    if text == "dask":
        return ""
    if isinstance(text, str) and text.startswith("dask:") and len(text) > 5:
        return text[5:]
    raise ValueError(f"scheduler must be 'threads', 'dask' or 'dask:ADDRESS', got {text!r}")


@contextlib.contextmanager
def open_client(address: str, n_workers: int | None = None, needed_by: str = "bsp_fast"):
    """A ``distributed.Client``: connected to ``address``, or (empty address) to a new
    ``LocalCluster`` of ``n_workers`` (default: one per core) single-threaded worker
    processes without the statistical profiler, closed on exit."""
    distributed = require("distributed", needed_by)
    if address:
        client = distributed.Client(address)
        try:
            yield client
        finally:
            client.close()
        return
    n = n_workers or os.cpu_count() or 1
    import dask

    # Dask's statistical profiler samples every worker thread 100 times a second: measured
    # 10-15 % of a conversion task's CPU time (docs/distributed.md), so it is off here.
    with dask.config.set({"distributed.worker.profile.enabled": False}), \
            distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                     dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def run_on_scheduler(spec: str, prog: str, run):
    """A command's ``--scheduler SPEC``: ``run(None)`` for ``threads``, else ``run(client)``
    on the Dask cluster; returns what ``run`` returns. A bad SPEC is a ``ValueError``, a
    missing Dask an ``ImportError`` and an unreachable cluster an ``OSError``, each for the
    command's exit-code ladder (``command_line.run_command``: 2, 1, 1)."""
    address = parse_scheduler(spec)
    if address is None:
        return run(None)
    with open_client(address, needed_by=f"{prog} --scheduler dask") as client:
        return run(client)


def worker_threads(default: int = 1) -> int:
    """The calling task's share of its Dask worker's threads: ``nthreads`` divided by the
    tasks the worker is executing now (``default`` outside a worker)."""
    try:
        from distributed import get_worker

        w = get_worker()
    except (ImportError, ValueError):
        return default
    state = getattr(w, "state", None)
    n = getattr(w, "nthreads", None) or getattr(state, "nthreads", None) or default
    running = len(getattr(state, "executing", ()) or ()) or 1
    return max(1, int(n) // running)


@contextlib.contextmanager
def heap_for_media():
    """Lets glibc keep freed memory while a conversion task runs, and trims afterwards.

    Dask starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which also turns off
    glibc's adaptive mmap threshold: every frame buffer and crop block the decoder frees
    goes back to the kernel and the next one is faulted in again, page by page. Measured
    on 8 recordings x 300 frames at 1600x600, that made the media stage ~1.5x slower in a
    worker than in a plain process. Blocks below 32 MB now come from the heap and up to
    256 MB of free heap is kept during the task; ``malloc_trim(0)`` hands it back at the
    end, so the worker's memory looks as Dask expects between tasks.
    """
    libc = None
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD
        libc.mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):  # not glibc
        libc = None
    try:
        yield
    finally:
        if libc is not None:
            trim = os.environ.get("MALLOC_TRIM_THRESHOLD_", "")
            libc.mallopt(-1, int(trim) if trim.isdigit() else 128 << 10)
            libc.malloc_trim(0)


def test_hook(task: str, index: int) -> None:
    """Fault injection for the tests (environment variable ``BSP_FAST_TEST_DASK_HOOK``):

    * ``kill:TASK:INDEX:MARKER``: the first attempt of task ``TASK`` (``shard`` or ``clip``)
      number ``INDEX`` creates the file ``MARKER`` and ends its worker process with
      ``os._exit`` (the next attempt finds the marker and runs normally);
    * ``sleep:TASK:SECONDS[:MARKER]``: every such task sleeps first (to interrupt a run),
      after creating the file ``MARKER`` when given (so a test signals only once a task
      is sleeping, not while the cluster is still starting);
    * ``@PATH``: the spec is read from the file PATH when it exists (so that worker
      processes restarted after a kill see what the test sets).
    """
    spec = os.environ.get("BSP_FAST_TEST_DASK_HOOK", "")
    if spec.startswith("@"):
        try:
            with open(spec[1:], encoding="utf-8") as fh:
                spec = fh.read().strip()
        except FileNotFoundError:
            return
    if not spec:
        return
    parts = spec.split(":", 3)
    if parts[0] == "kill" and len(parts) == 4 and parts[1] == task and int(parts[2]) == index:
        try:
            fd = os.open(parts[3], os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return
        os.close(fd)
        os._exit(17)
    if parts[0] == "sleep" and len(parts) in (3, 4) and parts[1] == task:
        import time

        if len(parts) == 4:
            open(parts[3], "a", encoding="utf-8").close()
        time.sleep(float(parts[2]))
