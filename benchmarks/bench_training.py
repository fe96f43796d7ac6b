"""Training speed and accuracy of bsp-train per model and --precision (32 vs bf16-mixed).

Writes a generated file (bsp_fast.data.testing), trains each model with bsp_fast.train for
a few epochs in each precision and prints train clips/s (fit time over all clips of all
epochs, validation included) and the test metrics, so the precision default can be chosen
on measurements.

    PYTHONPATH=python python benchmarks/bench_training.py [--train-clips 2048]
        [--clip-length 30] [--epochs 3] [--threads 2] [--models lifting/baseline_3d ...]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

DEFAULT_MODELS = ("classification/lstm", "classification/pedestrian_graph",
                  "autoencoder/simple_transformer", "lifting/baseline_3d", "lifting/lstm",
                  "lifting/poseformer", "lifting/lstm_relative_rot")
MAIN = {"classification": "f1", "autoencoder": "pck_0.05", "lifting": "mpjpe_mm",
        "pose_estimation": "pck_0.05"}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--train-clips", type=int, default=2048)
    p.add_argument("--clip-length", type=int, default=30)
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--threads", type=int, default=os.cpu_count())
    p.add_argument("--models", nargs="+", default=list(DEFAULT_MODELS), metavar="TASK/MODEL")
    p.add_argument("--precisions", nargs="+", default=["32", "bf16-mixed"])
    args = p.parse_args(argv)
    import torch

    import bsp_fast
    from bsp_fast.data.testing import write_clip_file

    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
          f"{args.train_clips} train clips of L={args.clip_length}, batch {args.batch_size}, "
          f"{args.epochs} epochs, load average {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        h5 = Path(tmp) / "clips.h5"
        n = args.train_clips
        write_clip_file(h5, clips=(n, n // 4, n // 4), clip_length=args.clip_length,
                        frames_per_recording=8 * args.clip_length, seed=1, rotations=False)
        print("| model | precision | train clips/s | fit s | test metric |")
        print("|---|---|---:|---:|---:|")
        for spec in args.models:
            task, model = spec.split("/")
            # runs are named by task and model: lstm exists for two tasks
            for precision in args.precisions:
                t0 = time.perf_counter()
                try:
                    res = bsp_fast.train(task, model, data=h5,
                                         out=Path(tmp) / f"{task}-{model}-{precision}",
                                         epochs=args.epochs, batch_size=args.batch_size,
                                         precision=precision, accelerator="cpu", quiet=True)
                except ValueError as exc:  # e.g. no bf16 LSTM kernel on this CPU
                    print(f"| {task}/{model} | {precision} | refused: {exc} | | |", flush=True)
                    continue
                fit = res.seconds.get("fit", time.perf_counter() - t0)
                rate = n * args.epochs / fit
                key = MAIN[task]
                print(f"| {task}/{model} | {precision} | {rate:,.0f} | {fit:.1f} | "
                      f"{key} {res.metrics[key]:.4g} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
