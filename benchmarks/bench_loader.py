"""Clips per second of ``bsp_fast.data.ClipDataset`` against a naive per-item h5py reader.

Both loaders do the same per-clip work (read, deform, augment, normalise, to torch) and go
through a ``torch.utils.data.DataLoader`` with the same batch size and worker count, in the
same run. The naive reader is the usual first implementation: each ``__getitem__`` opens
the file, indexes one clip of each dataset it needs, transforms that clip and returns
tensors, which ``default_collate`` stacks; it reads random clips (``shuffle=True``).
``ClipDataset`` reads contiguous runs of clips with one HDF5 call per dataset and run and
transforms whole batches (``__getitems__``).

Without ``--h5`` the script writes a schema-v1 file with ``bsp_fast.data.testing``
(20,000 train clips by default; plus a small media file for ``pose_estimation``) to a
temporary directory. Train-split settings: noise sigma 5 px and missing-joint
probability 0.2944 (the report's first MJP) for the 2D-input tasks, flips and rotations
for classification and autoencoder. Rates exclude the first batch (worker start-up); the
CPU column is the CPU time of all processes per clip, start-up included.

    PYTHONPATH=python:build/<dir>/py python3 benchmarks/bench_loader.py
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import sys
import tempfile
import time

import h5py
import numpy as np
import torch
import torch.utils.data

from bsp_fast.data import ClipDataset, transforms as T
from bsp_fast.data.testing import write_clip_file

TASKS_2D = ("classification", "autoencoder", "lifting")


class NaiveClips(torch.utils.data.Dataset):
    """Open, index one clip, convert: the per-item reader the loaders are measured against."""

    def __init__(self, path, split, task, noise, mjp):
        self.path, self.split, self.task = path, split, task
        with h5py.File(path, "r") as f:
            self.n = len(f[split]["labels"])
        self.deform = T.Deform(noise, mjp) if task != "pose_estimation" else None
        self.augment = T.Compose([T.HorizontalFlip(0.5), T.RandomRotation(10.0)])

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        with h5py.File(self.path, "r") as f:
            g = f[self.split]
            px = g["projection_2d"][i]
            label = int(g["labels"][i])
            if self.task == "lifting":
                loc = g["targets/absolute_pose_loc"][i]
            if self.task == "pose_estimation":
                frames = g["clip_frames"][i]
                rgb = np.stack([g["frames/rgb"][k] for k in frames])
                box = g["frames/crop_box"][np.sort(frames)]
                vis = g["frames/joint_visible"][np.sort(frames)]
        if self.task == "pose_estimation":
            size = np.stack([box[:, 2] - box[:, 0], box[:, 3] - box[:, 1]], -1)
            crop = (px - box[:, None, :2]) * (rgb.shape[1] / size)[:, None, :]
            return {"inputs": torch.from_numpy(rgb).permute(0, 3, 1, 2),
                    "targets": torch.from_numpy(crop.astype(np.float32)),
                    "visible": torch.from_numpy(vis != 0), "label": label}
        rng = np.random.default_rng()
        if self.task != "lifting":
            px = self.augment(px, rng=rng, width=1600)
        n = T.normalize_hips_neck(self.deform(px, rng=rng))
        out = {"inputs": torch.from_numpy(n.points), "visible": torch.from_numpy(n.visible),
               "shift": torch.from_numpy(n.shift), "scale": torch.from_numpy(n.scale),
               "label": label}
        if self.task == "autoencoder":
            c = T.normalize_hips_neck(px)
            out.update(targets=torch.from_numpy(c.points), target_shift=torch.from_numpy(c.shift),
                       target_scale=torch.from_numpy(c.scale))
        elif self.task == "lifting":
            t, shift, scale = T.normalize_hips_neck_3d(loc)
            out.update(targets=torch.from_numpy(t), targets_m=torch.from_numpy(loc))
        return out


def _cpu() -> float:
    """CPU seconds of this process and of its exited children (the DataLoader workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _rate(loader, limit: int) -> tuple:
    """(clips/s after the first batch, i.e. worker start-up excluded, up to ``limit``;
    CPU seconds per clip of all processes over the whole run, start-up included;
    seconds to the first batch: worker start-up)."""
    c0 = _cpu()
    t_start = time.perf_counter()
    it = iter(loader)
    batch = next(it)
    first = time.perf_counter() - t_start
    total = len(batch["label"])
    n, t0 = 0, time.perf_counter()
    for batch in it:
        n += len(batch["label"])
        if n >= limit:
            break
    rate = n / (time.perf_counter() - t0) if n else float("nan")
    total += n
    del it, batch  # non-persistent workers exit here, so their CPU time is counted
    gc.collect()
    return rate, (_cpu() - c0) / total, first


def _batch(task, args) -> int:
    return args.pose_batch_size if task == "pose_estimation" else args.batch_size


def _fast(path, task, workers, args):
    kw = dict(noise=args.noise, mjp=args.mjp) if task != "pose_estimation" else {}
    ds = ClipDataset(path, "train", task, **kw)
    return ds.loader(_batch(task, args), num_workers=workers, persistent_workers=False)


def _naive(path, task, workers, args):
    ds = NaiveClips(path, "train", task, args.noise, args.mjp)
    return torch.utils.data.DataLoader(ds, batch_size=_batch(task, args), shuffle=True,
                                       num_workers=workers)


def _files(args, tmp):
    main = args.h5
    if main is None:
        main = os.path.join(tmp, "clips.h5")
        print(f"writing {args.clips} train clips of L={args.clip_length} to {main} ...",
              file=sys.stderr)
        write_clip_file(main, clips=(args.clips, 16, 16), clip_length=args.clip_length,
                        frames_per_recording=20 * args.clip_length, rotations=False)
    media = None
    if args.pose_clips > 0:
        media = os.path.join(tmp, "media.h5")
        write_clip_file(media, clips=(args.pose_clips, 8, 8), clip_length=args.clip_length,
                        media=True, crop_size=args.crop_size, rotations=False)
    return main, media


def run(args) -> list:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_loader_") as tmp:
        main, media = _files(args, tmp)
        jobs = [(t, main) for t in args.tasks if t in TASKS_2D]
        if media and "pose_estimation" in args.tasks:
            jobs.append(("pose_estimation", media))
        for task, path in jobs:
            for workers in args.workers:
                limit = args.limit if task != "pose_estimation" else args.pose_clips
                # best of --repeat runs: the machine may be shared, contention only slows
                fast, cpu, first = max(_rate(_fast(path, task, workers, args), limit)
                                       for _ in range(args.repeat))
                nlimit = args.pose_naive_limit if task == "pose_estimation" else args.naive_limit
                naive, ncpu, _ = max(_rate(_naive(path, task, workers, args),
                                           min(limit, nlimit))
                                     for _ in range(args.repeat))
                rows.append(dict(task=task, workers=workers, clips_per_s=fast,
                                 naive_clips_per_s=naive, speedup=fast / naive,
                                 cpu_us_per_clip=cpu * 1e6, naive_cpu_us_per_clip=ncpu * 1e6,
                                 first_batch_ms=first * 1e3))
                print(f"{task:16s} workers={workers}: {fast:10,.0f} clips/s  naive "
                      f"{naive:8,.0f} clips/s  x{fast / naive:.1f}  CPU/clip {cpu * 1e6:.0f} us "
                      f"(naive {ncpu * 1e6:.0f} us)  first batch {first * 1e3:.0f} ms "
                      f"load {os.getloadavg()[0]:.1f}", file=sys.stderr)
    return rows


def table(rows, args) -> str:
    out = [f"clip length {args.clip_length}, batch {args.batch_size} (pose_estimation "
           f"{args.pose_batch_size}, {args.crop_size}x{args.crop_size} crops), train split, noise "
           f"{args.noise} px, MJP {args.mjp}, {os.cpu_count()} cores, torch {torch.__version__}, "
           f"best of {args.repeat}, load average {os.getloadavg()[0]:.1f} at the end",
           "", "| task | workers | ClipDataset clips/s | naive h5py clips/s | speed-up | "
           "CPU us/clip (naive) | first batch ms |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['task']} | {r['workers']} | {r['clips_per_s']:,.0f} | "
                   f"{r['naive_clips_per_s']:,.0f} | {r['speedup']:.1f}x | "
                   f"{r['cpu_us_per_clip']:.0f} ({r['naive_cpu_us_per_clip']:.0f}) | "
                   f"{r['first_batch_ms']:.0f} |")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--h5", help="a bsp-convert file to read (default: write a fixture)")
    p.add_argument("--clips", type=int, default=20000, help="train clips of the fixture")
    p.add_argument("--clip-length", type=int, default=30, help="L of the fixture")
    p.add_argument("--pose-clips", type=int, default=1024,
                   help="train clips of the media fixture for pose_estimation (0: skip); "
                        "64 batches of 16, so worker start-up does not swamp the rate")
    p.add_argument("--crop-size", type=int, default=64, help="S of the media fixture's crops")
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--pose-batch-size", type=int, default=16, help="batch of pose_estimation")
    p.add_argument("--workers", type=int, nargs="+", default=[0, 2])
    p.add_argument("--tasks", nargs="+", default=list(TASKS_2D) + ["pose_estimation"])
    p.add_argument("--noise", type=float, default=5.0, help="Gaussian sigma (px)")
    p.add_argument("--mjp", type=float, default=0.2944, help="missing-joint probability")
    p.add_argument("--limit", type=int, default=40000, help="clips timed per loader run")
    p.add_argument("--pose-naive-limit", type=int, default=256,
                   help="clips the (slow) naive reader reads per pose_estimation run")
    p.add_argument("--naive-limit", type=int, default=2000,
                   help="clips timed per naive run (it is slow)")
    p.add_argument("--repeat", type=int, default=2, help="runs per configuration (best kept)")
    p.add_argument("--json", help="also write the rows as JSON here")
    args = p.parse_args(argv)
    rows = run(args)
    print(table(rows, args))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
