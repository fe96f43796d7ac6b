"""A reproduced table as markdown (``bsp-reproduce``'s ``results.md``, and the rows of the
results page): our cells beside the report's values, the trivial baseline, epochs, cost
columns, the findings with their marks, and the notes under them (the rule of the marks,
precisions and machines, the registered protocol and its deviations).

It is handed what ``bsp-reproduce`` collected: the loaded table file ``tab``
(:func:`bsp_fast.reproduction.table_files.load_table`: its metrics with the task
registry's labels and formats, ``deformed_inputs`` and ``trivial`` of its task), the
results ``res`` (:func:`bsp_fast.reproduction.runner.run_table`) and the marked findings
(:mod:`bsp_fast.reproduction.findings`, :mod:`bsp_fast.reproduction.evidence`). One run per
row: cells are the run's values and each finding shows the direction it went, unmarked;
with seeds: cells are mean ± std [interval] and the findings carry marks, Holm-adjusted p
and P(a beats b).
"""
from __future__ import annotations

import json
from pathlib import Path

from ..metrics.uncertainty import MIN_RECORDINGS, MIN_SEEDS
from .values import format_value

__all__ = ["format_table", "results_table", "table_header", "settings_cells", "status_text",
           "marks_note", "precision_note", "machines_note", "machine_text", "finding_label",
           "protocol_lines", "protocols_text", "code_text", "cost_cells", "COST_HEADER",
           "SMOKE_BANNER"]

#: printed over every smoke table: its runs only prove the plumbing
SMOKE_BANNER = ("> **smoke budget: plumbing only.** One epoch of two batches per run: the "
                "numbers and the marks below say nothing about the models or the report.")
#: the cost columns: parameters and forward FLOPs per clip of the row's model, training time
COST_HEADER = ["params", "MFLOPs/clip", "fit min (wall; CPU)"]


def md_table(header, rows) -> str:
    """A markdown table, cells as given."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


# ---------------------------------------------------------------------- the table
def table_header(tab: dict, epochs_label: str) -> tuple:
    """``(header, metrics, reported, settings)`` of a results table: row, model, the
    deformation settings (2D-input tasks), our metrics, the report's, the trivial
    baseline's first metric (named: classification's is the majority class, never
    crossing) and ``epochs_label``."""
    metrics = list(tab["metrics"])
    reported = [m for m in metrics if any(m in (r.get("report") or {}) for r in tab["rows"])]
    settings = tab["deformed_inputs"]
    header = ["row", "model"] + (["σ (px)", "MJP"] if settings else [])
    header += [tab["metrics"][m]["label"] for m in metrics]
    header += [f"report {tab['metrics'][m]['label']}" for m in reported]
    header += [f"trivial {tab['metrics'][metrics[0]]['label']} ({tab['trivial']})",
               epochs_label]
    return header, metrics, reported, settings


def settings_cells(r: dict) -> list:
    """The σ and MJP cells of a row's result (``per joint`` for a per-joint MJP)."""
    mjp = r.get("mjp")
    return [f"{r.get('noise') or 0:g}", "per joint" if isinstance(mjp, list) else f"{mjp or 0:g}"]


def cost_cells(seconds: list, cost: dict | None) -> list:
    """The three cost cells of a row: its model's ``cost`` (``{"parameters",
    "flops_per_clip"}`` of its first run; empty or None: not measured) and the mean
    training time over its runs (``seconds``: their ``metrics.json`` seconds)."""
    params = f"{cost['parameters']:,}" if cost else "–"
    flops = f"{cost['flops_per_clip'] / 1e6:,.1f}" if cost else "–"
    fits = [s["fit"] for s in seconds if s and s.get("fit") is not None]
    cpus = [s["fit_cpu"] for s in seconds if s and s.get("fit_cpu") is not None]
    if not fits:
        return [params, flops, "–"]
    t = f"{sum(fits) / len(fits) / 60:.1f}"
    if len(cpus) == len(fits):
        t += f"; {sum(cpus) / len(cpus) / 60:.1f}"
    # a run resumed before fit seconds were carried over resumes recorded its last
    # process's only: the row's mean is a lower bound
    if any(s and s.get("partial") for s in seconds):
        t = "≥ " + t
    return [params, flops, t]


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
        cells += cost_cells([s.get("seconds") for s in seeds], r.get("cost")) if trained \
            else ["–"] * len(COST_HEADER)
        rows.append(cells)
    return header, rows


def results_table(tab: dict, res: dict) -> str:
    """The markdown of the table's rows alone, as :func:`format_table` prints it (the
    results page, :mod:`.results_page`, shows it too)."""
    return md_table(*_rows(tab, res, len(res["seeds"]) == 1))


# ---------------------------------------------------------------------- findings and notes
def finding_label(f: dict) -> str:
    """A finding's text as printed: exploratory ones labelled (never bold)."""
    return ("exploratory (added after results were seen; not in the confirmatory family): "
            + f["text"]) if f.get("exploratory") else f["text"]


