"""The one report writer of ``bsp-reproduce``: the table (our cells beside the report's
values, the trivial baseline, epochs, cost columns), the findings with their marks, and
the files beside them (``results.md``, ``results.json``, ``curves.png``, the table's
figures, ``--breakdown``'s tables). One run per row: cells are the run's values and each
finding shows the direction it went, unmarked (:mod:`.findings`); ``--seeds N``: cells are
mean ± std [interval] and the findings are marked from the two-level intervals and tests,
Holm-adjusted, with P(a beats b) (:mod:`.evidence`)."""
from __future__ import annotations

import json
from pathlib import Path

from ..atomic import write_text
from ..metrics.uncertainty import MIN_RECORDINGS, MIN_SEEDS
from . import evidence
from .cost_columns import COST_HEADER, cost_cells
from .figures import draw_figures, learning_curves
from .findings import evaluate_findings as point_findings, format_value
from .protocol import finding_label, mark_exploratory, protocol_lines
from .table_files import settings_cells, table_header

__all__ = ["format_report", "format_table", "findings_of", "write_report", "results_table",
           "status_text", "marks_note", "precision_note", "machines_note"]


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
        cells += cost_cells([s.get("run") for s in seeds], [s.get("seconds") for s in seeds],
                            r.get("cost")) if trained else ["–"] * len(COST_HEADER)
        rows.append(cells)
    return header, rows


def results_table(tab: dict, res: dict) -> str:
    """The markdown of the table's rows alone, as :func:`format_table` prints it (the
    README's rendering, :mod:`.readme`, reuses it)."""
    return _md(*_rows(tab, res, res.get("seeds") is None))


def marks_note(findings: list, budget: str) -> str:
    """The rule of the marks, printed under the findings of a table with seeds (the
    family's size counted from ``findings``: the comparisons Holm adjusted)."""
    def count(exploratory):
        return sum(p is not None and p == p for f in findings
                   if bool(f.get("exploratory")) == exploratory for p in f.get("p_holm") or [])

    extra = count(True)
    return ("Marks: decided when the Holm-adjusted p of the t test on the seed, recording "
            "and interaction variance components (Satterthwaite df) is below 0.05; "
            f"Holm's family: this table file's {count(False)} confirmatory comparisons at "
            f"budget {budget}" + (f" (the {extra} exploratory ones: a family of their own)"
                                  if extra else "")
            + f"; inconclusive by rule with fewer than {MIN_SEEDS} seeds in a row or "
            f"{MIN_RECORDINGS} test recordings, with a standard error of 0, or with a "
            "row's seeds in two modes (some, not all, predicting one class on >= 95 % of "
            "test clips). "
            "P(a beats b): the share of (seed of a, seed of b) pairs where a's value is "
            "better, on the test recordings.")


def _p(p) -> str:
    return "–" if p is None or p != p else ("< 0.001" if p < 0.001 else f"{p:.3f}")


def status_text(f: dict) -> str:
    """A finding's mark as printed: with the rule that made it inconclusive and, with
    seeds, the Holm-adjusted p of each comparison."""
    why = [f"rule: {f['rule']}"] if f.get("rule") else []
    if f.get("p_holm"):
        why.append("p " + ", ".join(_p(p) for p in f["p_holm"]))
    return f["status"] + (f" ({'; '.join(why)})" if why else "")


def _improvement(f: dict) -> str:
    return "; ".join("–" if q is None else f"{q['value']:.2f}"
                     for q in f.get("p_improvement") or [None])


#: printed over every smoke table: its runs only prove the plumbing
SMOKE_BANNER = ("> **smoke budget: plumbing only.** One epoch of two batches per run: the "
                "numbers and the marks below say nothing about the models or the report.")


