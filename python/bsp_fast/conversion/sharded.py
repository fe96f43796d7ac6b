"""``bsp_fast.convert(..., client=...)`` / ``bsp-convert --scheduler dask``: the conversion
as Dask tasks, one per shard, and an ``OUT.h5`` of HDF5 virtual datasets over the shards.

Every shard task runs the C++ converter (``_core.convert_csv`` with ``shard_index`` /
``shard_count``): it reads data.csv, plans the whole split exactly as the one-process
converter does (same seed, same clips, same frame tables) and writes its part: clips
``[N*k/K, N*(k+1)/K)`` of each split and a contiguous run of whole recordings of the frame
tables. The shards, concatenated along the first axis, are the one-process file, so the
driver only writes ``OUT.h5``: the shards' attributes and, for every dataset, a virtual
dataset mapping the shards' pieces in order (paths relative to ``OUT.h5``). Media failures
come back from the tasks as values, so the driver raises the same error the one-process
converter meets first, or (``skip_bad_media``) plans again without the recordings, as that
converter does. See docs/distributed.md.
"""
from __future__ import annotations

import math
import os
import time
import uuid
from pathlib import Path

from .._native import core as _core
from ..atomic import publish, remove, temp_path
from .errors import UnusableConversion
from .report import problems
from .vds import part_name, write_virtual

__all__ = ["convert_sharded", "shard_dir"]


def shard_dir(out: Path) -> Path:
    """The folder of shards next to ``out`` (``clips.h5`` -> ``clips.h5.shards``)."""
    return out.with_name(out.name + ".shards")


def _convert_shard(csv: str, folder: str, k: int, count: int, options: dict,
                   exclude: list) -> dict:
    """One Dask task: shard ``k`` of ``count`` into ``folder/part-k.h5`` (temporary name,
    renamed when complete; discarded when a media file failed)."""
    from ..dask_cluster import heap_for_media, test_hook, worker_threads

    test_hook("shard", k)
    t0 = time.perf_counter()
    opts = dict(options)
    if not opts.get("threads"):
        opts["threads"] = worker_threads()
    final = Path(folder) / part_name(k)
    tmp = temp_path(final)
    try:
        with heap_for_media():
            report = _core.convert_csv(csv, str(tmp), None, shard_count=count, shard_index=k,
                                       exclude=[tuple(e) for e in exclude], **opts)
        if report["shard_failures"]:
            remove(tmp)
        else:  # a retried task may find its earlier attempt's part: the same bytes
            publish(tmp, final, force=True)
    except BaseException:
        remove(tmp)
        raise
    report["shard"] = k
    report["seconds"]["task"] = time.perf_counter() - t0
    return report


def _raise_failure(f: dict):
    """Raises the shard's failure as the one-process converter raises it: the same type
    (``f["kind"]``, a ``_core.ErrorKind``, mapped back to its class by the core) and message."""
    _core.raise_error(f["kind"], f["reason"])


def _run_shards(client, csv, folder, count, options, exclude):
    futures = [client.submit(_convert_shard, csv, str(folder), k, count, options, exclude,
                             key=f"bsp-convert-shard-{k}-{uuid.uuid4().hex}", pure=False)
               for k in range(count)]
    try:
        return client.gather(futures)
    except BaseException:
        client.cancel(futures)
        raise


def _run_until_clean(client, csv, tmp_dir: Path, shards: int, options: dict, relabel):
    """Runs the shards until none fails: each pass plans again without the media files
    the last one could not use (as the one-process converter does), or raises the first
    failure unless ``skip_bad_media``. Returns the reports and the writes counted as the
    one-process converter counts them."""
    exclude: list = []
    passes = 1
    while True:
        reports = _run_shards(client, csv, tmp_dir.absolute(), shards, options, exclude)
        failures = sorted((f for r in reports for f in r["shard_failures"]),
                          key=lambda f: (int(f["phase"]), f["order"]))
        for f in failures:
            f["path"], f["reason"] = relabel(f["path"]), relabel(f["reason"])
        if not failures:
            return reports, passes
        if not options.get("skip_bad_media"):
            _raise_failure(failures[0])
        for f in failures:
            exclude.append((*f["recording"], f["path"], f["reason"]))
        # found only while decoding: the one-process converter had written the file
        passes += any(f["phase"] == _core.FailurePhase.decode for f in failures)
        for p in tmp_dir.iterdir():
            p.unlink()


