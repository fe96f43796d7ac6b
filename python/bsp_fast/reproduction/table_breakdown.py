"""``bsp-reproduce TABLE --breakdown``: the test breakdown of every row of a table
(``bsp-eval RUN --breakdown``'s tables per joint, size or distance bin, profile and
missing-joint count), each bin's main value as mean ± std over the row's seeds, written as
``breakdown.md`` and ``breakdown.json`` beside ``results.md`` with one bar figure per
breakdown table (``breakdown-per-joint.png``, ...; error bars: ± one sample standard
deviation over seeds).

Each run's document is computed once and kept as ``RUN/test_breakdown.json``
(``bsp-eval RUN --breakdown --save``); a later call reuses it unless it is older than the
run's ``metrics.json`` (a run trained again) or ``--force`` is given.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..reporting.breakdown import (COUNTS, draw_breakdowns, format_aggregate, plain,
                                  table_heading)
from ..training.tasks import metric_formats

__all__ = ["run_dirs", "run_breakdowns", "aggregate", "table_breakdown", "MD", "JSON"]

MD, JSON = "breakdown.md", "breakdown.json"


def run_dirs(res: dict) -> list:
    """``[(row, seed or None, run_dir)]`` of bsp-reproduce's results (:func:`.runner.run_table`:
    every row holds its runs under ``seeds``);
    rows that read another row's trivial baseline have no run of their own, nor runs read
    from a published table (.restore: their checkpoints are on another machine)."""
    return [(name, seed, Path(one["run"]))
            for name, r in res["results"].items() if r.get("source") != "initial"
            for seed, one in r["seeds"].items() if one["run"]]


def _fresh(run_dir: Path, file: Path) -> bool:
    metrics = run_dir / "metrics.json"
    return file.is_file() and (not metrics.is_file()
                               or file.stat().st_mtime >= metrics.stat().st_mtime)


def run_breakdowns(res: dict, force: bool = False, log=print) -> dict:
    """``{row: [document per seed]}``: each run's saved breakdown, computed (and saved)
    where missing or stale."""
    from ..training.runs import BREAKDOWN_FILE as FILE
    from ..training.evaluate import breakdown

    docs: dict = {}
    for name, seed, run_dir in run_dirs(res):
        path = run_dir / FILE
        if force or not _fresh(run_dir, path):
            log(f"[{name} seed {seed}] breakdown of {run_dir}")
            breakdown(str(run_dir), save=True)
        docs.setdefault(name, []).append(json.loads(path.read_text()))
    return docs


def _main_key(columns: dict) -> str:
    return next(k for k in columns if k not in COUNTS)


def _stat(values: list) -> tuple:
    v = np.array([np.nan if x is None else float(x) for x in values], float)
    v = v[np.isfinite(v)]
    if not len(v):
        return math.nan, math.nan, 0
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0, len(v)


def _tables_by_title(docs: dict) -> list:
    """The first copy of each table title over every document, in order of appearance
    (a saved document older than a table, e.g. the time-to-event one, lacks it)."""
    seen: dict = {}
    for seed_docs in docs.values():
        for doc in seed_docs:
            for t in doc["tables"]:
                seen.setdefault(t["title"], t)
    return list(seen.values())


def aggregate(docs: dict) -> list:
    """One entry per breakdown table (in the documents' order) and value column it
    aggregates (the first value column, or the table's ``aggregate`` list; entries past
    the first get the label in their title): ``title``, ``by``, ``count`` (its unit),
    ``metric`` and ``label``, ``bins`` and, per row, ``{bin: {"mean", "std", "seeds",
    "count"}}`` (``count``: the mean over seeds; ``seeds``: how many had a value in the
    bin)."""
    out = []
    for t0 in _tables_by_title(docs):
        for i, key in enumerate(t0.get("aggregate") or [_main_key(t0["columns"])]):
            entry = _aggregate_one(docs, t0, key)
            if i:
                entry["title"] = f"{t0['title']} ({entry['label']})"
            out.append(entry)
    return out


def _aggregate_one(docs: dict, t0: dict, key: str) -> dict:
    """:func:`aggregate`'s entry of the table titled like ``t0`` for value column ``key``."""
    bins: list = []
    per_row: dict = {}
    for name, seed_docs in docs.items():
        cells: dict = {}
        for doc in seed_docs:
            table = next((t for t in doc["tables"] if t["title"] == t0["title"]), None)
            if table is None:
                continue
            for r in table["rows"]:
                if r["bin"] not in bins:
                    bins.append(r["bin"])
                c = cells.setdefault(r["bin"], {"values": [], "counts": []})
                c["values"].append(r.get(key))
                c["counts"].append(r["count"])
        per_row[name] = {}
        for b, c in cells.items():
            mean, std, n = _stat(c["values"])
            per_row[name][b] = {"mean": mean, "std": std, "seeds": n,
                                "count": float(np.mean(c["counts"]))}
    return {"title": t0["title"], "by": t0["by"], "count": t0["count"],
            "metric": key, "label": t0["columns"][key], "bins": bins, "rows": per_row}


def table_breakdown(tab: dict, res: dict, force: bool = False, log=print) -> list:
    """Everything ``--breakdown`` adds to a table's folder; returns the paths written."""
    from ..atomic import write_text

    docs = run_breakdowns(res, force, log)
    if not docs:
        return []
    agg = aggregate(docs)
    labels = {r["name"]: r.get("label", r["name"]) for r in tab["rows"] if r["name"] in docs}
    if len(set(labels.values())) < len(labels):  # e.g. an ablation grid: names tell rows apart
        labels = {name: name for name in labels}
    n_seeds = len(res["seeds"])
    base = Path(res["dir"])
    write_text(base / MD, format_aggregate(agg, labels, n_seeds,
                                           table_heading(tab["title"], res["budget"]),
                                           metric_formats()))
    write_text(base / JSON, json.dumps(plain({"table": tab["table"], "budget": res["budget"],
                                              "seeds": res.get("seeds"), "tables": agg}),
                                       indent=1) + "\n")
    return [base / MD, base / JSON] + draw_breakdowns(agg, labels, base, tab["table"],
                                                       res["budget"])
