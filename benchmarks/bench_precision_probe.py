"""What ``--precision auto``'s probe (``bsp_fast.training.precision``) decides for every
model on this CPU, at the quick budgets' batch sizes, with random weights on fixture clips:
the median training step in float32 and in bf16 autocast, the ratio, the pick and the
probe's own time. A fresh cache each run (nothing is read from or written to the user's).

    PYTHONPATH=python python3 benchmarks/bench_precision_probe.py [--threads 1]
        [--models classification/lstm lifting/poseformer ...] [--device cuda]
        [--fixtures DIR] [--steps]

``--device cuda`` times the same steps on the GPU (wall time, the queue drained at each
reading) and prints both medians, their ratio and what ``auto``'s probe picks there.
``--fixtures DIR`` keeps the fixture clip files there (made if missing), so that a
machine without the C++ core, which makes them, can run on copies.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

#: (task/model, the quick budget's batch size, the fixture's clip length)
MODELS = [("classification/lstm", 64, 16), ("classification/pedestrian_graph", 64, 16),
          ("autoencoder/simple_transformer", 32, 30), ("lifting/baseline_3d", 64, 16),
          ("lifting/lstm", 64, 16), ("lifting/lstm_relative_rot", 64, 16),
          ("lifting/poseformer", 16, 16), ("pose_estimation/pose_cnn", 8, 4),
          ("pose_estimation/pose_temporal", 4, 30)]


def fixture(folder: str, name: str, batch_size: int, length: int) -> str:
    """The fixture clip file of ``name``'s task and clip length in ``folder`` (made if
    missing; benchmarks/gpu_check.sh makes them ahead for a machine without the core)."""
    from bsp_fast.data.testing import write_clip_file

    task = name.split("/")[0]
    h5 = os.path.join(folder, f"{task}-{length}.h5")
    if not os.path.exists(h5):
        write_clip_file(h5, clips=(max(batch_size, 16), 4, 4), clip_length=length,
                        media=task == "pose_estimation", crop_size=64, seed=1)
    return h5


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--models", nargs="+", default=[m for m, _, _ in MODELS])
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--fixtures", help="folder of the fixture clip files (made if missing)")
    p.add_argument("--steps", action="store_true",
                   help="CPU: also time the probe's steps where auto does not probe (a CPU "
                        "without native bf16, or kernels held to AVX2 by ONEDNN_MAX_CPU_ISA "
                        "and ATEN_CPU_CAPABILITY): float32 and bf16 ms/step and their ratio")
    args = p.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix="bench_precision_")
    fixtures = args.fixtures or tmp
    os.makedirs(fixtures, exist_ok=True)
    os.environ["BSP_PRECISION_PROBE"] = "1"
    os.environ["BSP_PRECISION_CACHE"] = os.path.join(tmp, "precision.json")
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset
    from bsp_fast.training import precision as P

    torch.set_num_threads(args.threads)
    native = [f for f in P.cpu_flags() if f in ("avx512_bf16", "amx_bf16")]
    print(f"CPU {P.cpu_summary()}; bf16: {', '.join(native) or 'none (AVX2 only)'}; "
          f"{args.threads} thread(s); "
          f"torch {torch.__version__}; load average {os.getloadavg()[0]:.1f}")
    gpu = args.device == "cuda"
    if gpu:
        print(f"GPU {torch.cuda.get_device_name()}; bf16 {torch.cuda.is_bf16_supported()}")
        print("| model | batch | float32 ms/step | bf16 ms/step | float32 / bf16 | auto picks "
              "| probe s |\n|---|---|---|---|---|---|---|")
    elif args.steps:
        print("| model | batch | auto picks | why | float32 ms/step | bf16 ms/step | "
              "float32 / bf16 |\n|---|---|---|---|---|---|---|")
    else:
        print("| model | batch | auto picks | why | probe s |\n|---|---|---|---|---|")
    for name, batch_size, length in MODELS:
        if name not in args.models:
            continue
        task, model = name.split("/")
        ds = ClipDataset(fixture(fixtures, name, batch_size, length), "train", task)
        batch = ds[list(range(min(batch_size, len(ds))))]
        torch.manual_seed(0)
        net = models.create(task, model)
        t0 = time.perf_counter()
        if gpu:
            try:
                probe = P.time_steps(net, batch, device="cuda")
                f32, b16 = probe(False), probe(True)
            except Exception as exc:  # the other models still run; the error is the row
                print(f"| {name} | {batch_size} | failed: {type(exc).__name__}: {exc} |")
                continue
            got, _ = P.decide_precision("auto", "gpu", net, probe=probe,
                                        key=f"{name} batch {batch_size} on the GPU")
            print(f"| {name} | {batch_size} | {f32 * 1e3:.1f} | {b16 * 1e3:.1f} | "
                  f"x{f32 / b16:.2f} | {got} | {time.perf_counter() - t0:.1f} |", flush=True)
            continue
        probe = P.time_steps(net, batch)
        got, why = P.decide_precision("auto", "cpu", net, probe=probe,
                                      key=f"{name} batch {batch_size}")
        if args.steps:  # the probe's medians (measured now if auto did not probe)
            f32, b16 = probe(False), probe(True)
            print(f"| {name} | {batch_size} | {got} | {why} | {f32 * 1e3:.1f} | "
                  f"{b16 * 1e3:.1f} | x{f32 / b16:.2f} |", flush=True)
            continue
        print(f"| {name} | {batch_size} | {got} | {why} | {time.perf_counter() - t0:.1f} |",
              flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
