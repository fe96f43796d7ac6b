"""The one report writer of ``bsp-reproduce``: marks the findings of a table's results and
writes, into the table's run folder, what :mod:`bsp_fast.reporting` renders of them:
``results.md`` (the table and its findings, also printed), ``results.json`` (every run's
values, the summaries, the findings and the figures' paths), ``curves.png``,
the table's declared figures and ``--breakdown``'s tables. One run per row: each finding
shows the direction it went, unmarked (:mod:`.findings`); ``--seeds N``: the findings are
marked from the two-level intervals and tests, Holm-adjusted, with P(a beats b)
(:mod:`.evidence`)."""
from __future__ import annotations

import json
from pathlib import Path

from ..atomic import write_text
from ..reporting.figures import draw_figures, learning_curves
from ..reporting.reproduced import format_table
from . import evidence
from .findings import evaluate_findings as point_findings
from .protocol import mark_exploratory

__all__ = ["format_report", "findings_of", "write_report", "val_series"]


def findings_of(tab: dict, res: dict) -> list:
    """The findings of ``res`` (from :func:`.runner.run_table`), its rows summarised over
    their seeds: marked from the values of a table of one seed (no interval to mark
    from), else from intervals."""
    evidence.summarise(tab, res)
    if len(res["seeds"]) == 1:
        return mark_exploratory(tab, point_findings(tab, res["results"]))
    return mark_exploratory(tab, evidence.evaluate_findings(tab, res))


def format_report(tab: dict, res: dict) -> str:
    """Markdown of ``res``: the table and its findings
    (:func:`bsp_fast.reporting.reproduced.format_table`)."""
    return format_table(tab, res, findings_of(tab, res))


def val_series(tab: dict, res: dict) -> dict:
    """``{row: [{optimiser updates: val metric} per run]}`` of every trained row, the
    table's main metric (its first) from the runs' CSV logs: what the table's
    ``curves.png`` draws. Lightning logs epoch-end values at the index of the epoch's last
    update, hence + 1; runs read from a published table (.restore) have no logs here."""
    from ..training.logs import read_logs

    metric = next(iter(tab["metrics"]))
    out = {}
    for name, r in res["results"].items():
        if r.get("source") != "test":
            continue
        out[name] = []
        for s in r["seeds"].values():
            if not s["run"]:
                continue
            logs = read_logs(Path(s["run"]))
            steps = logs.get("step", {})
            out[name].append({int(steps[e]) + 1: v
                              for e, v in logs.get(f"val/{metric}", {}).items() if e in steps})
    return out


def write_report(tab: dict, res: dict, *, breakdown: bool = False, force: bool = False,
                 log=print) -> Path:
    """Prints the table and writes ``results.md``, ``results.json``, ``curves.png``, the
    table's figures and, with ``breakdown``, its breakdown tables into
    ``res["dir"]``; returns ``results.md``'s path."""
    found = findings_of(tab, res)
    series = val_series(tab, res)
    text = format_table(tab, res, found)
    log(text)
    base = Path(res["dir"])
    curves = learning_curves(tab, res, series)
    figures = draw_figures(tab, res)  # the table's own figures (``figures:``)
    write_text(base / "results.md", text)
    write_text(base / "results.json", json.dumps(
        {**res, "findings": found, "figures": [str(f) for f in figures]}, indent=1,
        default=str))
    if breakdown:
        from .table_breakdown import table_breakdown

        figures += table_breakdown(tab, res, force)
    log(f"wrote {base / 'results.md'}" + (f" and {curves}" if curves else "")
        + "".join(f", {f}" for f in figures))
    return base / "results.md"
