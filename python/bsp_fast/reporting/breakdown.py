"""Text and figures of the test breakdowns: one run's ``bsp-eval --breakdown`` document
(:func:`bsp_fast.training.eval_breakdown.build_breakdown`, whose column headers and bin
labels are these) as markdown tables, a long CSV (one line per table, row and value) or
JSON (NaN written as null); and a table's
breakdown over seeds (``bsp-reproduce --breakdown``,
:func:`bsp_fast.reproduction.table_breakdown.aggregate`) as ``breakdown.md`` and one bar
figure per breakdown table.

A value column is formatted by its metric's table format, handed over as ``formats``
(``{key: fmt}``, :func:`bsp_fast.training.tasks.metric_formats`); a key without one (a
count, or a value no task declares) is written ``.3f``.
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

from .values import format_metric

__all__ = ["format_breakdown", "run_heading", "table_heading", "to_json", "plain", "FORMATS",
           "COUNTS", "HEADERS", "headers", "edges_labels", "ranges_labels", "format_aggregate",
           "draw_breakdowns"]

FORMATS = ("md", "markdown", "csv", "json")
#: the count columns of a breakdown table: whole numbers, never formatted as a metric
COUNTS = ("count", "joints", "crossing")


def plain(value):
    """JSON-safe copy: NaN/inf become None, NumPy scalars plain numbers."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def to_json(doc: dict) -> str:
    """``doc`` as JSON text (NaN and infinite values as null)."""
    return json.dumps(plain(doc), indent=1)


# ---------------------------------------------------------------------- a document's labels
#: the header of every column a breakdown table may have; the document keeps its columns'
#: headers (and its bins' labels), so that a saved one renders without the task registry
HEADERS = {"joints": "joints", "crossing": "crossing clips", "mpjpe_mm": "MPJPE (mm)",
           "pck_0.05": "PCK@0.05 (%)", "pck_auc": "PCK-AUC (%)", "f1": "F1",
           "precision": "precision", "recall": "recall", "accuracy": "accuracy",
           "auroc": "AUROC", "ap": "AP"}


def headers(*keys) -> dict:
    """``{key: header}`` of a breakdown table's columns, in the order given."""
    return {k: HEADERS[k] for k in keys}


def edges_labels(edges, unit: str) -> list:
    """The labels of the half-open bins between ``edges`` (``50-100 px``; the last one,
    open-ended, ``>= 400 px``)."""
    return [f">= {lo:g} {unit}" if math.isinf(hi) else f"{lo:g}-{hi:g} {unit}"
            for lo, hi in zip(edges, edges[1:])]


def ranges_labels(ranges) -> list:
    """The labels of inclusive ``(lo, hi)`` ranges (``3-5``; ``0`` for one value)."""
    return [str(lo) if lo == hi else f"{lo}-{hi}" for lo, hi in ranges]


def _value(formats: dict, key: str, value, missing: str = "–") -> str:
    return format_metric(formats.get(key, ".3f"), value, missing=missing)


def _cell(formats: dict, key: str, value) -> str:
    """A breakdown cell: counts as integers, metrics in their table format."""
    if value is not None and key in COUNTS:
        return str(int(value))
    return _value(formats, key, value, missing="—")


def _markdown(formats: dict, table: dict) -> list:
    keys = list(table["columns"])
    head = [table["by"], table["count"]] + [table["columns"][k] for k in keys]
    lines = [f"### {table['title']} (count: {table['count']})", "",
             "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in table["rows"]:
        cells = [str(r["bin"]), _cell(formats, "count", r["count"])]
        cells += [_cell(formats, k, r.get(k)) for k in keys]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _long_csv(tables: list) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["table", "row", "count_unit", "count", "metric", "value"])
    for t in tables:
        for r in t["rows"]:
            for k in t["columns"]:
                v = plain(r.get(k))
                w.writerow([t["title"], r["bin"], t["count"], r["count"], k,
                            "" if v is None else repr(v) if isinstance(v, float) else v])
    return buf.getvalue().rstrip("\n")


def _preamble(doc: dict) -> list:
    """The lines over the tables: totals, the model's cost, the bins and the notes."""
    totals = ", ".join(f"{v} {k}" for k, v in doc["totals"].items())
    lines = [f"{doc['task']}, {doc['split']} split: {totals}"]
    cost = doc.get("cost") or {}
    if cost:
        lines.append(f"model: {cost['parameters']:,} parameters, "
                     f"{cost['flops_per_clip']:,.0f} forward FLOPs per clip")
    for name, b in doc["bins"].items():
        lines.append(f"bins of {name}, per {b['per']}: " + ", ".join(b["rows"]))
    return lines + [f"note: {n}" for n in doc["notes"]] + [""]


