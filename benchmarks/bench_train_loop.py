"""Training speed per model (#36, items 2, 3 and 5): a plain PyTorch loop in eager float32,
eager bf16 autocast, ``torch.compile`` float32 and bf16, and ``bsp-train`` end to end,
side by side in one run, each in a fresh process, the same optimiser updates on the same
batches with validation at the tables' cadence (once per epoch, the whole val split).

    PYTHONPATH=python python3 benchmarks/bench_train_loop.py [--epochs 2]
        [--models lifting/poseformer ...] [--modes eager32 eager_bf16 compiled32 ...]
        [--json out.json] [--fixtures DIR] [--accelerator gpu]

The plain loop is what a user would write: ``ClipDataset`` batches in a seeded random
order, the model's own loss and ``configure_optimizers`` (AdamW and its scheduler),
``torch.no_grad`` validation. Per mode the table gives clips/s of the steady state
(updates after the first two), the first update's seconds (the compile, for compiled
modes), and the whole process's wall seconds from start to exit (imports included), and
the validation loss after the last epoch (compiled vs eager: the same updates, so the
losses must agree within float32 / bf16 rounding). ``bsp-train`` runs with the tables'
options (``--precision`` as given, one thread, validation every epoch, checkpoints,
early stopping, CSV logs); its ratio to the plain loop at the same precision is item 3's
number. ``project_quick_s`` gives a quick-budget run's training seconds per mode:
first update + the budget's updates x the steady seconds per update. ``--repeat N`` trains
N runs per process, one after the other (a ``bsp-reproduce`` worker trains a table's
seeds so, paying the imports once); ``cpu_s`` is the process's CPU seconds, imports
included, which unlike wall time does not depend on the share of the cores a process got
on a loaded machine. ``--accelerator gpu`` trains on the GPU (batches moved there as a
user's loop would, each step timed to the drained queue; ``bsp-train`` with
``accelerator="gpu"``); ``--fixtures DIR`` keeps the generated clip files there (made if
missing), so that a machine without the C++ core, which makes them, can run on copies.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import tempfile
import time

T0 = time.perf_counter()

#: (task/model, the quick budget's batch size, clip length, the quick budget's updates)
MODELS = [("classification/lstm", 64, 16, 520), ("classification/pedestrian_graph", 64, 16, 520),
          ("autoencoder/simple_transformer", 32, 30, 570), ("lifting/baseline_3d", 64, 16, 500),
          ("lifting/lstm", 64, 16, 500), ("lifting/lstm_relative_rot", 64, 16, 500),
          ("lifting/poseformer", 16, 16, 500)]
MODES = ("eager32", "eager_bf16", "compiled32", "compiled_bf16", "bsp_train32",
         "bsp_train_bf16")


def _plain(job) -> dict:
    """One plain-loop run in this (fresh) process; returns its timings."""
    name, batch, h5, epochs, mode, t_start, updates, accelerator = job
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    torch.set_num_threads(1)
    dev = "cuda" if accelerator == "gpu" else "cpu"

    def to(b):
        return {k: v.to(dev, non_blocking=True) if isinstance(v, torch.Tensor) else v
                for k, v in b.items()} if dev != "cpu" else b

    def clock() -> float:
        if dev != "cpu":
            torch.cuda.synchronize()  # the step's kernels done, not only queued
        return time.perf_counter()
    task, model = name.split("/")
    bf16 = mode.endswith("bf16")
    train, val = ClipDataset(h5, "train", task), ClipDataset(h5, "val", task)
    torch.manual_seed(1)
    net = models.create(task, model).to(dev)
    if mode.startswith("compiled"):
        net.compute = torch.compile(net.compute, dynamic=False)  # as bsp-train --compile on
    opt = net.configure_optimizers(lr=None)
    opt = opt["optimizer"] if isinstance(opt, dict) else (opt[0][0] if isinstance(opt, tuple) else opt)
    g = torch.Generator().manual_seed(1)
    step_s, val_s, val_loss = [], 0.0, float("nan")
    for _ in range(epochs):
        net.train()
        order = torch.randperm(len(train), generator=g).tolist()
        for i in range(0, len(order), batch):  # the last batch may be short, as in bsp-train
            if updates and len(step_s) == updates:
                break
            t = clock()
            b = to(train[order[i:i + batch]])
            with torch.autocast(dev, dtype=torch.bfloat16, enabled=bf16):
                loss = net.loss(net.forward_batch(b), b)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step_s.append(clock() - t)
        t = clock()
        net.eval()
        total, n = 0.0, 0
        with torch.no_grad(), torch.autocast(dev, dtype=torch.bfloat16, enabled=bf16):
            for i in range(0, len(val), batch):
                b = to(val[list(range(i, min(i + batch, len(val))))])
                k = len(b["inputs"])
                total += float(net.loss(net.forward_batch(b), b)) * k
                n += k
        val_loss = total / n
        val_s += clock() - t
    t = clock()  # the test split scored once, as bsp-train does
    test = ClipDataset(h5, "test", task)
    with torch.no_grad(), torch.autocast(dev, dtype=torch.bfloat16, enabled=bf16):
        for i in range(0, len(test), batch):
            b = to(test[list(range(i, min(i + batch, len(test))))])
            net.loss(net.forward_batch(b), b)
    val_s += clock() - t
    steady = step_s[2:] or step_s
    return {"first_s": step_s[0], "step_s": sum(steady) / len(steady), "updates": len(step_s),
            "val_s": val_s, "val_loss": val_loss, "clips_per_s": batch / (sum(steady) / len(steady)),
            "fit_s": sum(step_s) + val_s, "total_s": time.time() - t_start}


def _bsp_train(job) -> dict:
    name, batch, h5, epochs, mode, t_start, updates, accelerator = job
    import bsp_fast

    task, model = name.split("/")
    out = os.path.join(os.path.dirname(h5), f"run-{task}-{model}-{mode}-{accelerator}")
    t = time.perf_counter()
    res = bsp_fast.train(task, model, data=h5, out=out, epochs=epochs, batch_size=batch,
                         precision="bf16-mixed" if mode.endswith("bf16") else "32",
                         threads=1, early_stop=0, seed=1, accelerator=accelerator, force=True,
                         max_steps=updates or 0)
    fit = time.perf_counter() - t
    return {"fit_s": fit, "total_s": time.time() - t_start,
            "val_loss": float(res.val.get("loss", float("nan"))), "seconds": res.seconds}


def _run(job, repeat: int = 1):
    """The job ``repeat`` times in this process (``--repeat``: a table's seeds as one
    ``bsp-reproduce`` worker trains them, imports paid once); the first run's timings,
    ``total_s`` the whole process's seconds until the last run ended."""
    fn = _bsp_train if job[4].startswith("bsp_train") else _plain
    first = fn(job)
    for _ in range(repeat - 1):  # a failed run raises: reaching the end means all ran
        fn(job)
    # CPU seconds of the whole process (imports included): under load, where wall time
    # depends on the share of the cores a process got, the comparable number
    return dict(first, total_s=time.time() - job[5], repeat=repeat, cpu_s=time.process_time())


