"""bsp-reproduce's seed runs: one fresh ``python -m bsp_fast train`` process per run (what
the runner did before, and what a user's shell loop does) against one long-lived worker
per job slot (reproduction/worker.py), side by side in one run on the same configs.

    PYTHONPATH=python python3 benchmarks/bench_reproduce_workers.py [--data FILE.h5]
        [--task classification --model lstm] [--runs 6] [--jobs 2] [--epochs 1]
        [--repeats 2] [--json out.json]

Without ``--data`` a synthetic clip file is written (bsp_fast.data.testing). Each mode
trains the same ``--runs`` configs (seeds 0..runs-1, one torch thread each, ``--jobs`` at
a time); the modes alternate ``--repeats`` times. Per mode: wall seconds, CPU seconds of
the processes it started (user + system), and the ratio fresh / workers. Both modes must
give the same test metrics run by run (checked; a difference is an error): the worker
changes where a run's imports are paid, not what it computes.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _configs(root: Path, data: Path, args, mode: str) -> list:
    import yaml

    out = []
    for seed in range(args.runs):
        run = root / mode / f"seed-{seed}"
        cfg = dict(task=args.task, model=args.model, data=str(data), out=str(run),
                   epochs=args.epochs, batch_size=args.batch_size, threads=1, seed=seed,
                   precision="32")
        path = root / f"{mode}-seed-{seed}.yaml"
        path.write_text(yaml.safe_dump(cfg))
        out.append((f"seed {seed}", path, None))
    return out


def fresh(todo, jobs: int) -> None:
    """One ``python -m bsp_fast train --config CFG --force --quiet`` process per run."""
    from bsp_fast.reproduction.runner import _env

    pending, running, env = list(todo), [], _env()
    while pending or running:
        while pending and len(running) < jobs:
            _, cfg, _ = pending.pop(0)
            running.append(subprocess.Popen(
                [sys.executable, "-m", "bsp_fast", "train", "--config", str(cfg), "--force",
                 "--quiet"], env=env, stdout=subprocess.DEVNULL))
        time.sleep(0.1)
        for p in list(running):
            if p.poll() is not None:
                running.remove(p)
                if p.returncode:
                    raise SystemExit(f"bsp-train exited with {p.returncode}")


def workers(todo, jobs: int) -> None:
    from bsp_fast.reproduction.runner import _run

    _run(todo, jobs, True, lambda *_: None)


def _metrics(root: Path, mode: str, runs: int) -> list:
    return [json.loads((root / mode / f"seed-{s}" / "metrics.json").read_text())["test"]
            for s in range(runs)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", help="a bsp-convert HDF5 file (default: a synthetic one)")
    ap.add_argument("--task", default="classification")
    ap.add_argument("--model", default="lstm")
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=1)
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", help="write the results here too")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-workers-") as tmp:
        root = Path(tmp)
        data = Path(args.data) if args.data else root / "clips.h5"
        if not args.data:
            from bsp_fast.data.testing import write_clip_file

            write_clip_file(data, clips=(256, 64, 64), clip_length=16, seed=1)
        rows = []
        for rep in range(args.repeats):
            for mode, fn in (("fresh", fresh), ("workers", workers)):
                todo = _configs(root, data, args, mode)
                cpu0, t0 = _children_cpu(), time.perf_counter()
                fn(todo, args.jobs)
                rows.append(dict(mode=mode, repeat=rep, wall_s=time.perf_counter() - t0,
                                 cpu_s=_children_cpu() - cpu0, load=os.getloadavg()[0]))
                print(f"{mode:8s} repeat {rep}: wall {rows[-1]['wall_s']:.1f} s, "
                      f"CPU {rows[-1]['cpu_s']:.1f} s, load {rows[-1]['load']:.2f}",
                      flush=True)
            same = _metrics(root, "fresh", args.runs) == _metrics(root, "workers", args.runs)
            if not same:
                raise SystemExit("a worker's run differs from the same run in a fresh process")

    def mean(mode, key):
        vals = [r[key] for r in rows if r["mode"] == mode]
        return sum(vals) / len(vals)

    from bsp_fast.training.precision import cpu_summary

    summary = {"cpu": cpu_summary(), "task": args.task, "model": args.model, "runs": args.runs,
               "jobs": args.jobs, "epochs": args.epochs, "rows": rows, "same_metrics": True,
               "wall_ratio": mean("fresh", "wall_s") / mean("workers", "wall_s"),
               "cpu_ratio": mean("fresh", "cpu_s") / mean("workers", "cpu_s"),
               "cpu_saved_per_run_s": (mean("fresh", "cpu_s") - mean("workers", "cpu_s"))
               / args.runs}
    print(f"{summary['cpu']}\nfresh / workers: wall x{summary['wall_ratio']:.2f}, CPU "
          f"x{summary['cpu_ratio']:.2f}; {summary['cpu_saved_per_run_s']:.1f} CPU s saved "
          f"per run; same test metrics run by run: yes")
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
