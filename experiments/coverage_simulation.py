#!/usr/bin/env python3
"""How often nominal 95 % intervals cover a known difference between two rows (#37), for
the two-level bootstrap over seeds and recordings (``bsp_fast.metrics.hierarchical``,
methods ``percentile``, ``corrected``, ``t``) and, beside it, the recordings-only interval
that holds the seeds fixed (what the tables printed so far).

Synthetic tables with known answers (``simulate_coverage``): per recording a difficulty
N(0, recording_sd) shared by both rows, per (row, seed) an offset N(0, seed_sd), per (seed,
recording) 20-60 clips with per-clip noise N(0, 0.05); the true difference ``delta``.
Sizes: the tables' (3 and 5 seeds, 20 test recordings) and 10 seeds.

    python experiments/coverage_simulation.py --out runs/coverage [--sims 1000]

Writes ``coverage.json`` and ``coverage.md`` into ``--out`` as rows finish; ``--resume``
keeps the rows written.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

GRID_SD = ((0.03, 0.01), (0.01, 0.03), (0.0, 0.03))  # (seed_sd, recording_sd)


def markdown(rows: list) -> str:
    out = ["| method | seeds | recordings | seed sd | recording sd | delta | sims | coverage, "
           "seeds and recordings | coverage, recordings only | mean width (two-level; "
           "recordings only) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['method']} | {r['seeds']} | {r['recordings']} | {r['seed_sd']:g} | "
                   f"{r['recording_sd']:g} | {r['delta']:g} | {r['sims']} | "
                   f"{100 * r['coverage_seeds_and_recordings']:.1f} % | "
                   f"{100 * r['coverage_recordings_only']:.1f} % | "
                   f"{r['width_seeds_and_recordings']:.4f}; {r['width_recordings_only']:.4f} |")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--sims", type=int, default=1000)
    p.add_argument("--resamples", type=int, default=1000)
    p.add_argument("--seeds", type=int, nargs="+", default=[3, 5, 10])
    p.add_argument("--recordings", type=int, nargs="+", default=[20])
    p.add_argument("--deltas", type=float, nargs="+", default=[0.0, 0.02])
    p.add_argument("--methods", nargs="+", default=["percentile", "corrected", "t"])
    p.add_argument("--resume", action="store_true")
    args = p.parse_args(argv)
    from bsp_fast.atomic import write_text
    from bsp_fast.metrics.hierarchical import simulate_coverage

    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "coverage.json"
    rows = json.loads(path.read_text())["rows"] if args.resume and path.exists() else []
    done = {(r["method"], r["seeds"], r["recordings"], r["seed_sd"], r["recording_sd"],
             r["delta"]) for r in rows}
    t0 = time.perf_counter()
    for method in args.methods:
        for S in args.seeds:
            for R in args.recordings:
                for seed_sd, rec_sd in GRID_SD:
                    for delta in args.deltas:
                        key = (method, S, R, seed_sd, rec_sd, delta)
                        if key in done:
                            continue
                        rows.append(simulate_coverage(
                            seeds=S, recordings=R, seed_sd=seed_sd, recording_sd=rec_sd,
                            delta=delta, sims=args.sims, n_resamples=args.resamples,
                            method=method))
                        doc = {"command": " ".join(sys.argv), "rows": rows,
                               "seconds": round(time.perf_counter() - t0, 1)}
                        write_text(path, json.dumps(doc, indent=1) + "\n")
                        write_text(args.out / "coverage.md", markdown(rows) + "\n")
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
