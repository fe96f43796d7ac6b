"""Text forms of a ``bsp-eval --breakdown`` document
(:func:`bsp_fast.training.eval_breakdown.build_breakdown`): markdown tables, a long CSV
(one line per table, row and value) and JSON (NaN written as null)."""
from __future__ import annotations

import csv
import io
import json
import math

from .tasks import format_metric, metric_spec

__all__ = ["format_breakdown", "to_json", "plain", "FORMATS"]

FORMATS = ("md", "markdown", "csv", "json")


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


def _cell(key: str, value) -> str:
    """A breakdown cell: counts as integers, metrics in the task registry's format."""
    if value is not None and key in ("count", "joints", "crossing"):
        return str(int(value))
    spec = metric_spec(key)
    return format_metric(spec.fmt if spec is not None else ".3f", value, missing="—")


def _markdown(title: str, by: str, unit: str, columns: dict, rows: list) -> list:
    keys = list(columns)
    head = [by, unit] + [columns[k] for k in keys]
    lines = [f"### {title} (count: {unit})", "", "| " + " | ".join(head) + " |",
             "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        cells = [str(r["bin"]), _cell("count", r["count"])]
        cells += [_cell(k, r.get(k)) for k in keys]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _summary_row(doc: dict) -> dict:
    s = dict(doc["summary"])
    return {"bin": doc["split"], **s}


def format_breakdown(doc: dict, fmt: str = "md", heading: str | None = None) -> str:
    """The breakdown as ``md`` (alias ``markdown``), ``csv`` or ``json`` text."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {list(FORMATS)}, got {fmt!r}")
    if fmt == "json":
        return to_json(doc)
    summary = {"title": "summary", "by": "split", "count": doc["summary_count"],
               "columns": doc["summary_columns"], "rows": [_summary_row(doc)]}
    tables = [summary] + list(doc["tables"])
    if fmt == "csv":
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
    lines = [heading] if heading else []
    totals = ", ".join(f"{v} {k}" for k, v in doc["totals"].items())
    lines.append(f"{doc['task']}, {doc['split']} split: {totals}")
    cost = doc.get("cost") or {}
    if cost:
        lines.append(f"model: {cost['parameters']:,} parameters, "
                     f"{cost['flops_per_clip']:,.0f} forward FLOPs per clip")
    for name, b in doc["bins"].items():
        lines.append(f"bins of {name}, per {b['per']}: " + ", ".join(b["rows"]))
    lines += [f"note: {n}" for n in doc["notes"]] + [""]
    for t in tables:
        lines += _markdown(t["title"], t["by"], t["count"], t["columns"], t["rows"])
    return "\n".join(lines).rstrip("\n")
