#!/usr/bin/env python3
"""PoseFormer beside the LSTM as training goes on: validation MPJPE against optimiser
updates and against CPU seconds, from the runs of ``bsp-reproduce ablation_poseformer``
(their CSV logs: ``val/mpjpe_mm``, ``cost/updates`` and ``cost/cpu_s`` per epoch, read with
``bsp_fast.training.logs.read_logs``), and where PoseFormer's curve first passes the
LSTM's, if it does.

    bsp-reproduce ablation_poseformer --data data/medium-poses --seeds 3 --jobs 2
    python experiments/poseformer_updates.py runs/ablation_poseformer-quick

"Passes", precisely: each model's curve is the mean over its seeds at the update counts
every seed logged (the same batch size and data give the same counts), placed at that
count or at the seeds' mean CPU seconds there. PoseFormer passes at the first of its points whose mean is below
the LSTM's mean at the same x (the LSTM's curve linearly interpolated; past its last
point, its last value); points before the LSTM's first are not compared. Means only: the
spread over seeds is drawn as a band (± one sample standard deviation) and printed, and a
pass inside it is not a difference.

Writes ``poseformer_updates.png``, ``.json`` and ``.md`` into the table's folder (or
``--out``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROWS = ("poseformer", "lstm")
METRIC = "mpjpe_mm"


def run_series(run_dir, metric: str = METRIC) -> dict:
    """``{"updates", "cpu_s", "value"}`` arrays of one run, one entry per epoch with a
    validation value (epochs without ``cost/`` columns are left out)."""
    from bsp_fast.training.logs import read_logs

    logs = read_logs(run_dir)
    val, upd, cpu = (logs.get(k, {}) for k in (f"val/{metric}", "cost/updates", "cost/cpu_s"))
    epochs = sorted(e for e in val if e in upd and e in cpu)
    return {"updates": np.array([upd[e] for e in epochs], float),
            "cpu_s": np.array([cpu[e] for e in epochs], float),
            "value": np.array([val[e] for e in epochs], float)}


def mean_curve(runs: list, x: str) -> tuple:
    """``(x, mean, std)`` over the seeds' runs (:func:`run_series`); see the module
    docstring for how the seeds are aligned."""
    runs = [r for r in runs if len(r["value"])]
    if not runs:
        return np.array([]), np.array([]), np.array([])
    common = sorted(set.intersection(*(set(r["updates"].tolist()) for r in runs)))
    pick = [np.searchsorted(r["updates"], common) for r in runs]
    vals = np.array([r["value"][i] for r, i in zip(runs, pick)]).reshape(len(runs), -1)
    grid = np.array([r[x][i] for r, i in zip(runs, pick)]).reshape(len(runs), -1).mean(0)
    std = vals.std(0, ddof=1) if len(runs) > 1 else np.zeros(len(common))
    return grid, vals.mean(0), std


def first_pass(xa, ya, xb, yb, better: str = "lower"):
    """The first ``xa`` where curve a is better than curve b at the same x (b linearly
    interpolated, held at its last value past its end; a's points before b's first are
    not compared), or None."""
    xa, ya, xb, yb = (np.asarray(v, float) for v in (xa, ya, xb, yb))
    if not len(xa) or not len(xb):
        return None
    for x, y in zip(xa, ya):
        if x < xb[0]:
            continue
        ref = float(np.interp(x, xb, yb))  # np.interp holds the last value past the end
        if (y < ref) if better == "lower" else (y > ref):
            return float(x)
    return None


def _runs(table_dir: Path, row: str) -> list:
    dirs = sorted(p for p in (table_dir / row).glob("seed-*") if p.is_dir())
    if not dirs and (table_dir / row / "logs").is_dir():
        dirs = [table_dir / row]  # a single-seed table
    return [run_series(d) for d in dirs]


def summarise(table_dir) -> dict:
    table_dir = Path(table_dir)
    out = {"table_dir": str(table_dir), "metric": METRIC, "rows": {}, "passes": {}}
    curves = {}
    for row in ROWS:
        runs = _runs(table_dir, row)
        if not runs:
            raise ValueError(f"{table_dir / row}: no runs (expected seed-*/ or logs/ of "
                             "bsp-reproduce ablation_poseformer)")
        curves[row] = {x: mean_curve(runs, x) for x in ("updates", "cpu_s")}
        xs, mean, std = curves[row]["updates"]
        out["rows"][row] = {"seeds": len(runs), "updates": xs.tolist(), "mean": mean.tolist(),
                            "std": std.tolist(),
                            "cpu_s_total": [float(r["cpu_s"][-1]) for r in runs if len(r["cpu_s"])]}
    for x in ("updates", "cpu_s"):
        a, b = curves["poseformer"][x], curves["lstm"][x]
        out["passes"][x] = first_pass(a[0], a[1], b[0], b[1])
    return out, curves


def _draw(curves: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    from bsp_fast.atomic import atomic_output

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, x, label in zip(axes, ("updates", "cpu_s"),
                            ("optimiser updates", "CPU seconds of the training process")):
        for row in ROWS:
            xs, mean, std = curves[row][x]
            line, = ax.plot(xs, mean, marker=".", label=row)
            ax.fill_between(xs, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        ax.set_xlabel(label)
        ax.set_ylabel("val MPJPE (mm)")
        ax.grid(alpha=0.3)
        ax.legend(title="mean ± std over seeds")
    fig.tight_layout()
    with atomic_output(path, force=True) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)


def _text(res: dict) -> str:
    lines = ["| row | seeds | last updates | last val MPJPE (mm, mean ± std) | CPU s per seed |",
             "|---|---|---|---|---|"]
    for row, r in res["rows"].items():
        lines.append(f"| {row} | {r['seeds']} | {r['updates'][-1]:.0f} | {r['mean'][-1]:.2f} "
                     f"± {r['std'][-1]:.2f} | {', '.join(f'{c:.0f}' for c in r['cpu_s_total'])} |")
    for x, unit in (("updates", "updates"), ("cpu_s", "CPU s")):
        at = res["passes"][x]
        lines.append("")
        lines.append(f"PoseFormer's mean val MPJPE passes the LSTM's at {at:.0f} {unit}"
                     if at is not None else
                     f"PoseFormer's mean val MPJPE does not pass the LSTM's within the runs "
                     f"({unit})")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("table_dir", help="OUT/ablation_poseformer-BUDGET of bsp-reproduce")
    p.add_argument("--out", help="folder of the outputs (default: table_dir)")
    ns = p.parse_args(argv)
    try:
        res, curves = summarise(ns.table_dir)
    except ValueError as exc:
        print(f"poseformer_updates: {exc}", file=sys.stderr)
        return 1
    from bsp_fast.atomic import write_text

    out = Path(ns.out or ns.table_dir)
    out.mkdir(parents=True, exist_ok=True)
    _draw(curves, out / "poseformer_updates.png")
    text = _text(res)
    write_text(out / "poseformer_updates.md", text)
    write_text(out / "poseformer_updates.json", json.dumps(res, indent=1))
    print(text + f"wrote {out / 'poseformer_updates.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