def clip_file(folder: str, name: str, batch: int, length: int, train_clips: int) -> tuple:
    """``(path, train clips)`` of ``name``'s generated clip file for ``--train-clips`` in
    ``folder`` (made if missing; benchmarks/gpu_check.sh makes them ahead for a machine
    without the core); models at small batches get half the clips."""
    from bsp_fast.data.testing import write_clip_file

    n = train_clips if batch >= 32 else train_clips // 2
    h5 = os.path.join(folder, f"{name.replace('/', '-')}-{n}.h5")
    if not os.path.exists(h5):
        write_clip_file(h5, clips=(n, n // 4, n // 4), clip_length=length,
                        frames_per_recording=8 * length, seed=1, rotations=False)
    return h5, n


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--train-clips", type=int, default=1024)
    p.add_argument("--models", nargs="+", default=[m[0] for m in MODELS])
    p.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    p.add_argument("--updates", type=int, default=0,
                   help="optimiser updates per run (0: --epochs whole epochs); with "
                        "--train-clips 1152 and --updates 500 a run is a quick-budget run")
    p.add_argument("--repeat", type=int, default=1,
                   help="runs per process (a bsp-reproduce worker trains a table's seeds "
                        "one after the other in one process): imports are paid once")
    p.add_argument("--json", help="append one JSON line per (model, mode) to this file")
    p.add_argument("--fixtures", help="folder of the generated clip files (made if missing)")
    p.add_argument("--accelerator", choices=("cpu", "gpu"), default="cpu")
    args = p.parse_args(argv)
    from bsp_fast.models.lstm import cpu_bf16

    from bsp_fast.training.precision import cpu_summary

    print(f"CPU: {cpu_summary()}; bf16 autocast native: {cpu_bf16()}; "
          f"load average {os.getloadavg()[0]:.2f}; {args.train_clips} train clips, "
          f"{args.epochs} epochs, one thread per process", flush=True)
    if args.accelerator == "gpu":
        import torch

        print(f"GPU: {torch.cuda.get_device_name()}; torch {torch.__version__}", flush=True)
    elif not cpu_bf16():
        args.modes = [m for m in args.modes if not m.endswith("bf16")]
    tmp = args.fixtures or tempfile.mkdtemp(prefix="bench_train_loop_")
    os.makedirs(tmp, exist_ok=True)
    ctx = mp.get_context("spawn")
    print("| model | batch | mode | clips/s (steady) | first update s | fit s | process s | "
          "process CPU s | val loss | quick-budget train s (projected) |\n"
          "|---|---|---|---|---|---|---|---|---|---|")
    rows, failed = [], 0
    for name, batch, length, quick_updates in MODELS:
        if name not in args.models:
            continue
        h5, n = clip_file(tmp, name, batch, length, args.train_clips)
        for mode in args.modes:
            with ctx.Pool(1) as pool:  # a fresh process: imports and start-up counted
                steps = -(-n // batch)
                epochs = -(-args.updates // steps) if args.updates else args.epochs
                try:
                    r = pool.apply(_run, ((name, batch, h5, epochs, mode, time.time(),
                                           args.updates, args.accelerator), args.repeat))
                except Exception as exc:  # the other rows still run; the error is the row
                    print(f"| {name} | {batch} | {mode} | failed: {type(exc).__name__}: "
                          f"{exc} |", flush=True)
                    failed += 1
                    continue
            r.update(model=name, batch=batch, mode=mode, load=os.getloadavg()[0],
                     accelerator=args.accelerator)
            if "step_s" in r:
                r["project_quick_s"] = r["first_s"] + (quick_updates - 1) * r["step_s"]
            rows.append(r)
            print(f"| {name} | {batch} | {mode} | {r.get('clips_per_s', float('nan')):,.0f} | "
                  f"{r.get('first_s', float('nan')):.2f} | {r['fit_s']:.1f} | {r['total_s']:.1f} | "
                  f"{r['cpu_s']:.1f} | "
                  f"{r['val_loss']:.5f} | {r.get('project_quick_s', float('nan')):.0f} |",
                  flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(r) + "\n")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
