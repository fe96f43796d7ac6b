"""Training-step CPU time of the pose networks with their activations in NCHW against
channels_last (the ``MEMORY_FORMAT`` of ``bsp_fast.models.pose_temporal`` and
``pose_cnn``; the "default" column is what each uses), float32 and bf16 autocast, one
thread: forward, loss, backward and AdamW on random crops at the quick budget's batch (4
clips x 30 frames). The formats are timed in turn (ABAB...) so that a change of load hits
both; the median step's process CPU time is reported, with the ratio channels_last / NCHW.

    PYTHONPATH=python python3 benchmarks/bench_memory_format.py [--crop 64] [--steps 6]
        [--models pose_temporal pose_cnn]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--models", nargs="+", default=["pose_temporal", "pose_cnn"])
    p.add_argument("--crop", type=int, default=64)
    p.add_argument("--clips", type=int, default=4)
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--steps", type=int, default=6, help="timed steps per format (6)")
    args = p.parse_args(argv)
    import importlib

    import torch

    from bsp_fast import models
    from bsp_fast.models.base import activation_layout
    from bsp_fast.training import precision as P

    torch.set_num_threads(1)
    native = [f for f in P.cpu_flags() if f in ("avx512_bf16", "amx_bf16")]
    print(f"CPU {P.cpu_summary()}; bf16: {', '.join(native) or 'none (AVX2 only)'}; 1 thread; "
          f"torch {torch.__version__}; load average {os.getloadavg()[0]:.1f}; "
          f"{args.clips} clips x {args.frames} frames of {args.crop} px")
    print("| model | precision | NCHW CPU s/step | channels_last | channels_last / NCHW | "
          "default |\n|---|---|---|---|---|---|")
    formats = {"NCHW": torch.contiguous_format, "channels_last": torch.channels_last}
    g = torch.Generator().manual_seed(0)
    S, B, L = args.crop, args.clips, args.frames
    batch = {"inputs": torch.randint(0, 256, (B, L, 3, S, S), generator=g, dtype=torch.uint8),
             "targets": torch.rand(B, L, 26, 2, generator=g) * S,
             "visible": torch.rand(B, L, 26, generator=g) > 0.3}
    for name in args.models:
        module = importlib.import_module(f"bsp_fast.models.{name}")
        default = module.MEMORY_FORMAT
        for dtype in ("float32", "bf16"):
            torch.manual_seed(0)
            net = models.create("pose_estimation", name)
            opt = torch.optim.AdamW(net.parameters(), 1e-3)

            def step():
                with torch.autocast("cpu", dtype=torch.bfloat16, enabled=dtype == "bf16"):
                    loss = net.loss(net.forward_batch(batch), batch)
                opt.zero_grad()
                loss.backward()
                opt.step()

            times = {k: [] for k in formats}
            try:
                for k, fmt in formats.items():  # one warm-up step each
                    module.MEMORY_FORMAT = fmt
                    step()
                for _ in range(args.steps):
                    for k, fmt in formats.items():
                        module.MEMORY_FORMAT = fmt
                        t = time.process_time()
                        step()
                        times[k].append(time.process_time() - t)
            finally:
                module.MEMORY_FORMAT = default
            a, b = (statistics.median(times[k]) for k in formats)
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=dtype == "bf16"):
                used = activation_layout(default)
            which = "NCHW" if used == torch.contiguous_format else "channels_last"
            print(f"| {name} | {dtype} | {a:.3f} | {b:.3f} | x{b / a:.2f} | {which} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
