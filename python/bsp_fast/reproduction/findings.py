"""The report's findings on one run per row: orderings, effect directions and sizes,
"fails", "beats the trivial baseline" (``bsp-reproduce`` without ``--seeds``). One run says
in which direction a finding went (``direction``: holds or does not hold), not whether it
reproduces: a mark needs the seeds' spread, so every finding of a one-run table is
inconclusive by rule (:mod:`.evidence` marks them with ``--seeds``). The same comparisons
on the report's own numbers fill the report column of both. See docs/reproduce.md."""
from __future__ import annotations

from ..metrics.uncertainty import MIN_SEEDS, UNSURE
from ..reporting.findings import point_text, report_drop_text
from ..training.tasks import get_task
from .table_files import rows_of

__all__ = ["evaluate_findings", "better", "YES", "NO", "NA", "HOLDS",
           "FAILS", "ONE_RUN"]

YES, NO, NA = "reproduced", "not reproduced", "n/a"
HOLDS, FAILS = "holds", "does not hold"
#: why a one-run table marks nothing (the rule of :mod:`bsp_fast.metrics.uncertainty`)
ONE_RUN = f"one run per row (a mark needs at least {MIN_SEEDS} seeds: --seeds {MIN_SEEDS})"


def better(tab, metric) -> int:
    """+1 when higher is better, -1 when lower is, 0 when neither."""
    return {"higher": 1, "lower": -1}.get(tab["metrics"][metric].get("better"), 0)


def _rel(a, b, relation, margin=0.0) -> bool:
    d = a - b
    return {">": d > margin, ">=": d >= -margin, "<": d < -margin, "<=": d <= margin}[relation]


def _holds(tab, f, v: dict, initial: dict) -> bool:
    """Whether one finding holds on ``v[row]`` (``initial[row]``: the value it compares
    with, where it needs one)."""
    sign, k = better(tab, f["metric"]), f["kind"]
    if k == "order":
        rs = f["rows"]
        return all(sign * (v[a] - v[b]) > 0 for a, b in zip(rs, rs[1:]))
    if k == "compare":
        return _rel(v[f["a"]], v[f["b"]], f.get("relation", ">="), f.get("margin", 0.0))
    if k == "drop":
        return sign * (v[f["base"]] - v[f["other"]]) > 0
    if k == "robuster":
        return (sign * (v[f["a"][0]] - v[f["a"][1]])) < (sign * (v[f["b"][0]] - v[f["b"][1]]))
    if k == "at_least":
        return v[f["row"]] >= f["value"]
    if k == "fails":
        return v[f["row"]] <= initial[f["row"]] + f.get("margin", 0.0)
    return all(sign * (v[r] - initial[r]) > 0 for r in f["rows"])  # beats_initial


def _finding(tab, f, values: dict, initial: dict) -> tuple:
    """(ours, report, direction) of one finding; ``values[source][row]`` is the metric of a row
    (source ``ours`` or ``report``); ``initial[row]`` the trivial baseline's (ours only).
    The cells' text is :func:`bsp_fast.reporting.findings.point_text`'s."""
    need, out = rows_of(f), {}
    for src in ("ours", "report"):
        v = values[src]
        # a threshold or a trivial baseline is ours to test; the report column says what
        # the report stated (report_text)
        mine_only = f["kind"] in ("fails", "beats_initial", "at_least") and (
            src == "report" or (f["kind"] != "at_least"
                                and any(initial.get(r) is None for r in need)))
        if mine_only or any(v.get(r) is None for r in need):
            out[src] = ("", None)
            continue
        out[src] = (point_text(tab, f, v, initial, _baseline(tab, f)[0]),
                    _holds(tab, f, v, initial))
    if f["kind"] == "drop" and f.get("report") is not None and out["report"][1] is None:
        out["report"] = (report_drop_text(tab, f), True)
    ours, ok = out["ours"]
    report = out["report"][0] or f.get("report_text", "stated in the report")
    direction = NA if ok is None else (HOLDS if ok else FAILS)
    return ours or "rows not run", report, direction


def _baseline(tab: dict, f: dict) -> tuple:
    """``(label, f(initial metrics) -> value or None)`` a finding compares with: its
    ``baseline:`` (one the table's task offers) or the task's trivial baseline."""
    task = get_task(tab["task"])
    if f.get("baseline") is not None:
        return task.finding_baselines[f["baseline"]]
    return task.baseline, lambda initial: initial.get(f["metric"])


def evaluate_findings(tab: dict, results: dict) -> list:
    """``[{"text", "ours", "report", "direction", "status", "rule"}]`` for the findings of
    ``tab`` on the ``results`` of :func:`reproduce`: ``direction`` holds, does not hold or
    n/a (a row it needs was not run) from the numbers; ``status`` inconclusive by the rule
    :data:`ONE_RUN` (n/a where the direction is)."""
    out = []
    for f in tab["findings"]:
        m = f["metric"]
        values = {"ours": {r: results[r]["metrics"].get(m) for r in results},
                  "report": {r["name"]: (r.get("report") or {}).get(m) for r in tab["rows"]}}
        of = _baseline(tab, f)[1]
        initial = {r: of(results[r]["initial"]) for r in results}
        ours, report, direction = _finding(tab, f, values, initial)
        na = direction == NA
        out.append({"text": f["text"], "ours": ours, "report": report, "direction": direction,
                    "status": NA if na else UNSURE, "rule": None if na else ONE_RUN})
    return out
