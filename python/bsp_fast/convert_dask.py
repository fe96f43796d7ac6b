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

import builtins
import math
import os
import shutil
import time
import uuid
from pathlib import Path

from ._native import core as _core
from .convert_report import problems

__all__ = ["convert_sharded", "shard_dir"]


def shard_dir(out: Path) -> Path:
    """The folder of shards next to ``out`` (``clips.h5`` -> ``clips.h5.shards``)."""
    return out.with_name(out.name + ".shards")


def _part_name(k: int) -> str:
    return f"part-{k:05d}.h5"


def _convert_shard(csv: str, folder: str, k: int, count: int, options: dict,
                   exclude: list) -> dict:
    """One Dask task: shard ``k`` of ``count`` into ``folder/part-k.h5`` (temporary name,
    renamed when complete; discarded when a media file failed)."""
    from ._dask import heap_for_media, test_hook, worker_threads

    test_hook("shard", k)
    t0 = time.perf_counter()
    opts = dict(options)
    if not opts.get("threads"):
        opts["threads"] = worker_threads()
    final = os.path.join(folder, _part_name(k))
    tmp = os.path.join(folder, f".{_part_name(k)}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        with heap_for_media():
            report = _core.convert_csv(csv, tmp, None, shard_count=count, shard_index=k,
                                       exclude=[tuple(e) for e in exclude], **opts)
        if report["shard_failures"]:
            Path(tmp).unlink(missing_ok=True)
        else:
            os.replace(tmp, final)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    report["shard"] = k
    report["seconds"]["task"] = time.perf_counter() - t0
    return report


def _raise_failure(f: dict):
    cls = getattr(_core, f["kind"], None) or getattr(builtins, f["kind"], RuntimeError)
    raise cls(f["reason"])


def _run_shards(client, csv, folder, count, options, exclude):
    futures = [client.submit(_convert_shard, csv, str(folder), k, count, options, exclude,
                             key=f"bsp-convert-shard-{k}-{uuid.uuid4().hex}", pure=False)
               for k in range(count)]
    try:
        return client.gather(futures)
    except BaseException:
        client.cancel(futures)
        raise


def convert_sharded(csv: str, out: Path, options: dict, client, *, shards=None,
                    strict=False, root=None) -> dict:
    """Converts on ``client``'s workers; ``options`` as for ``_core.convert_csv``. Writes
    ``out`` and ``shard_dir(out)`` (temporary names, renamed when complete) and returns the
    report (like the one-process one, plus ``shards`` and ``scheduler``)."""
    from .conversion import UnusableConversion

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
    token = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp_dir = out.with_name(f".{out.name}.tmp-{token}.shards")
    tmp_file = out.with_name(f".{out.name}.tmp-{token}")
    final_dir = shard_dir(out)
    try:
        tmp_dir.mkdir(parents=True)
        exclude: list = []
        passes = 1  # writes, as the one-process converter counts them
        while True:
            reports = _run_shards(client, csv, tmp_dir.absolute(), shards, options, exclude)
            failures = sorted((f for r in reports for f in r["shard_failures"]),
                              key=lambda f: (f["phase"], f["order"]))
            for f in failures:
                f["path"], f["reason"] = relabel(f["path"]), relabel(f["reason"])
            if not failures:
                break
            if not options.get("skip_bad_media"):
                _raise_failure(failures[0])
            for f in failures:  # plan again without them, as the one-process converter does
                exclude.append((*f["recording"], f["path"], f["reason"]))
            passes += any(f["phase"] == 1 for f in failures)  # found only while decoding
            for p in tmp_dir.iterdir():
                p.unlink()
        report = _merge(reports, passes, shards, time.perf_counter() - t0)
        report["media"]["enabled"] = bool(options.get("media", True))
        report["warnings"] = problems(report)
        if strict and report["warnings"]:
            raise UnusableConversion(f"{root}: unusable conversion (strict): "
                                     + "; ".join(report["warnings"]) + "; nothing written")
        for p in tmp_dir.iterdir():  # left by attempts whose worker died mid-write
            if p.name.startswith("."):
                p.unlink()
        _write_virtual(tmp_file, tmp_dir, final_dir.name, shards)
        _publish(tmp_file, tmp_dir, out, final_dir)
    except BaseException:
        tmp_file.unlink(missing_ok=True)
        shutil.rmtree(tmp_dir, ignore_errors=True)
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


def _copy_attrs(src, dst) -> None:
    for name in src.attrs:
        dst.attrs.create(name, src.attrs[name], dtype=src.attrs.get_id(name).dtype)


def _write_virtual(path: Path, folder: Path, rel_folder: str, count: int) -> None:
    """``path``: the root and group attributes of shard 0 and one virtual dataset per
    dataset, the shards' pieces concatenated along axis 0 (sources: ``rel_folder/part-k``,
    relative to ``path``'s folder)."""
    import h5py

    parts = [h5py.File(folder / _part_name(k), "r") for k in range(count)]
    try:
        first = parts[0]
        names: list = []
        first.visit(names.append)
        with h5py.File(path, "w", libver="latest") as out:
            _copy_attrs(first, out)
            for name in names:
                obj = first[name]
                if isinstance(obj, h5py.Group):
                    _copy_attrs(obj, out.require_group(name))
                    continue
                pieces = [p[name] for p in parts]
                total = sum(d.shape[0] for d in pieces)
                layout = h5py.VirtualLayout(shape=(total,) + obj.shape[1:], dtype=obj.dtype)
                at = 0
                for k, d in enumerate(pieces):
                    n = d.shape[0]
                    if n:
                        layout[at:at + n] = h5py.VirtualSource(
                            f"{rel_folder}/{_part_name(k)}", name, shape=d.shape,
                            dtype=d.dtype)
                    at += n
                ds = out.create_virtual_dataset(name, layout)
                _copy_attrs(obj, ds)
    finally:
        for p in parts:
            p.close()


def _publish(tmp_file: Path, tmp_dir: Path, out: Path, final_dir: Path) -> None:
    """Renames the shards' folder, then the file, into place (an old folder is moved aside
    first and removed last; without the file nothing is published)."""
    old = None
    if final_dir.exists():
        old = final_dir.with_name(f".{final_dir.name}.old-{uuid.uuid4().hex[:8]}")
        os.replace(final_dir, old)
    os.replace(tmp_dir, final_dir)
    os.replace(tmp_file, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
