#!/usr/bin/env python3
"""Does ``--precision auto``'s choice change a table's numbers? One row of a table, trained
again with the same seeds in float32, against the table's own runs (#36: "compiled/bf16
choices never change a table's numbers beyond the stated tolerance, checked by re-training
one row of each table both ways").

The float32 runs come from the table's own command with the precision set and the row
chosen, into another folder::

    bsp-reproduce lifting --data data/medium-poses --seeds 5 --rows lstm \\
        --set precision=32 --out runs-fp32
    python experiments/precision_retrain.py --auto runs/lifting-quick \\
        --fp32 runs-fp32/lifting-quick --row lstm --metric mpjpe_mm --margin 2% --out DIR

Each call adds (or replaces) one row of ``DIR/precision_retrain.json`` and re-renders
``DIR/precision_retrain.md``. The difference float32 - auto and its 95 % interval come from
the tables' two-level bootstrap (t method; test recordings drawn jointly, the same seed
numbers drawn together: a seed fixes the initial weights and the data order under both
precisions; ``bsp_fast.reproduction.evidence.rerun_difference``). The verdict is the
tables' equivalence test against ``--margin`` (absolute, or ``N%`` of the auto row's
value): *agrees* when the whole interval lies within +-margin, *differs* when wholly
outside, *undetermined* otherwise; a margin is to be stated before the float32 runs.

``--auto`` may also be the table's published file (``docs/results/TABLE-BUDGET.json`` and
its per-recording sums), for a table whose runs were made on another machine; a re-run of
fewer seeds is compared with the table's first seeds (the same seed numbers), the table's
mean and std recomputed over them.

``--change`` names another change than float32 for a re-run that keeps the table's
precision (e.g. ``--change "NCHW layout (ebfbec9)"``: the same row and seeds re-trained
after a code change that should alter rounding only); its re-run must have trained in
the table runs' precision.

The margins, stated before the first float32 run (2026-11-26): MPJPE 2 % and PCK 0.5
percentage points (the bf16 tolerances on the same weights, docs/training.md), F1 0.02.
Rows: classification lstm-perfect (f1, 0.02), lifting lstm (mpjpe_mm, 2%), autoencoder
clean (pck_0.05, 0.005), pose_estimation pose_cnn (pck_0.05, 0.005), 5 seeds each.

Stated 2026-11-27, while the runs trained and before any of their test numbers was
seen: the lifting table's four rows, re-trained in float32 on an AVX2-only CPU (the 3-seed
timing run of docs/performance.md, where ``auto`` picks float32), against the published
bf16 table's first 3 seeds (``--auto docs/results/lifting-quick.json``), each with
``--change "float32 (AVX2-only CPU)"`` and the margin MPJPE 2 %. Precision and CPU change
together there, so a difference is the pair's, not float32's alone.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

FILE = "precision_retrain"


def _results(folder: Path) -> dict:
    if folder.suffix == ".json":  # a published table (its run folder on another machine)
        from bsp_fast.reproduction.readme import load_published

        try:
            return load_published(folder)
        except ValueError as e:
            sys.exit(f"precision_retrain: {e}")
    path = folder / "results.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        sys.exit(f"precision_retrain: {path} does not exist (run bsp-reproduce first)")
    except ValueError as e:
        sys.exit(f"precision_retrain: {path}: not JSON ({e})")


def _precisions(r: dict) -> list:
    return sorted({str(s.get("precision")) for s in r["seeds"].values()})


def _margin(text: str, value: float) -> float:
    try:
        return abs(value) * float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        sys.exit(f"precision_retrain: --margin must be a number or N%, got {text!r}")


def compare(auto_dir: Path, fp32_dir: Path, row: str, metric: str, margin: str,
            change: str = "float32") -> dict:
    from bsp_fast.metrics.uncertainty import equivalence
    from bsp_fast.reproduction.evidence import rerun_difference
    from bsp_fast.reproduction.readme import portable

    a, b = _results(auto_dir), _results(fp32_dir)
    for res, folder in ((a, auto_dir), (b, fp32_dir)):
        if row not in res["results"]:
            sys.exit(f"precision_retrain: {folder / 'results.json'} has no row {row!r}")
    ra, rb = a["results"][row], b["results"][row]
    if list(rb["seeds"]) != list(ra["seeds"]):
        ra = _first_seeds(ra, list(rb["seeds"]), metric, auto_dir)
    fp32 = change.startswith("float32")  # e.g. "float32 (AVX2-only CPU)": another machine
    if fp32 and _precisions(rb) != ["32"]:
        sys.exit(f"precision_retrain: {fp32_dir}: row {row!r} ran in {_precisions(rb)}, "
                 "not float32 (--set precision=32)")
    if not fp32 and _precisions(rb) != _precisions(ra):
        sys.exit(f"precision_retrain: {fp32_dir}: row {row!r} ran in {_precisions(rb)}, the "
                 f"table's runs in {_precisions(ra)}: a re-run for {change!r} must keep the "
                 "precision")
    test = rerun_difference({"results": {row: ra}}, row, b, row, metric)
    m = _margin(margin, ra["metrics"][metric])
    return {"table": a.get("table"), "budget": a.get("budget"), "row": row,
            "metric": metric, "seeds": [int(s) for s in ra["seeds"]],
            "recordings": test.n, "auto_precision": _precisions(ra),
            "auto": ra["metrics"][metric], "fp32": rb["metrics"][metric],
            "auto_std": ra.get("std", {}).get(metric), "fp32_std": rb.get("std", {}).get(metric),
            "difference": test.value, "interval": [test.low, test.high], "p": test.p,
            "margin": m, "margin_given": margin,
            "verdict": equivalence(test, 0.0, m), "change": change,
            "fit_cpu_min": {k: _cpu(r) for k, r in (("auto", ra), ("fp32", rb))},
            "auto_runs": portable(auto_dir), "fp32_runs": portable(fp32_dir)}


def _first_seeds(r: dict, seeds: list, metric: str, folder: Path) -> dict:
    """The table's row cut to the re-run's seeds, a leading part of the table's (a re-run
    of 3 seeds against a 5-seed table); its mean and std recomputed over those seeds."""
    import numpy as np

    if list(r["seeds"])[:len(seeds)] != seeds:
        sys.exit(f"precision_retrain: the re-run's seeds {seeds} are not the first seeds of "
                 f"{folder}'s row ({list(r['seeds'])})")
    kept = {k: r["seeds"][k] for k in seeds}
    vals = [s["metrics"][metric] for s in kept.values()]
    return dict(r, seeds=kept, metrics={metric: float(np.mean(vals))},
                std={metric: float(np.std(vals, ddof=1)) if len(vals) > 1 else None})


def _cpu(r: dict) -> float | None:
    total = [s.get("seconds", {}).get("fit_cpu") for s in r["seeds"].values()]
    return None if None in total else round(sum(total) / 60, 2)


def render(rows: list) -> str:
    def f(x, d=4):
        return ("–" if x is None else "0" if x == 0 else f"{x:.{d}g}" if abs(x) >= 1e-3
                else f"{x:.2e}")

    lines = ["| table / row | metric | seeds | table's runs (precision) | re-run with | re-run "
             "| re-run − table's [95 % interval] | margin | verdict | fit CPU min table's / "
             "re-run |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = r["interval"]
        cpu = r["fit_cpu_min"]
        lines.append(
            f"| {r['table']} / {r['row']} | {r['metric']} | {len(r['seeds'])} | "
            f"{f(r['auto'])} ± {f(r['auto_std'], 2)} ({', '.join(r['auto_precision'])}) | "
            f"{r.get('change', 'float32')} | "
            f"{f(r['fp32'])} ± {f(r['fp32_std'], 2)} | {r['difference']:+.4g} "
            f"[{lo:+.4g}, {hi:+.4g}] | ±{f(r['margin'], 3)} ({r['margin_given']}) | "
            f"{r['verdict']} | {f(cpu['auto'], 3)} / {f(cpu['fp32'], 3)} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--auto", type=Path, required=True, help="the table's run folder "
                   "(RUNS/TABLE-BUDGET, --precision auto), or its published file "
                   "(docs/results/TABLE-BUDGET.json) where the runs were made on another "
                   "machine")
    p.add_argument("--fp32", type=Path, required=True, help="the same row's float32 runs "
                   "(RUNS32/TABLE-BUDGET)")
    p.add_argument("--row", required=True)
    p.add_argument("--metric", required=True)
    p.add_argument("--margin", required=True, help="equivalence margin: absolute, or N%% of "
                   "the auto row's value")
    p.add_argument("--out", type=Path, required=True, help="folder of precision_retrain.json/.md")
    p.add_argument("--change", default="float32", help="what the re-run changed (default "
                   "float32; a label starting with 'float32' needs float32 runs too, e.g. "
                   "'float32 (AVX2-only CPU)'; anything else: the table's precision, other "
                   "code)")
    a = p.parse_args(argv)
    from bsp_fast.atomic import write_text
    from bsp_fast.reproduction.readme import portable_command
    from bsp_fast.training.precision import cpu_summary

    row = compare(a.auto, a.fp32, a.row, a.metric, a.margin, a.change)
    row["command"] = portable_command("experiments/precision_retrain.py",
                                      sys.argv[1:] if argv is None else argv)
    row["cpu"] = cpu_summary()  # where this script ran; the runs' CPU is in their logs
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"{FILE}.json"
    doc = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {"rows": []}
    def ident(r):
        return r["table"], r["row"], r["metric"], r.get("change", "float32")

    rows = [r for r in doc["rows"] if ident(r) != ident(row)] + [row]
    doc = {"rows": rows}
    write_text(path, json.dumps(doc, indent=1) + "\n")
    write_text(a.out / f"{FILE}.md", render(rows))
    print(render([row]), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