def marks_note(findings: list, budget: str) -> str:
    """The rule of the marks, printed under the findings of a table with seeds (the
    family's size counted from ``findings``: the comparisons Holm adjusted)."""
    def count(exploratory):
        return sum(p is not None and p == p for f in findings
                   if bool(f.get("exploratory")) == exploratory for p in f.get("p_holm") or [])

    extra = count(True)
    return ("Marks: decided when the Holm-adjusted p of the t test on the seed, recording "
            "and interaction variance components (Satterthwaite df, at most a dominant "
            "mean square's) is below 0.05; "
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


def machine_text(rec) -> str:
    """``"AMD EPYC (avx2), 2 CPUs"`` (``+ GPU name``) for a run's machine record
    (:func:`bsp_fast.training.precision.machine_record`); ``"not recorded"`` for None
    (runs made before runs recorded it, 2026-11-27)."""
    if not rec:
        return "not recorded"
    # the record lists which of the speed flags the CPU has (training/precision.py's
    # SPEED_FLAGS); none of them means not even its first two
    flags = " ".join(rec.get("cpu_flags") or []) or "no avx2/avx512f"
    gpu = f" + {rec['gpu']}" if rec.get("gpu") else ""
    return f"{rec.get('cpu')} ({flags}), {rec.get('cpus')} CPUs{gpu}"


def machines_note(results: dict) -> str:
    """``Machines (...): <CPU (flags), N CPUs[ + GPU]>: K runs (row a, row b); ...``: where
    each run was made (its config.yaml's ``machine``: the machine that finished it), so
    that a table trained on several kinds of CPU, or partly on a GPU, says which rows ran
    where; runs without the record last, as "not recorded"."""
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


# ---------------------------------------------------------------------- the protocol
def code_text(code: dict) -> str:
    """The code a run was made with: its commit, or the package version."""
    if "commit" in code:
        return f"commit {code['commit'][:10]}" + (" with uncommitted changes"
                                                  if code.get("dirty") else "")
    return f"bsp_fast {code.get('version', '?')} (not a git checkout)"


def protocols_text(mixed: dict) -> str:
    """The protocols (hashes and options) runs were made under, ``mixed``: ``{name:
    {"hash", "options"}}``."""
    hashes = sorted({(m["hash"] or "none")[:12] for m in mixed.values()})
    return "protocol hash " + ", ".join(hashes) + "".join(
        sorted({f"; options {json.dumps(m['options'], sort_keys=True)}"
                for m in mixed.values() if m["options"]}))


def _protocol_record(p: dict) -> list:
    out = ["", f"Registered protocol: `{Path(p['table_file']).name}` sha256 "
           f"{p['hash'][:12]} ({p['hashed']}), {code_text(p['code'])}, results written "
           f"{p['utc']}."]
    if p.get("options"):
        out.append("Options given over the table file's (`--set`, option flags): "
                   f"`{json.dumps(p['options'], sort_keys=True)}`.")
    if p.get("mixed"):
        none = " ('none': not recorded)" if any(not m.get("hash") for m in
                                                p["mixed"].values()) else ""
        out.append(f"**Mixed protocols (--allow-changed):** {len(p['mixed'])} run(s) "
                   f"were made under {protocols_text(p['mixed'])}{none}: "
                   f"{', '.join(p['mixed'])}.")
    if p.get("restored"):
        froms = sorted({(p.get("runs", {}).get(n) or {}).get("restored_from", "?")
                        for n in p["restored"]})
        out.append(f"**Read from published results (--with-published):** "
                   f"{len(p['restored'])} run(s) trained on another machine, their "
                   f"numbers as published in {', '.join(froms)}; each keeps the protocol "
                   "and code it was trained under (its record in results.json).")
    return out


def protocol_lines(tab: dict, res: dict) -> list:
    """Markdown lines printed under a table: the protocol its results were made under,
    runs mixed in from another protocol (``--allow-changed``), the table's deviations."""
    out = _protocol_record(res["protocol"]) if res.get("protocol") else []
    devs = tab.get("deviations") or []
    if devs:
        out += ["", "Deviations from the registered protocol:"]
        for d in devs:
            seen = ("after test numbers were seen" + (f" (in {d['seen_in']})"
                                                     if d.get("seen_in") else "")
                    if d["seen_test_numbers"] else "before any test number was seen")
            out.append(f"- {d['when']}, commit {d['commit']}, {seen}: {d['what']} "
                       f"Why: {d['why']}")
    return out


# ---------------------------------------------------------------------- results.md
def format_table(tab: dict, res: dict, findings: list) -> str:
    """Markdown of a table and its ``findings``: one run per row (one seed) or
    cells ``mean ± std [95 % interval]`` over seeds, with the findings' differences,
    intervals and marks; a smoke budget's table under :data:`SMOKE_BANNER`."""
    one = len(res["seeds"]) == 1
    header, rows = _rows(tab, res, one)
    machines = ["", machines_note(res.get("results") or {})]
    banner = [SMOKE_BANNER, ""] if res.get("budget") == "smoke" else []
    if one:
        text = [f"### {tab['title']} — budget {res['budget']}", "", *banner,
                md_table(header, rows), "",
                md_table(["finding (report)", "ours", "report", "in this run", "status"],
                         [[finding_label(f), f["ours"], f["report"], f.get("direction", "–"),
                           status_text(f)] for f in findings]), *machines]
        return "\n".join(text + protocol_lines(tab, res)) + "\n"
    split = "seed varied with the seed" if res.get("split_seeds") else "fixed"
    text = [f"### {tab['title']} — budget {res['budget']}, {len(res['seeds'])} seeds "
            f"(split {split})", "", *banner,
            "Cells: mean ± std over seeds [95 % interval of the mean over seeds and test "
            "recordings: seed, recording and interaction variance components, "
            "Satterthwaite df at most a dominant mean square's, inside the metric's range]. "
            f"Rule: {tab.get('budget_rule', '').strip()}", "", md_table(header, rows), "",
            md_table(["finding (report)", "ours: difference [95 % interval, seeds and "
                      "recordings] (seeds only)", "P(a beats b)", "report",
                      "status (Holm-adjusted p)"],
                     [[finding_label(f), f["ours"], _improvement(f), f["report"],
                       status_text(f)] for f in findings]), "",
            marks_note(findings, res["budget"])]
    if (note := precision_note(res)) is not None:
        text += ["", note]
    text += machines
    return "\n".join(text + protocol_lines(tab, res)) + "\n"