def convert_sharded(csv: str, out: Path, options: dict, client, *, shards=None,
                    strict=False, root=None, force=False) -> dict:
    """Converts on ``client``'s workers; ``options`` as for ``_core.convert_csv``. Writes
    ``out`` and ``shard_dir(out)`` (temporary names, renamed when complete) and returns the
    report (like the one-process one, plus ``shards`` and ``scheduler``)."""
    if shards is None:
        shards = max(1, len(client.nthreads()))  # one per worker, with its threads
    # Workers get absolute paths (their working directory is not ours); media failures
    # name files the way the one-process converter does, relative to the path given.
    given = os.path.dirname(csv) or "."
    csv = os.path.abspath(csv)
    here = os.path.dirname(csv)

    def relabel(text: str) -> str:
        return text.replace(here + os.sep, given + os.sep) if here != given else text

    t0 = time.perf_counter()
    tmp_file = temp_path(out)
    tmp_dir = tmp_file.with_name(tmp_file.name + ".shards")
    final_dir = shard_dir(out)
    try:
        tmp_dir.mkdir(parents=True)
        reports, passes = _run_until_clean(client, csv, tmp_dir, shards, options, relabel)
        report = _merge(reports, passes, shards, time.perf_counter() - t0)
        report["media"]["enabled"] = bool(options.get("media", True))
        report["warnings"] = problems(report)
        if strict and report["warnings"]:
            raise UnusableConversion(f"{root}: unusable conversion (strict): "
                                     + "; ".join(report["warnings"]) + "; nothing written")
        for p in tmp_dir.iterdir():  # left by attempts whose worker died mid-write
            if p.name.startswith("."):
                p.unlink()
        write_virtual(tmp_file, tmp_dir, final_dir.name, shards)
        # The shards' folder first (it belongs to `out`; without the file nothing is
        # published), then the file, each swapped in atomically.
        publish(tmp_dir, final_dir, force=True)
        publish(tmp_file, out, force=force)
    except BaseException:
        remove(tmp_file)
        remove(tmp_dir)
        raise
    report["output"] = str(out)
    report["shard_dir"] = str(final_dir)
    return report


def _merge(reports: list, passes: int, shards: int, seconds: float) -> dict:
    """Shard 0's report (the whole plan; its verification) with the media summed."""
    report = dict(reports[0])
    report.pop("shard_failures", None)
    report.pop("shard", None)
    media = dict(report["media"])
    media["frames"] = {s: sum(r["media"]["frames"][s] for r in reports)
                       for s in ("train", "val", "test")}
    media["fully_occluded"] = {s: sum(r["media"]["fully_occluded"][s] for r in reports)
                               for s in ("train", "val", "test")}
    media["passes"] = passes
    media["check_seconds"] = max(r["media"]["check_seconds"] for r in reports)
    media["seconds"] = max(r["media"]["seconds"] for r in reports)
    frames = sum(media["frames"].values())
    media["crops_per_second"] = frames / seconds if seconds > 0 and frames else math.nan
    report["media"] = media
    report["seconds"] = {k: max(r["seconds"].get(k, 0.0) for r in reports)
                         for k in reports[0]["seconds"]}
    report["seconds"]["total"] = seconds
    report["seconds"]["tasks_sum"] = sum(r["seconds"]["task"] for r in reports)
    report["shards"] = shards
    report["scheduler"] = "dask"
    return report
