"""Seeds on two cores (#36, item 4): for each model, training clips per second of two
seeds run as two processes of one torch thread each, against one process of two threads
running them one after the other (what ``bsp-reproduce --seeds N --jobs 2`` and
``--jobs 1 --set threads=2`` do). Plain training steps (forward, loss, backward, AdamW) of
fresh models on one fixture batch each, the quick budgets' batch sizes, float32 and bf16
autocast where the CPU has native bf16 (what ``--precision auto``'s probe picks here).

    PYTHONPATH=python python3 benchmarks/bench_seed_layout.py [--steps 6]
        [--models classification/lstm lifting/poseformer ...] [--sync-delay 20]

The two processes' timed steps start at one moment after their imports and warm-up, so
process start-up is not counted on either side.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import time

#: (task/model, the quick budget's batch size, clip length)
MODELS = [("classification/lstm", 64, 16), ("classification/pedestrian_graph", 64, 16),
          ("autoencoder/simple_transformer", 32, 30), ("lifting/baseline_3d", 64, 16),
          ("lifting/lstm_relative_rot", 64, 16), ("lifting/poseformer", 16, 16)]


def _train(args) -> float:
    """Seconds for ``steps`` training steps of one fresh model with ``threads`` threads."""
    name, batch_size, length, h5, steps, threads, bf16, seed, start_at = args
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    torch.set_num_threads(threads)
    task, model = name.split("/")
    ds = ClipDataset(h5, "train", task)
    batch = ds[list(range(min(batch_size, len(ds))))]
    torch.manual_seed(seed)
    net = models.create(task, model).train()
    opt = torch.optim.AdamW(net.parameters(), lr=1e-4)

    def step():
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            loss = net.loss(net.forward_batch(batch), batch)
        opt.zero_grad(set_to_none=True)
        loss.float().backward()
        opt.step()

    step()  # warm-up
    if start_at:  # both processes start their timed steps together
        time.sleep(max(0.0, start_at - time.time()))
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return time.perf_counter() - t0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=6)
    p.add_argument("--sync-delay", type=float, default=20.0,
                   help="seconds the two processes get to import and warm up before their "
                        "timed steps start together")
    p.add_argument("--models", nargs="+", default=[m for m, _, _ in MODELS])
    args = p.parse_args(argv)
    from bsp_fast.data.testing import write_clip_file
    from bsp_fast.models.lstm import cpu_bf16

    bf16 = cpu_bf16()
    tmp = tempfile.mkdtemp(prefix="bench_seed_layout_")
    print(f"{os.cpu_count()} cores, bf16 autocast: {bf16}, load average "
          f"{os.getloadavg()[0]:.1f}")
    print("| model | batch | 1 process x 2 threads, 2 seeds in turn: clips/s | 2 processes x "
          "1 thread at once: clips/s | 2x1 / 1x2 |\n|---|---|---|---|---|")
    ctx = mp.get_context("spawn")
    for name, batch_size, length in MODELS:
        if name not in args.models:
            continue
        h5 = os.path.join(tmp, f"{length}.h5")
        if not os.path.exists(h5):
            write_clip_file(h5, clips=(64, 4, 4), clip_length=length, seed=1)
        clips = 2 * args.steps * batch_size
        job = (name, batch_size, length, h5, args.steps)
        with ctx.Pool(1) as pool:  # a fresh process, like a run
            serial = sum(pool.map(_train, [job + (2, bf16, s, 0.0) for s in (1, 2)]))
        with ctx.Pool(2) as pool:  # timed from a common start, after imports and warm-up
            start = time.time() + args.sync_delay
            parallel = max(pool.map(_train, [job + (1, bf16, s, start) for s in (1, 2)]))
        print(f"| {name} | {batch_size} | {clips / serial:,.0f} | {clips / parallel:,.0f} | "
              f"{serial / parallel:.2f} |", flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
