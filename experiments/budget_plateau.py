"""Has each row of a table reached a validation plateau at its budget? (#36: faster
training should buy convergence; the budgets it proposes go to the registered protocol as
a proposal, never applied silently.)

    python3 experiments/budget_plateau.py runs/lifting-quick [--tail 0.25] [--gain 0.01]

For every run (``ROW/seed-S`` or ``ROW``) it reads the validation loss per epoch from the
run's CSV logs and reports the best epoch against the last, and the relative improvement
of the best validation loss over the last ``--tail`` of the run's updates
(``(min before the tail - min overall) / min before the tail``). A row is **on a plateau**
when every seed's improvement over its last quarter is below ``--gain`` (1 %), or the run
stopped early (its early stop fired before the cap). Otherwise it proposes twice the cap
of updates (``max_steps``), the smallest step that a second look can test; where a row
already stopped early, it proposes the budget unchanged. These are proposals for a later
table file version (a recorded deviation), not measurements of what a larger budget buys.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import yaml


def _runs(table_dir: Path) -> dict:
    """``{row: [run_dir, ...]}`` of the finished runs under a table's output folder."""
    out: dict = {}
    for metrics in sorted(table_dir.glob("*/seed-*/metrics.json")) + \
            sorted(table_dir.glob("*/metrics.json")):
        run = metrics.parent
        row = run.parent.name if run.name.startswith("seed-") else run.name
        out.setdefault(row, []).append(run)
    return out


def run_plateau(run_dir: Path, tail: float) -> dict:
    """Best and last epoch, updates, and the best val loss's relative gain in the tail."""
    from bsp_fast.training.logs import read_logs

    logs = read_logs(run_dir)
    val = {e: v for e, v in logs.get("val/loss", {}).items() if math.isfinite(v)}
    steps = logs.get("step", {})
    cfg = yaml.safe_load((run_dir / "config.yaml").read_text(encoding="utf-8"))
    if not val:
        return {"run": str(run_dir), "epochs": 0}
    epochs = sorted(val)
    last_step = steps.get(epochs[-1], 0) + 1
    cut = (1.0 - tail) * last_step
    before = [val[e] for e in epochs if steps.get(e, 0) + 1 <= cut]
    best = min(val.values())
    gain = (min(before) - best) / abs(min(before)) if before else float("nan")
    cap = int(cfg.get("max_steps") or 0)
    # the updates made (logged at each epoch's end; a run capped by max_steps inside an
    # epoch made its last updates after its last validation)
    made = int(max(logs.get("cost/updates", {}).values(), default=last_step))
    stopped_early = bool(cap) and made < cap and epochs[-1] + 1 < int(cfg["epochs"])
    return {"run": str(run_dir), "best_epoch": min(val, key=val.get) + 1,
            "epochs": epochs[-1] + 1, "updates": max(made, last_step), "cap": cap,
            "gain_in_tail": gain, "stopped_early": stopped_early}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("table_dir", type=Path, help="a bsp-reproduce output folder, e.g. "
                   "runs/lifting-quick")
    p.add_argument("--tail", type=float, default=0.25)
    p.add_argument("--gain", type=float, default=0.01)
    p.add_argument("--json", type=Path, help="also write the rows here")
    args = p.parse_args(argv)
    runs = _runs(args.table_dir)
    if not runs:
        print(f"{args.table_dir}: no finished runs (ROW/seed-S/metrics.json)", file=sys.stderr)
        return 1
    print(f"{args.table_dir}: plateau = best val loss gained < {args.gain:.0%} over the last "
          f"{args.tail:.0%} of updates in every seed, or early stop\n")
    print("| row | seeds | best / last epoch per seed | updates (cap) | gain in the last "
          f"{args.tail:.0%} per seed | plateau | proposed cap |\n|---|---|---|---|---|---|---|")
    rows = []
    for row, dirs in runs.items():
        rs = [run_plateau(d, args.tail) for d in dirs]
        plateau = all(r.get("stopped_early") or (r.get("gain_in_tail", 1) < args.gain)
                      for r in rs)
        cap = max(r.get("cap", 0) for r in rs)
        proposal = cap if plateau else 2 * cap
        rows.append({"row": row, "runs": rs, "plateau": plateau, "proposed_max_steps": proposal})
        epochs = ", ".join(f"{r.get('best_epoch')}/{r['epochs']}" for r in rs)
        gains = ", ".join(f"{100 * r.get('gain_in_tail', float('nan')):.1f} %" for r in rs)
        print(f"| {row} | {len(rs)} | {epochs} | "
              f"{max(r.get('updates', 0) for r in rs)} ({cap}) | "
              f"{gains} | "
              f"{'yes' if plateau else 'no'} | {proposal} |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
