"""bsp-convert end to end, and its CSV stage against what users would otherwise run.

Same run, same generated file (random float32 poses, ~10 KB per row like the real data):

1. CSV stage on the first --csv-rows rows: pandas.read_csv + ast.literal_eval (the original
   tooling; timed on a subset, it is slow), a pyarrow.csv + pyarrow.compute pipeline (the
   fastest pure-Python route we found), and bsp_fast.read_csv with 1 and 2 threads.
2. The whole conversion of the full file (--rows, default 225,000 like the published
   dataset) with `bsp-convert` in a child process: wall time and peak resident memory,
   uncompressed and with --compress (file size, write time), each next to `wc -l` and
   `bsp_fast.read_csv` (pose columns, in this process) of the same file timed just before
   it, and the conversion's ratio to each (issue 59: at most 8x `wc -l`). Each conversion
   writes a new file: the previous run's output is deleted first, untimed (--replace keeps
   it, and the conversion then replaces it).

    PYTHONPATH=python:build/<name>/py python3 benchmarks/bench_convert.py [--rows 225000] [--csv-rows 20000]

To compare two builds side by side, generate the file once and convert it with each build in
turn (the child process inherits PYTHONPATH, so it runs the build named there):

    python3 benchmarks/bench_convert.py --data /tmp/bench --convert-only --repeat 3
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_csv  # noqa: E402  (the shared row generator and the Python alternatives)

import bsp_fast as bf  # noqa: E402


def _where(pkg: Path) -> str:
    """Which bsp_fast ran, without this machine's paths: the source tree's (relative to the
    repository) or an installed copy."""
    root = Path(__file__).resolve().parent.parent
    try:
        return f"from {pkg.resolve().relative_to(root)}"
    except ValueError:
        return "installed (site-packages)"

def write_dataset(root: Path, rows: int, seed: int = 0) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    cols = bench_csv.make_columns(rows, seed=seed)
    # Like the published data: long contiguous runs of annotated frames per recording
    # (~570 of 900), joints inside the image except for a few frames.
    ids = cols["id"]
    start = np.r_[True, ids[1:] != ids[:-1]]
    first = np.maximum.accumulate(np.where(start, np.arange(rows), 0))
    cols["frame.idx"] = (np.arange(rows) - first).astype(np.int64)
    uv = cols["frame.pedestrian.pose.camera"]
    uv[:] = np.clip(np.nan_to_num(uv, nan=100.0), 1.0, 599.0)
    uv[np.random.default_rng(seed).random(rows) < 0.002, 0] = np.nan
    bf.write_csv(root / "data.csv", cols)
    return root


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def csv_stage(path: Path, nrows: int, pandas_rows: int) -> list:
    size = os.path.getsize(path)
    mb_per_row = size / 1e6 / nrows
    res = []
    t, _ = timed(lambda: bench_csv.pandas_literal_eval(str(path), pandas_rows))
    res.append(("pandas + ast.literal_eval (original)", pandas_rows / t, pandas_rows * mb_per_row / t))
    t, _ = timed(lambda: bench_csv.arrow_pipeline(str(path)))
    res.append(("pyarrow.csv + pyarrow.compute split/cast", nrows / t, size / 1e6 / t))
    for th in (1, 2):
        t, _ = timed(lambda: bf.read_csv(path, columns=list(bench_csv.POSE_COLUMNS), threads=th))
        res.append((f"bsp_fast.read_csv, {th} thread{'s' if th > 1 else ''}", nrows / t, size / 1e6 / t))
    return res


def run_convert(dataset: Path, out: Path, *extra) -> tuple:
    # The child reports its own peak RSS (KiB) on its last stderr line. VmHWM, not ru_maxrss:
    # Linux carries ru_maxrss over from the forking parent (which holds the generated data).
    code = ("import re, sys; from bsp_fast.conversion import main; rc = main(sys.argv[1:]); "
            "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1), "
            "file=sys.stderr); sys.exit(rc)")
    cmd = [sys.executable, "-c", code, str(dataset), str(out), "--force", "--quiet", "--no-media", *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    peak_kib = int(p.stderr.strip().splitlines()[-1])
    return wall, peak_kib / 1024, os.path.getsize(out) / 1e6, cpu


def references(csv: Path) -> tuple:
    """Wall seconds of `wc -l` and of bsp_fast.read_csv (pose columns) of `csv`."""
    wc, _ = timed(lambda: subprocess.run(["wc", "-l", str(csv)], check=True, capture_output=True))
    rd, _ = timed(lambda: bf.read_csv(csv, columns=list(bench_csv.POSE_COLUMNS)))
    return wc, rd


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=225_000)
    ap.add_argument("--csv-rows", type=int, default=20_000)
    ap.add_argument("--pandas-rows", type=int, default=2_000)
    ap.add_argument("--dir", default=None, help="work directory (default: a temporary one)")
    ap.add_argument("--data", default=None,
                    help="keep the generated datasets in this folder and reuse them when present "
                         "(same --rows); the output HDF5 is written there too")
    ap.add_argument("--convert-only", action="store_true",
                    help="only the uncompressed whole conversion (no CSV stage, no --compress)")
    ap.add_argument("--compressed", action="store_true",
                    help="with --convert-only: the --compress conversion instead")
    ap.add_argument("--repeat", type=int, default=1, help="time each conversion N times")
    ap.add_argument("--replace", action="store_true",
                    help="convert over the previous run's output (--force replaces it) instead "
                         "of deleting it first, untimed: on ext4 the rename then writes the new "
                         "file back and the old one's blocks are freed (discarded, with the "
                         "discard mount option) in the converting process")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        tmp = Path(args.data) if args.data else Path(tmp)
        if args.convert_only:
            run = (("--compress (shuffle+deflate 1)", ("--compress",)) if args.compressed
                   else ("uncompressed (default)", ()))
            return convert_table(tmp, args, (run,))
        small = write_dataset(tmp / "small", args.csv_rows)
        stage = csv_stage(small / "data.csv", args.csv_rows, args.pandas_rows)
        base = stage[0][1]
        best_py = stage[1][1]
        print(f"CSV stage, pose columns, {args.csv_rows:,} rows "
              f"({os.path.getsize(small / 'data.csv') / 1e6:.0f} MB):\n")
        print("| reader | rows/s | MB/s | vs pandas | vs pyarrow |")
        print("|---|---:|---:|---:|---:|")
        for name, rps, mbs in stage:
            print(f"| {name} | {rps:,.0f} | {mbs:,.0f} | {rps / base:,.0f}× | {rps / best_py:.1f}× |")
        return convert_table(tmp, args, (("uncompressed (default)", ()),
                                         ("--compress (shuffle+deflate 1)", ("--compress",))))


def convert_table(tmp: Path, args, runs) -> int:
    full = tmp / "full"
    marker = full / f".rows-{args.rows}"  # a complete file of this size is already there
    t = 0.0
    if not marker.exists():
        t, _ = timed(lambda: write_dataset(full, args.rows, seed=1))
        marker.touch()
    size = os.path.getsize(full / "data.csv") / 1e9
    print(f"\nWhole conversion of {args.rows:,} rows ({size:.2f} GB data.csv, "
          f"{f'generated in {t:.0f} s' if t else 'reused'}), defaults (L = 30), 2 threads, "
          f"{'over the previous output' if args.replace else 'into a new file'}, "
          f"bsp_fast {_where(Path(bf.__file__).parent)}, load {os.getloadavg()[0]:.2f}:\n")
    # CPU s: user + system time of the child, all threads (less sensitive than the wall
    # time to other work on the machine, though not immune: caches and memory are shared).
    # wc -l and read_csv of the same file just before each conversion: the page cache and
    # the machine's load are then as alike as one run makes them.
    print("| output | wall s | CPU s | peak RSS MB | file MB | wc -l s | read_csv s | "
          "÷ wc -l | ÷ read_csv | load before |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, extra in runs:
        for _ in range(args.repeat):
            if not args.replace:  # untimed, and before the references: memory as it would be
                (tmp / "out.h5").unlink(missing_ok=True)
            load = os.getloadavg()[0]
            wc, rd = references(full / "data.csv")
            wall, peak, mb, cpu = run_convert(full, tmp / "out.h5", *extra)
            print(f"| {label} | {wall:.2f} | {cpu:.2f} | {peak:,.0f} | {mb:,.0f} | {wc:.2f} | "
                  f"{rd:.2f} | {wall / wc:.1f}× | {wall / rd:.1f}× | {load:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