def table_heading(title: str, budget: str) -> str:
    """The heading of a table's ``breakdown.md``."""
    return f"## {title}: test breakdown, budget {budget}"


def run_heading(doc: dict) -> str:
    """The line over one run's breakdown: its task, model and checkpoint."""
    return f"{doc['task']} / {doc['model']}: test breakdown of {doc['checkpoint']}"


def format_breakdown(doc: dict, formats: dict, fmt: str = "md",
                     heading: str | None = None) -> str:
    """The breakdown as ``md`` (alias ``markdown``), ``csv`` or ``json`` text."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {list(FORMATS)}, got {fmt!r}")
    if fmt == "json":
        return to_json(doc)
    summary = {"title": "summary", "by": "split", "count": doc["summary_count"],
               "columns": doc["summary_columns"],
               "rows": [{"bin": doc["split"], **dict(doc["summary"])}]}
    tables = [summary] + list(doc["tables"])
    if fmt == "csv":
        return _long_csv(tables)
    lines = ([heading] if heading else []) + _preamble(doc)
    for t in tables:
        lines += _markdown(formats, t)
    return "\n".join(lines).rstrip("\n")


# ---------------------------------------------------------------------- over seeds
def _aggregate_cell(formats: dict, metric: str, c) -> str:
    """``mean ± std (n COUNT)`` of one bin of one row; — where no seed has a value."""
    if c is None or not c["seeds"]:
        return "—" if c is None else f"— (n {c['count']:.0f})"
    sd = f" ± {_value(formats, metric, c['std'])}" if c["seeds"] > 1 else ""
    return f"{_value(formats, metric, c['mean'])}{sd} (n {c['count']:.0f})"


def format_aggregate(agg: list, labels: dict, n_seeds: int, heading: str,
                     formats: dict) -> str:
    """Markdown: one table per breakdown table, bins down, rows across; a cell is
    ``mean ± std (n COUNT)`` over the seeds with a value in that bin."""
    lines = [heading, "",
             f"Each cell: mean ± std over {n_seeds} seed(s) of the row, and the bin's "
             "count (mean over seeds) in brackets; — where no seed has a value in the "
             "bin.", ""]
    for t in agg:
        rows = list(t["rows"])
        head = [t["by"]] + [labels.get(r, r) for r in rows]
        lines += [f"### {t['title']}: {t['label']} (count: {t['count']})", "",
                  "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        for b in t["bins"]:
            cells = [str(b)] + [_aggregate_cell(formats, t["metric"], t["rows"][r].get(b))
                                for r in rows]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def _slug(title: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")


def draw_breakdowns(agg: list, labels: dict, out_dir, title: str, budget: str) -> list:
    """One grouped bar figure per breakdown table (bars: rows; error bars: ± std over
    seeds), ``OUT/breakdown-<table>.png``; returns the paths."""
    from .._extras import require

    require("matplotlib", "bsp-reproduce --breakdown's figures").use("Agg", force=True)
    from .curves import save_figure

    return [save_figure(_bar_figure(t, labels, title, budget),
                        Path(out_dir) / f"breakdown-{_slug(t['title'])}.png") for t in agg]


def _bar_figure(t: dict, labels: dict, title: str, budget: str):
    import matplotlib.pyplot as plt
    import numpy as np

    rows, bins = list(t["rows"]), t["bins"]
    scale = 100.0 if t["metric"].startswith("pck") else 1.0
    width = 0.8 / max(len(rows), 1)
    wide = len(bins) > 8
    f, ax = plt.subplots(figsize=(11 if wide else 7, 4.5))
    x = np.arange(len(bins))
    for i, r in enumerate(rows):
        cells = [t["rows"][r].get(b) for b in bins]
        mean = [scale * c["mean"] if c and c["seeds"] else np.nan for c in cells]
        std = [scale * c["std"] if c and c["seeds"] else np.nan for c in cells]
        ax.bar(x + (i - (len(rows) - 1) / 2) * width, mean, width, yerr=std,
               capsize=2, label=labels.get(r, r), error_kw={"lw": 0.8})
    ax.set_xticks(x)
    ax.set_xticklabels(bins, rotation=60 if wide else 0, ha="right" if wide else "center",
                       fontsize=7 if wide else 8)
    ax.set_ylabel(t["label"])
    ax.set_xlabel(t["by"])
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, title="mean ± std over seeds", title_fontsize=7)
    ax.set_title(f"{title}: {t['title']}", fontsize=10)
    f.text(0.99, 0.01, f"budget {budget}", ha="right", va="bottom", fontsize=7, color="grey")
    f.tight_layout()
    return f
