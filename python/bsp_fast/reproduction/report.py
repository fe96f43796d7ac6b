"""The one report writer of ``bsp-reproduce``: the table (our cells beside the report's
values, the trivial baseline, epochs, cost columns), the findings with their marks, and
the files beside them (``results.md``, ``results.json``, ``curves.png``, the table's
figures, ``--breakdown``'s tables). One run per row: cells are the run's values and the
findings are marked from them (:mod:`.findings`); ``--seeds N``: cells are mean ± std
[interval] and the findings are marked from intervals (:mod:`.evidence`)."""
from __future__ import annotations

import json
from pathlib import Path

from ..atomic import write_text
from . import evidence
from .cost_columns import COST_HEADER, cost_cells
from .figures import draw_figures, learning_curves
from .findings import evaluate_findings as point_findings, format_value
from .table_files import settings_cells, table_header

__all__ = ["format_report", "format_table", "findings_of", "write_report"]


def _md(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


def _cell(tab, m, r) -> str:
    """``mean ± std [low, high]`` over seeds; the value alone for one run."""
    text = format_value(tab, m, r["metrics"].get(m))
    std, iv = (r.get("std") or {}).get(m), (r.get("interval") or {}).get(m)
    if std is not None:
        text += f" ± {format_value(tab, m, std)}"
    if iv and format_value(tab, m, iv[0]) != "–" and format_value(tab, m, iv[1]) != "–":
        text += f" [{format_value(tab, m, iv[0])}, {format_value(tab, m, iv[1])}]"
    return text


def _rows(tab: dict, res: dict, one: bool) -> tuple:
    header, metrics, reported, settings = table_header(
        tab, "epochs (best/run)" if one else "epochs (best/run) per seed")
    header += COST_HEADER
    rows = []
    for row in tab["rows"]:
        r = res["results"].get(row["name"])
        if r is None:
            continue
        cells = [row["name"], row.get("label", row["name"])]
        if settings:
            cells += settings_cells(r)
        cells += [_cell(tab, m, r) for m in metrics]
        cells += [format_value(tab, m, (row.get("report") or {}).get(m)) for m in reported]
        cells.append(format_value(tab, metrics[0], r["initial"].get(metrics[0])))
        trained = r.get("source") != "initial"
        seeds = list(r["seeds"].values()) if trained else []
        cells.append(", ".join(f"{s['best_epoch']}/{s['epochs']}" for s in seeds) or "–")
        cells += cost_cells([s.get("run") for s in seeds], [s.get("seconds") for s in seeds]) \
            if trained else ["–"] * len(COST_HEADER)
        rows.append(cells)
    return header, rows


#: printed over every smoke table: its runs only prove the plumbing
SMOKE_BANNER = ("> **smoke budget: plumbing only.** One epoch of two batches per run: the "
                "numbers and the marks below say nothing about the models or the report.")


def format_table(tab: dict, res: dict, findings: list) -> str:
    """Markdown of a table and its ``findings``: one run per row (``res["seeds"]`` None) or
    cells ``mean ± std [95 % interval]`` over seeds, with the findings' differences,
    intervals and marks; a smoke budget's table under :data:`SMOKE_BANNER`."""
    one = res.get("seeds") is None
    header, rows = _rows(tab, res, one)
    banner = [SMOKE_BANNER, ""] if res.get("budget") == "smoke" else []
    if one:
        text = [f"### {tab['title']} — budget {res['budget']}", "", *banner,
                _md(header, rows), "",
                _md(["finding (report)", "ours", "report", "status"],
                    [[f["text"], f["ours"], f["report"], f["status"]] for f in findings])]
        return "\n".join(text) + "\n"
    split = "seed varied with the seed" if res.get("split_seeds") else "fixed"
    text = [f"### {tab['title']} — budget {res['budget']}, {len(res['seeds'])} seeds "
            f"(split {split})", "", *banner,
            "Cells: mean ± std over seeds [95 % interval of the mean, bootstrap over test "
            "recordings resampled jointly for every seed"
            + ("; with split seeds, of the ratio pooled over seeds" if res.get("split_seeds")
               else "") + "]. "
            f"Rule: {tab.get('budget_rule', '').strip()}", "", _md(header, rows), "",
            _md(["finding (report)", "ours: difference [95 % interval]", "report", "status"],
                [[f["text"], f["ours"], f["report"], f["status"]] for f in findings])]
    return "\n".join(text) + "\n"


def findings_of(tab: dict, res: dict) -> list:
    """The findings of ``res`` (from :func:`.runner.run_table`): marked from the single
    runs' values, or (``--seeds``) summarised and marked from intervals."""
    if res.get("seeds") is None:
        return point_findings(tab, res["results"])
    evidence.summarise(tab, res)
    return evidence.evaluate_findings(tab, res)


def format_report(tab: dict, res: dict) -> str:
    """Markdown of ``res``: the table and its findings (:func:`format_table`)."""
    return format_table(tab, res, findings_of(tab, res))


def write_report(tab: dict, res: dict, *, breakdown: bool = False, force: bool = False,
                 log=print) -> Path:
    """Prints the table and writes ``results.md``, ``results.json`` (every run's values,
    the summaries, the findings and the figures' paths), ``curves.png`` (with seeds), the
    table's figures and, with ``breakdown``, its breakdown tables into ``res["dir"]``;
    returns ``results.md``'s path."""
    found = findings_of(tab, res)
    text = format_table(tab, res, found)
    log(text)
    base = Path(res["dir"])
    curves = None if res.get("seeds") is None else learning_curves(tab, res)
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
