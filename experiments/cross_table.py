#!/usr/bin/env python3
"""Rows of two tables' runs compared on the same test split: e.g. each classification row
at the original's batch size 1 (``classification_batch1``) against the same row at batch
64 (``classification``), where the two tables differ only in the batch size and its
update count. A row given as ``A:B`` compares row A of the first folder with row B of
the second, which may be the same folder (e.g. an ablation's ``lstm-s0-m0`` against its
``lstm-s0-m0-upd``).

    python3 experiments/cross_table.py --a runs/classification-quick \\
        --b runs/classification_batch1-quick --metric f1 \\
        --rows graph-perfect,graph-mjp0.3,graph-mjp0.7187,graph-mjp0.9328 --out DIR

Per row: ``b - a`` with its 95 % interval over seeds and test recordings (the tables'
two-level bootstrap, t method; recordings drawn jointly; the seeds of the two tables drawn
independently: a seed fixes the initial weights under both, but not the same sequence of
updates at another batch size) and its two-sided p, Holm-adjusted over the rows given (one
family). These comparisons were not registered in either table file: they are
exploratory. Writes ``DIR/cross_table.json`` (rows keyed by tables, row and metric;
replaced when given again) and ``DIR/cross_table.md``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _results(folder: Path) -> dict:
    path = folder / "results.json"
    if not path.is_file():
        sys.exit(f"cross_table: {path} does not exist (run bsp-reproduce first)")
    return json.loads(path.read_text(encoding="utf-8"))


def compare(a_dir: Path, b_dir: Path, rows: list, metric: str) -> list:
    """``rows``: names both tables have, or ``A:B`` (row A of ``a_dir``, row B of
    ``b_dir``)."""
    from bsp_fast.metrics.uncertainty import holm
    from bsp_fast.reproduction.evidence import rerun_difference

    a, b = _results(a_dir), _results(b_dir)
    out = []
    for row in rows:
        ra, _, rb = row.partition(":")
        rb = rb or ra
        for res, folder, name in ((a, a_dir, ra), (b, b_dir, rb)):
            if name not in res["results"]:
                sys.exit(f"cross_table: {folder / 'results.json'} has no row {name!r}")
        t = rerun_difference(a, ra, b, rb, metric, paired_seeds=False)
        out.append({"a": a.get("table"), "b": b.get("table"), "budget": a.get("budget"),
                    "row": ra if ra == rb else f"{ra} → {rb}", "metric": metric,
                    "seeds": [len(a["results"][ra]["seeds"]), len(b["results"][rb]["seeds"])],
                    "value_a": a["results"][ra]["metrics"][metric],
                    "value_b": b["results"][rb]["metrics"][metric],
                    "difference": t.value, "interval": [t.low, t.high], "p": t.p,
                    "recordings": t.n})
    for r, p in zip(out, holm([r["p"] for r in out])):
        r["p_holm"] = p
    return out


def render(rows: list) -> str:
    lines = ["| row | metric | a (table) | b (table) | b − a [95 % interval] | p (Holm over "
             "the rows of one call) |", "|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = r["interval"]
        lines.append(f"| {r['row']} | {r['metric']} | {r['value_a']:.3f} ({r['a']}, "
                     f"{r['seeds'][0]} seeds) | {r['value_b']:.3f} ({r['b']}, {r['seeds'][1]} "
                     f"seeds) | {r['difference']:+.3f} [{lo:+.3f}, {hi:+.3f}] | "
                     f"{r['p']:.3f} ({r['p_holm']:.3f}) |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    from bsp_fast.atomic import write_text
    from bsp_fast.reproduction.readme import portable_command

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--a", type=Path, required=True, help="one table's run folder")
    p.add_argument("--b", type=Path, required=True, help="the other's")
    p.add_argument("--rows", required=True,
                   help="rows both tables have, comma-separated; A:B for row A of --a "
                        "against row B of --b")
    p.add_argument("--metric", required=True)
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    rows = compare(a.a, a.b, [r for r in a.rows.split(",") if r], a.metric)
    command = portable_command("experiments/cross_table.py",
                               sys.argv[1:] if argv is None else argv)
    for r in rows:
        r["command"] = command
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "cross_table.json"
    doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {"rows": []}
    key = lambda r: (r["a"], r["b"], r["row"], r["metric"])  # noqa: E731
    new = {key(r) for r in rows}
    doc["rows"] = [r for r in doc["rows"] if key(r) not in new] + rows
    write_text(path, json.dumps(doc, indent=1))
    write_text(a.out / "cross_table.md", render(doc["rows"]))
    print(render(rows), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
