"""bsp-convert on Dask against the built-in threads, on one machine.

1. Generates (once; cached under --dir) a full-size bsp-synth dataset: --clips recordings of
   --frames frames at 1600x600 (the published dataset's image size).
2. Converts it with media (128 x 128 crops of clips of 16 frames every 6 frames) four
   ways: the one-process converter with 1 and 2 threads, and ``convert(..., client=...)`` on
   a LocalCluster of 1 and 2 single-threaded worker processes (one shard per worker),
   started as bsp-convert --scheduler dask starts it.
   Each runs --repeats times, interleaved, the fastest counts; the clusters are started
   before timing (their start-up time is reported apart). The Dask outputs are checked equal to the
   threaded one.
3. Prints a table: wall seconds (best and median), median CPU seconds, crops/s (best), speed-up over 1 thread, Dask time / threads time
   at the same core count (the overhead of the Dask path), and the 1-minute load average
   before and after each configuration (the machine is shared).

4. With --synth-clips N: bsp-synth of N clips (--frames frames at 1600x600) with
   --workers 2 against --scheduler dask (2 workers), interleaved, byte-identical checked.

    python benchmarks/bench_distributed.py [--clips 8] [--frames 300] [--repeats 2]
                                           [--synth-clips 0]
"""
from __future__ import annotations

import argparse
import contextlib
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# generated once, cached under --dir by --clips, --frames and --seed (shared with that script)
from bench_convert_media import dataset

OPTS = dict(clip_length=16, clip_offset=6, crop_size=128)


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run_once(fn, client=None) -> dict:
    """Wall seconds and CPU seconds of this process plus (with a client) its workers."""
    def cpu():
        return cpu_seconds() + (sum(client.run(cpu_seconds).values()) if client else 0.0)

    load, c0 = os.getloadavg()[0], cpu()
    t0 = time.perf_counter()
    rep = fn()
    wall = time.perf_counter() - t0
    return dict(wall=wall, cpu=cpu() - c0, frames=sum(rep["media"]["frames"].values()),
                load=load, outside=wall - rep["seconds"].get("task", wall))


def same(a: Path, b: Path) -> bool:
    import h5py

    names = []
    with h5py.File(a) as fa, h5py.File(b) as fb:
        fa.visit(names.append)
        for n in names:
            if isinstance(fa[n], h5py.Dataset) and not np.array_equal(fa[n][...], fb[n][...]):
                return False
    return True


def bench_synth(args) -> int:
    import filecmp

    from bsp_fast.dask_cluster import open_client
    from bsp_fast.synth import generate

    out = Path(args.dir) / "synth-dist"
    kw = dict(clips=args.synth_clips, frames=args.frames, size="1600x600", seed=args.seed,
              progress=False, force=True)
    times: dict = {"--workers 2": [], "--scheduler dask (2 workers)": []}
    with open_client("", n_workers=2) as client:
        for _ in range(args.repeats):
            for name, extra in (("--workers 2", dict(workers=2)),
                                ("--scheduler dask (2 workers)", dict(client=client))):
                load = os.getloadavg()[0]
                t0 = time.perf_counter()
                generate(out / name.split()[0].strip("-"), "sample", **kw, **extra)
                times[name].append((time.perf_counter() - t0, load))
    a, b = out / "workers", out / "scheduler"
    files = [str(p.relative_to(a)) for p in a.rglob("*") if p.is_file()]
    _, bad, err = filecmp.cmpfiles(a, b, files, shallow=False)
    print(f"bsp-synth {args.synth_clips} clips x {args.frames} frames at 1600x600, "
          f"{args.repeats} interleaved runs; byte-identical: {not bad and not err}")
    print("| mode | wall s (best) | wall s (median) | load (1 min) at the starts |")
    print("|---|---:|---:|---|")
    for name, runs in times.items():
        walls = [w for w, _ in runs]
        loads = [x for _, x in runs]
        print(f"| {name} | {min(walls):.1f} | {np.median(walls):.1f} | "
              f"{min(loads):.1f}-{max(loads):.1f} |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clips", type=int, default=8)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--dir", default=os.path.join(tempfile.gettempdir(), "bsp_bench_media"))
    ap.add_argument("--synth-clips", type=int, default=0)
    args = ap.parse_args(argv)
    if args.synth_clips:
        return bench_synth(args)
    import warnings

    import bsp_fast as bf
    from bsp_fast.dask_cluster import open_client

    warnings.filterwarnings("ignore", message="bsp_fast.convert")

    root = dataset(args)
    out = Path(args.dir) / "dist"
    out.mkdir(exist_ok=True)
    starts, configs = {}, {}
    with contextlib.ExitStack() as stack:
        for w in (1, 2):  # started first, as bsp-convert --scheduler dask starts them
            t0 = time.perf_counter()
            client = stack.enter_context(open_client("", n_workers=w))
            client.wait_for_workers(w)
            starts[w] = time.perf_counter() - t0
            configs[f"dask, {w} worker{'s' if w > 1 else ''}"] = (client, dict(
                client=client, shards=w), out / f"d{w}.h5")
        for t in (1, 2):
            configs[f"threads, {t}"] = (None, dict(threads=t), out / f"t{t}.h5")
        order = ["threads, 1", "threads, 2", "dask, 1 worker", "dask, 2 workers"]
        runs: dict = {name: [] for name in order}
        for _ in range(args.repeats):  # interleaved: the shared machine's load drifts
            for name in order:
                client, kw, path = configs[name]
                runs[name].append(run_once(lambda kw=kw, path=path: bf.convert(
                    root, path, force=True, **kw, **OPTS), client))
    rows = {}
    for name in order:
        best = min(runs[name], key=lambda r: r["wall"])
        best["load"] = (min(r["load"] for r in runs[name]), max(r["load"] for r in runs[name]))
        best["median"] = float(np.median([r["wall"] for r in runs[name]]))
        best["cpu"] = float(np.median([r["cpu"] for r in runs[name]]))
        rows[name] = best
    for w in (1, 2):
        assert same(out / "t2.h5", out / f"d{w}.h5"), f"dask {w} output differs"
    base = rows["threads, 1"]["wall"]
    print(f"{args.clips} recordings x {args.frames} frames, 1600x600, "
          f"{rows['threads, 1']['frames']} crops, {args.repeats} interleaved runs each; "
          f"{os.cpu_count()} cores")
    print("| converter | cores | wall s (best) | wall s (median) | CPU s (median) | crops/s | "
          "speed-up vs 1 thread | "
          "wall vs threads, same cores | Dask: s outside the slowest task | "
          "load (1 min) at the starts |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for name, r in rows.items():
        cores = 1 if name.endswith(" 1") or "1 worker" in name else 2
        ref = rows[f"threads, {cores}"]["wall"]
        outside = f"{r['outside']:.2f}" if name.startswith("dask") else ""
        print(f"| {name} | {cores} | {r['wall']:.2f} | {r['median']:.2f} | {r['cpu']:.2f} | "
              f"{r['frames'] / r['wall']:.0f} | {base / r['wall']:.2f} | "
              f"{r['wall'] / ref:.3f} | {outside} | {r['load'][0]:.1f}-{r['load'][1]:.1f} |")
    print("cluster start-up (not in the times above): "
          + ", ".join(f"{w} worker(s) {s:.1f} s" for w, s in starts.items()))
    print("Dask outputs equal the threaded output: yes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
