"""bsp-check against decoding the segmentation APNGs alone.

bsp-check reads every segmentation APNG once (files spread over threads; the C++ readers
release the GIL) and measures each annotated row's mask, plus it parses data.csv and opens
every MP4 (a packet scan, no decoding). The baseline is the least any mask check must do:
decode every frame of every APNG with the same reader on the same number of threads, one
file per thread at a time, discarding the pixels.

    python benchmarks/bench_check.py --dataset DIR [--threads 2] [--repeats 3]
    python benchmarks/bench_check.py --clips 32 --frames 900   # generates (cached) data

Without --dataset, a full-size bsp-synth dataset (1600x600, `video_preset: ultrafast`, as
the MP4s' encoding does not matter here) is generated once under --dir. Runs alternate
(baseline, check) --repeats times; the fastest of each counts, the ratio of each adjacent
pair and the process CPU seconds are printed too, and the load average before and after,
because the machine is shared.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def dataset(args) -> Path:
    if args.dataset:
        return Path(args.dataset)
    root = Path(args.dir) / f"check-{args.clips}x{args.frames}-1600x600-seed{args.seed}"
    if not (root / "data.csv").is_file():
        from bsp_fast.synth import generate

        cfg = Path(args.dir) / "bench_check_ultrafast.yaml"
        cfg.write_text("video_preset: ultrafast\n")
        t0 = time.perf_counter()
        generate(root, "full", clips=args.clips, frames=args.frames, seed=args.seed,
                 workers=os.cpu_count() or 1, config=cfg, progress=True, force=True)
        print(f"generated {root} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return root


def decode_all(path: str) -> int:
    from bsp_fast.media import ApngReader

    r = ApngReader(path)
    w, h = r.size
    step = max(1, (8 << 20) // (w * h))
    for start in range(0, len(r), step):
        r.read(np.arange(start, min(start + step, len(r))))
    return len(r)


def baseline(files: list, threads: int) -> tuple:
    t0, c0 = time.perf_counter(), time.process_time()
    with cf.ThreadPoolExecutor(max_workers=threads) as pool:
        frames = sum(pool.map(decode_all, files))
    return time.perf_counter() - t0, time.process_time() - c0, frames


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", help="an existing dataset (default: generate one)")
    p.add_argument("--clips", type=int, default=32)
    p.add_argument("--frames", type=int, default=900)
    p.add_argument("--seed", type=int, default=22752)
    p.add_argument("--dir", default=os.path.join(tempfile.gettempdir(), "bsp_bench"))
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    os.makedirs(args.dir, exist_ok=True)

    from bsp_fast.check import check_dataset

    root = dataset(args)
    files = sorted(str(f) for f in (root / "clips").glob("*.apng"))
    size_mb = sum(os.path.getsize(f) for f in files) / 1e6
    csv_mb = os.path.getsize(root / "data.csv") / 1e6
    load0 = os.getloadavg()
    base, chk, stage, bcpu, ccpu = [], [], [], [], []
    for _ in range(args.repeats):
        t, cpu, frames = baseline(files, args.threads)
        base.append(t)
        bcpu.append(cpu)
        t0, c0 = time.perf_counter(), time.process_time()
        rep = check_dataset(root, threads=args.threads)
        chk.append(time.perf_counter() - t0)
        ccpu.append(time.process_time() - c0)
        stage.append(rep["seconds"].get("media", float("nan")))
    load1 = os.getloadavg()
    b, c, m = min(base), min(chk), min(stage)
    paired = sorted(x / y for x, y in zip(chk, base))
    print(f"dataset: {root}: {len(files)} APNGs ({size_mb:.1f} MB, {frames} frames), "
          f"data.csv {rep['rows']} rows ({csv_mb:.0f} MB), {len(rep['recordings'])} "
          f"recordings; threads {args.threads}; repeats {args.repeats} (fastest counts)")
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, after "
          f"{load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; findings: {len(rep['findings'])}")
    print()
    print("| run | wall s | frames/s | vs decoding alone | CPU s |")
    print("|---|---:|---:|---:|---:|")
    print(f"| decode every APNG frame (baseline) | {b:.2f} | {frames / b:,.0f} | 1.00x | "
          f"{min(bcpu):.2f} |")
    print(f"| bsp-check, media stage | {m:.2f} | {frames / m:,.0f} | {m / b:.2f}x | |")
    print(f"| bsp-check, whole run (CSV, MP4 scans, masks, statistics) | {c:.2f} | "
          f"{frames / c:,.0f} | {c / b:.2f}x | {min(ccpu):.2f} |")
    print(f"\nwhole run / baseline, run by run (adjacent runs, sorted): "
          f"{', '.join(f'{x:.2f}' for x in paired)}; median {paired[len(paired) // 2]:.2f}; "
          f"CPU {min(ccpu) / min(bcpu):.2f}x")
    print(f"all runs (s): baseline {', '.join(f'{x:.2f}' for x in base)}; check "
          f"{', '.join(f'{x:.2f}' for x in chk)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
