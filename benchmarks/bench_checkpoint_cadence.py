"""``last.ckpt`` at every epoch end against ``last.ckpt`` by time (``--checkpoint-every``),
side by side in one process (#36, item 3).

    PYTHONPATH=python python3 benchmarks/bench_checkpoint_cadence.py [--rounds 3]
        [--epochs 60] [--data DATASET_OR_H5] [--json out.jsonl]

PedestrianGraph with the classification ablation's matched-updates settings (batch 64,
σ 5 + MJP 0.7187, float32, one thread, validation and ``best.ckpt`` every epoch) for
``--epochs`` epochs, alternately with ``--checkpoint-every 0`` (a save at every epoch end,
the behaviour before 2026-11-27) and ``5m`` (the default: by time, and after the last
epoch). Without ``--data`` the runs read a generated clip file of about the ablation's
size (``--train-clips``, default about 832 train windows: 13-14 updates an epoch). Per
cadence: the median fit CPU seconds (``metrics.json`` ``fit_cpu``: steal on a shared
machine does not count), the saves of ``last.ckpt`` and the test metrics, which must not
differ (a save changes no state).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

CADENCES = ("0", "5m")


def clip_file(folder: str, train_clips: int) -> str:
    """Windows of the matched-updates rows' shape: about 832 train windows, 206 val."""
    from bsp_fast.data.testing import write_clip_file

    path = os.path.join(folder, "clips.h5")
    write_clip_file(path, clips=(train_clips, 206, 64), clip_length=16, seed=1,
                    rotations=False)
    return path


def run(data: str, cadence: str, epochs: int, out: Path) -> dict:
    import bsp_fast
    from bsp_fast.training import lifecycle

    saves = []
    real = lifecycle.write_bytes

    def counting(path, payload, **kw):
        saves.append(Path(path).name)
        return real(path, payload, **kw)

    lifecycle.write_bytes = counting
    try:
        res = bsp_fast.train("classification", "pedestrian_graph", data=data, out=out,
                             epochs=epochs, batch_size=64, precision="32", threads=1,
                             noise=5.0, mjp=0.7187, seed=22742, checkpoint_every=cadence,
                             force=True, quiet=True, **({"benchmark": True, "balance": True}
                                                       if not data.endswith(".h5") else {}))
    finally:
        lifecycle.write_bytes = real
    return {"cadence": cadence, "fit_cpu_s": res.seconds["fit_cpu"],
            "fit_s": res.seconds["fit"], "last_ckpt_saves": saves.count("last.ckpt"),
            "best_ckpt_saves": saves.count("best.ckpt"), "test": res.metrics}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--epochs", type=int, default=60)
    p.add_argument("--data", help="a dataset directory or clip file (default: generated)")
    p.add_argument("--train-clips", type=int, default=832, help="of the generated file")
    p.add_argument("--json", help="append one JSON line per cadence to this file")
    args = p.parse_args(argv)
    from bsp_fast.training.precision import cpu_summary

    load = os.getloadavg()[0]
    print(f"CPU: {cpu_summary()}; load average {load:.2f}; one thread; {args.epochs} epochs "
          f"per run, {args.rounds} rounds", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_ckpt_") as tmp:
        data = os.path.abspath(args.data) if args.data else clip_file(tmp, args.train_clips)
        got = {c: [] for c in CADENCES}
        for r in range(args.rounds):
            for c in CADENCES:  # alternating: a change of load falls on both
                got[c].append(run(data, c, args.epochs, Path(tmp) / f"run-{c}-{r}"))
                print(f"round {r + 1} --checkpoint-every {c}: fit CPU "
                      f"{got[c][-1]['fit_cpu_s']:.2f} s", flush=True)
    same = all(x["test"] == got[CADENCES[0]][0]["test"] for c in CADENCES for x in got[c])
    base = statistics.median([x["fit_cpu_s"] for x in got["0"]])
    print("| --checkpoint-every | fit CPU s (median) | last.ckpt saves per run | "
          "vs every epoch |\n|---|---|---|---|")
    rows = []
    for c in CADENCES:
        med = statistics.median([x["fit_cpu_s"] for x in got[c]])
        row = {"cadence": c, "fit_cpu_s": med, "runs": [x["fit_cpu_s"] for x in got[c]],
               "last_ckpt_saves": got[c][0]["last_ckpt_saves"], "vs_every_epoch": base / med,
               "same_test_metrics": same, "epochs": args.epochs, "load": load,
               "load_end": os.getloadavg()[0], "cpu": cpu_summary(),
               "data": args.data or "generated"}
        rows.append(row)
        print(f"| {c} | {med:.2f} | {row['last_ckpt_saves']} | x{row['vs_every_epoch']:.3f} |")
    print(f"test metrics identical across cadences: {same}; load average at the end "
          f"{os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "a", encoding="utf-8") as f:
            for row in rows:
                f.write(json.dumps(row) + "\n")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