def precision_note(res: dict):
    """The line naming the rows whose seeds trained in different precisions, or None.
    ``--precision auto`` decides per machine (a run keeps its answer when resumed, and a
    row's seeds started together share one), so seeds added later on another machine, or
    after the probe's cache was cleared, can differ from the row's first ones."""
    mixed = []
    for name, r in (res.get("results") or {}).items():
        by: dict = {}
        for seed, v in (r.get("seeds") if isinstance(r.get("seeds"), dict) else {}).items():
            by.setdefault(str(v.get("precision") or "not recorded"), []).append(str(seed))
        if len(by) > 1:
            mixed.append(f"{name} (" + "; ".join(f"{p}: seeds {', '.join(ss)}"
                                                   for p, ss in sorted(by.items())) + ")")
    if not mixed:
        return None
    return ("Precision: these rows' seeds trained in different precisions (what `--precision "
            "auto` picked where and when each ran; bf16 autocast stays within each model's "
            "stated tolerance of float32, and the row's spread over seeds includes the "
            "difference): " + "; ".join(mixed) + ".")


def machines_note(results: dict) -> str:
    """``Machines (...): <CPU (flags), N CPUs[ + GPU]>: K runs (row a, row b); ...``: where
    each run was made (its config.yaml's ``machine``: the machine that finished it), so
    that a table trained on several kinds of CPU, or partly on a GPU, says which rows ran
    where; runs without the record last, as "not recorded"."""
    from ..training.precision import machine_text

    by: dict = {}
    for name, r in results.items():
        if r.get("source") == "initial" or not isinstance(r.get("seeds"), dict):
            continue
        for seed, v in r["seeds"].items():
            by.setdefault(machine_text(v.get("machine")), {}).setdefault(name, []).append(seed)
    parts = []
    for where, rows in sorted(by.items(), key=lambda kv: kv[0] == "not recorded"):
        n = sum(map(len, rows.values()))
        when = " (made before runs recorded it, 2026-11-27)" * (where == "not recorded")
        parts.append(f"{where}{when}: {n} run{'s' * (n != 1)} (" + ", ".join(rows) + ")")
    return "Machines (each run's, from its config.yaml): " + "; ".join(parts) + "."


def format_table(tab: dict, res: dict, findings: list) -> str:
    """Markdown of a table and its ``findings``: one run per row (``res["seeds"]`` None) or
    cells ``mean ± std [95 % interval]`` over seeds, with the findings' differences,
    intervals and marks; a smoke budget's table under :data:`SMOKE_BANNER`."""
    one = res.get("seeds") is None
    header, rows = _rows(tab, res, one)
    machines = ["", machines_note(res.get("results") or {})]
    banner = [SMOKE_BANNER, ""] if res.get("budget") == "smoke" else []
    if one:
        text = [f"### {tab['title']} — budget {res['budget']}", "", *banner,
                _md(header, rows), "",
                _md(["finding (report)", "ours", "report", "in this run", "status"],
                    [[finding_label(f), f["ours"], f["report"], f.get("direction", "–"),
                      status_text(f)] for f in findings]), *machines]
        return "\n".join(text + protocol_lines(tab, res)) + "\n"
    split = "seed varied with the seed" if res.get("split_seeds") else "fixed"
    text = [f"### {tab['title']} — budget {res['budget']}, {len(res['seeds'])} seeds "
            f"(split {split})", "", *banner,
            "Cells: mean ± std over seeds [95 % interval of the mean over seeds and test "
            "recordings: seed, recording and interaction variance components, "
            "Satterthwaite df, inside the metric's range]. "
            f"Rule: {tab.get('budget_rule', '').strip()}", "", _md(header, rows), "",
            _md(["finding (report)", "ours: difference [95 % interval, seeds and recordings] "
                 "(seeds only)", "P(a beats b)", "report", "status (Holm-adjusted p)"],
                [[finding_label(f), f["ours"], _improvement(f), f["report"], status_text(f)]
                 for f in findings]), "", marks_note(findings, res["budget"])]
    if (note := precision_note(res)) is not None:
        text += ["", note]
    text += machines
    return "\n".join(text + protocol_lines(tab, res)) + "\n"


def findings_of(tab: dict, res: dict) -> list:
    """The findings of ``res`` (from :func:`.runner.run_table`): marked from the single
    runs' values, or (``--seeds``) summarised and marked from intervals."""
    if res.get("seeds") is None:
        return mark_exploratory(tab, point_findings(tab, res["results"]))
    evidence.summarise(tab, res)
    return mark_exploratory(tab, evidence.evaluate_findings(tab, res))


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
