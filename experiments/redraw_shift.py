#!/usr/bin/env python3
"""How far a noisy row's test score moves when the test-time draws became per clip (#34).

Before #34 the noise / missing-joint / box-noise draws of a batch were keyed by the batch's
positions and length, so a checkpoint's test score depended on the evaluation batch size.
For each given run this scores the same checkpoint on the test split

* under the **old** batch-keyed draws (the pre-#34 key, re-created below and patched in for
  this measurement only), at evaluation batch sizes 1-8, 16, 32 and 64, and
* under the **per-clip** draws of ``bsp_fast.data.clip_random`` at the same batch sizes
  (which must all agree),

and writes, per run and metric, the old scores' range and standard deviation over batch
sizes, the old score at the run's own batch size (what a table printed) and the new score.
The runs were trained under the new draws; only the test-time draws differ between (a) and
(b), so this measures the evaluation's share of the change, not a re-trained table.

    python experiments/redraw_shift.py RUN_DIR [RUN_DIR...] --out runs/redraw

Writes ``redraw_shift.json`` and ``redraw_shift.md`` into ``--out``, a row per run as it
finishes (an interrupted run keeps the rows done; ``--resume`` skips them).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

BATCHES = (1, 2, 3, 4, 5, 6, 7, 8, 16, 32, 64)


def _old_rng(self, rows, epoch):
    """The pre-#34 key: seed, split, epoch, CRC-32 of the batch's positions, its length.
    (Positions are recovered from rows: the datasets here are unbalanced and unindexed,
    where position == row.)"""
    from bsp_fast.data.base import _SPLIT_CODE

    epoch = epoch if self.split == "train" else 0
    pos = np.searchsorted(self._rows, np.asarray(rows))
    key = zlib.crc32(np.asarray(pos, np.int64).tobytes())
    entropy = [self._seed, _SPLIT_CODE[self.split], epoch, key, len(pos)]
    return np.random.Generator(np.random.SFC64(np.random.SeedSequence(entropy)))


def score(run: Path, batches, old: bool) -> list:
    from bsp_fast.data import base
    from bsp_fast.training.evaluate import evaluate

    new_rng = base.SplitDataset._rng
    if old:
        base.SplitDataset._rng = _old_rng
    try:
        return [evaluate(run, "test", batch_size=b, workers=0).metrics for b in batches]
    finally:
        base.SplitDataset._rng = new_rng


def one_run(run: Path, batches, metrics) -> dict:
    import yaml

    cfg = yaml.safe_load((run / "config.yaml").read_text())
    own = int((cfg.get("options") or cfg).get("batch_size", 0) or 0)
    t0 = time.perf_counter()
    old, new = score(run, batches, True), score(run, batches, False)
    names = [m for m in metrics if m in new[0]] or [k for k in new[0] if k != "loss"][:1]
    out = {"run": str(run), "own_batch_size": own, "batches": list(batches),
           "seconds": round(time.perf_counter() - t0, 1), "metrics": {}}
    for m in names:
        o = np.array([r[m] for r in old])
        n = np.array([r[m] for r in new])
        at_own = float(o[list(batches).index(own)]) if own in batches else None
        out["metrics"][m] = {
            "old_min": float(o.min()), "old_max": float(o.max()), "old_sd": float(o.std(ddof=1)),
            "old_at_own_batch": at_own, "new": float(n[0]),
            "new_spread": float(n.max() - n.min()),
            "moved_from_own": None if at_own is None else float(n[0] - at_own)}
    return out


def markdown(rows: list) -> str:
    out = ["| run | metric | old draws over batch sizes (min - max, sd) | old at the run's "
           "batch | per-clip draws (spread over batch sizes) | moved |",
           "|---|---|---|---|---|---|"]
    for r in rows:
        for m, v in r["metrics"].items():
            own = "n/a" if v["old_at_own_batch"] is None else f"{v['old_at_own_batch']:.4f}"
            moved = "n/a" if v["moved_from_own"] is None else f"{v['moved_from_own']:+.4f}"
            out.append(f"| {Path(r['run']).name} (batch {r['own_batch_size']}) | {m} | "
                       f"{v['old_min']:.4f} - {v['old_max']:.4f} (sd {v['old_sd']:.4f}) | {own} "
                       f"| {v['new']:.4f} ({v['new_spread']:.1g}) | {moved} |")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--batches", type=int, nargs="+", default=list(BATCHES))
    p.add_argument("--metrics", nargs="+", default=["f1", "pck_0.05", "pckhn_0.1", "mpjpe_mm"])
    p.add_argument("--resume", action="store_true", help="keep the rows already written")
    args = p.parse_args(argv)
    from bsp_fast.atomic import write_text

    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "redraw_shift.json"
    rows = json.loads(path.read_text())["rows"] if args.resume and path.exists() else []
    done = {r["run"] for r in rows}
    for run in args.runs:
        if str(run) in done:
            continue
        rows.append(one_run(run, args.batches, args.metrics))
        meta = {"command": " ".join(sys.argv), "rows": rows}
        write_text(path, json.dumps(meta, indent=1) + "\n")
        write_text(args.out / "redraw_shift.md", markdown(rows) + "\n")
        print(markdown(rows[-1:]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
