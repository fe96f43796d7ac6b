"""Runs side by side in the layout of the report's tables, with the initial-metrics row
(``bsp-eval --table`` and the table bsp-train prints when a run finishes).

The runs are handed over read (``bsp_fast.training.runs.read_finished``) and the columns
are each task's (``bsp_fast.training.tasks.TABLE_COLUMNS``): the noise sigma and MJP of
the run where inputs can be deformed (classification, autoencoder), then its metrics
(lifting: MPJPE, N-MPJPE, PA-MPJPE, MPJVE in mm; autoencoder: MJR, PCK@0.05, PCKhn@0.1
in %; classification: F1, precision, recall, accuracy; pose_estimation: PCK@0.05,
PCKhn@0.1 in %, crop pixels).

Every table starts with the "initial metrics" of each distinct data setting: the trivial
baseline (majority class, identity, mean training pose, mean crop skeleton) on the same
split.
"""
from __future__ import annotations

import csv
import io
import math

from .._plain_progress import FALLBACK_NOTE, readable
from .values import format_metric

__all__ = ["table_rows", "format_table", "runs_table", "scored_text", "initial_text",
           "SETTING_KEYS"]

#: the config values that make two runs' data settings differ (one initial row each)
SETTING_KEYS = ("data", "clip_length", "clip_offset", "benchmark", "balance", "noise", "mjp",
                "lifting_target", "crop_size", "limit_batches", "batch_size")


def _fmt(value, fmt: str, raw: bool) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "" if raw else "–"
    if raw:
        return str(value) if not isinstance(value, list) else " ".join(map(str, value))
    if fmt == "mjp":  # a setting, not a metric
        if isinstance(value, list):
            return f"per joint (mean {sum(value) / len(value):.4g})"
        return f"{value:g}"
    return format_metric(fmt, value)


def table_rows(runs, columns: dict, split: str = "test", raw: bool = False) -> dict:
    """``{task: (header, rows)}`` of ``runs`` (``[(run directory, config, metrics)]``) in
    ``columns`` (``{task: ((header, where, key, format), ...)}``); rows are lists of
    strings (``raw``: unformatted values, for CSV)."""
    out = {}
    for task, cols in columns.items():
        mine = [r for r in runs if r[1].get("task") == task]
        if not mine:
            continue
        header = ["model"] + [c[0] for c in cols] + ["epochs", "run"]
        rows, seen = [], set()
        for path, cfg, metrics in mine:  # initial rows first, one per data setting
            key = tuple(str(cfg.get(k)) for k in SETTING_KEYS)
            initial = (metrics.get("initial") or {}).get(split)
            if key in seen or not initial:
                continue
            seen.add(key)
            name = "initial: " + str(metrics.get("initial", {}).get("baseline", "trivial"))
            rows.append(_row(name, cols, cfg, initial, "", path.name, raw))
        for path, cfg, metrics in mine:
            epochs = f"{metrics.get('best_epoch', '?')}/{metrics.get('epochs', '?')}"
            rows.append(_row(cfg.get("model", "?"), cols, cfg, metrics[split], epochs,
                             path.name, raw))
        out[task] = (header, rows)
    return out


def _row(name, cols, cfg, values, epochs, run, raw) -> list:
    cells = [name]
    for _, where, key, fmt in cols:
        value = cfg.get(key) if where == "c" else values.get(key)
        cells.append(_fmt(value, fmt, raw))
    return cells + [epochs, run]


def format_table(header, rows, fmt: str = "markdown") -> str:
    """One table as aligned markdown or as CSV."""
    if fmt == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)
        return buf.getvalue().rstrip("\n")
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
    line = lambda cells: "| " + " | ".join(str(c).ljust(w) for c, w in zip(cells, widths)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([line(header), sep] + [line(r) for r in rows])


def runs_table(runs, columns: dict, fmt: str = "markdown", split: str = "test") -> str:
    """The tables of ``runs`` (see :func:`table_rows`; one per task, each preceded by
    ``### task`` in markdown; one CSV over the union of the columns)."""
    if fmt not in ("markdown", "csv"):
        raise ValueError(f"format must be one of ['markdown', 'csv'], got {fmt!r}")
    tables = table_rows(runs, columns, split, raw=fmt == "csv")
    parts = []
    for task, (header, rows) in tables.items():
        if fmt == "csv":
            parts.append(format_table(["task"] + header, [[task] + r for r in rows], "csv"))
        else:
            parts.append(f"### {task} ({split})\n\n" + format_table(header, rows))
    if fmt == "csv" and len(parts) > 1:  # one CSV: the union of the columns
        return _merge_csv(parts)
    return "\n\n".join(parts)


def _merge_csv(parts) -> str:
    tables = [list(csv.reader(io.StringIO(p))) for p in parts]
    header: list = []
    for t in tables:
        header += [h for h in t[0] if h not in header]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for t in tables:
        idx = {h: i for i, h in enumerate(t[0])}
        for r in t[1:]:
            w.writerow([r[idx[h]] if h in idx else "" for h in header])
    return buf.getvalue().rstrip("\n")


def scored_text(res, limit_batches=None) -> str:
    """What ``bsp-eval RUN`` prints of one scoring (``res``: its ``EvalResult``, read for
    ``task``, ``model``, ``split``, ``checkpoint``, ``clips``, ``recordings`` and
    ``metrics``): the clips scored and every metric, the normaliser fallback explained
    where it is shown."""
    lines = [f"{res.task} / {res.model}: {res.split} metrics of {res.checkpoint}",
             f"  scored {res.clips} clips of {res.recordings} recordings"
             + (f" (--limit-batches {limit_batches})" if limit_batches else "")]
    shown = readable(res.metrics)
    lines += [f"  {key:14s} {value:.6g}" for key, value in shown.items()]
    if "normaliser_fallback" in shown:
        lines.append(f"  ({FALLBACK_NOTE})")
    return "\n".join(lines)


def initial_text(initial: dict) -> str:
    """What bsp-train prints of the initial metrics before training (``initial``: the
    trivial baseline's ``{"baseline": name, split: {metric: value}}``): one line per split,
    its metrics as ``name value``."""
    lines = [f"initial metrics ({initial['baseline']}, before training):"]
    for split in ("val", "test"):
        row = ", ".join(f"{k} {v:.4g}" for k, v in readable(initial.get(split, {})).items()
                        if v is not None)
        lines.append(f"  {split}: {row}")
    return "\n".join(lines)
