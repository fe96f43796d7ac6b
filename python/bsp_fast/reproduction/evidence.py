"""A table trained with several seeds, as evidence (docs/reproduce.md, "Seeds, intervals and
marks"): each cell the mean ± std over seeds and a 95 % interval over seeds *and* test
recordings, each of the report's findings marked from the same seed, recording and
interaction variance components (:func:`bsp_fast.metrics.hierarchical.variance_components`,
Satterthwaite's degrees of freedom bounded by a dominant mean square's; a cell's interval
respects its metric's range),
Holm-Bonferroni over the table's family of comparisons, with the probability of
improvement beside each comparison of two rows.

The data: per row, per seed, per test recording the sums behind each metric (``num``,
``den``: ``test_per_recording.json``), or for a per-clip metric (:data:`CLIP_METRICS`) each
recording's clips. Rows scored on one dataset are aligned on the union of their
recordings (a seed that did not test a recording adds nothing there), so the recordings
are drawn once per replicate for all of them (paired); rows of different datasets
(``data_suffix``) share no recordings and are independent. Rows trained with the same seed
numbers (in the same order) are paired on their seeds: a row and its trivial baseline
(or a row read from another row's trivial baseline, ``initial_of``) are the same runs, and
rows of one table that share seed numbers share their data order (pairing is valid whether
or not their seed effects correlate; it costs degrees of freedom when they do not).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..metrics import hierarchical as H
from ..metrics import uncertainty as U
from ..reporting.findings import (difference_label, fails_baseline, fails_label, seeds_text,
                                 threshold_label)
from .findings import better as _sign
from .protocol import confirmatory

__all__ = ["summarise", "evaluate_findings", "statistics", "rerun_difference",
           "DEFAULT_MARGIN", "METHOD", "CLIP_METRICS"]

#: the interval and test of cells and findings: the method whose coverage was measured
#: at the tables' sizes (experiments/coverage_study.py, docs/reproduce.md)
METHOD = "vc"
#: a seed of a classifier "collapsed" when at least this share of its test clips get one
#: predicted class; a row with some but not all seeds collapsed has seeds in two modes and
#: its comparisons are inconclusive by rule (no interval over a few seeds describes them)
COLLAPSED_SHARE = 0.95
#: a finding's ``equivalence_margin`` when it states none: this share of the report's size
DEFAULT_MARGIN = 0.5
#: per-clip metrics (not ratios of per-recording sums) and their functions in
#: ``bsp_fast.metrics.ranking``, ``fn(scores, labels)``; their clips are read from a
#: per-recording section's ``clips`` (one list per recording of ``[score, label, ...]``)
CLIP_METRICS = {"auroc": "auroc", "ap": "average_precision"}


def statistics(res: dict | None = None) -> dict:
    """What the cells' intervals and the marks are (saved in ``results.json``)."""
    return {"interval": "seed, recording and seed x recording variance components of the "
                        "linearised per-seed, per-recording sums, Satterthwaite df (no more "
                        "than that of a mean square carrying half the variance), rows "
                        "paired on the recordings of one dataset and on shared seed "
                        "numbers; a cell's interval respects its metric's range (fractions: "
                        "Clopper-Pearson at the effective sample size, mm: on the log)",
            "confidence": U.CONFIDENCE, "method": METHOD,
            "interval_seeds": "the same over seeds only, the test recordings fixed",
            "rules": f"inconclusive: {H.ZERO_SE}; seeds in two modes (a classifier seed "
                     f"with one predicted class on >= {COLLAPSED_SHARE:.0%} of its test "
                     "clips beside seeds without)",
            "family": "Holm-Bonferroni over every comparison of this table file's "
                      "confirmatory findings at this budget"
                      + (f" ({res['budget']})" if res else "")
                      + "; an ordering of k rows counts k - 1 comparisons, beats_initial "
                        "one per row; findings marked n/a do not count; the exploratory "
                        "findings are a family of their own",
            "min_seeds": U.MIN_SEEDS, "min_recordings": U.MIN_RECORDINGS,
            "equivalence_margin_default": f"{DEFAULT_MARGIN:g} x the report's size"}


class _Sums:
    """The per-seed, per-recording data of a result's rows, each file read once."""

    def __init__(self, res: dict):
        self.res, self.docs = res, {}

    def _doc(self, path):
        if isinstance(path, dict):  # a published table's sums, already read (load_published)
            return path
        if path not in self.docs:
            self.docs[path] = json.loads(Path(path).read_text(encoding="utf-8"))
        return self.docs[path]

    def runs_of(self, row: str) -> str:
        """The row whose runs ``row``'s values come from (itself, or its ``initial_of``)."""
        return self.res["results"][row].get("run_of") or row

    def seed_key(self, row: str) -> tuple:
        """The key rows are paired on their seeds by: the seed numbers, in order."""
        return tuple(self.res["results"][self.runs_of(row)]["seeds"])

    def collapsed(self, row: str, initial: bool) -> list:
        """The seeds of ``row`` (their numbers) that predict one class on at least
        :data:`COLLAPSED_SHARE` of their test clips (score >= 0.5 positive); [] without
        clips."""
        r = self.res["results"][row]
        section = "initial" if (initial or r.get("source") == "initial") else "test"
        out = []
        for name, s in r["seeds"].items():
            part = (self._doc(s["per_recording"]).get(section) or {}) \
                if s.get("per_recording") else {}
            clips = [c for rec in part.get("clips") or [] for c in rec]
            if clips:
                positive = float(np.mean([c[0] >= 0.5 for c in clips]))
                if max(positive, 1 - positive) >= COLLAPSED_SHARE:
                    out.append(name)
        return out

    def seeds(self, row: str, metric: str, initial: bool):
        """``([(recordings, data), ...] one per seed, empty)``: ``data`` ``(num, den)``
        arrays, or for a :data:`CLIP_METRICS` metric one ``(scores, labels)`` per
        recording; ``empty``: the metric's value for no data. None when a seed has no
        per-recording file or its ``test`` (``initial``: trivial baseline's) section lacks
        ``metric``."""
        r = self.res["results"][row]
        section = "initial" if (initial or r.get("source") == "initial") else "test"
        out, empty = [], None
        for i, s in enumerate(r["seeds"].values()):
            if not s.get("per_recording"):
                return None
            d = self._doc(s["per_recording"])
            part = d.get(section)
            if not part:
                return None
            if metric in CLIP_METRICS and part.get("clips") is not None:
                out.append((list(part["recordings"]), _clips(part, s["per_recording"])))
            elif metric in part.get("metrics", {}):
                recs, num, den = U.pool([part], metric)
                out.append((recs, (num, den)))
            else:
                return None
            if i == 0:  # the first seed's file says it
                empty = d.get("empty", {}).get(metric)
        return out, float("nan") if empty is None else empty


def _clips(part: dict, path) -> list:
    """``[(scores, labels)]`` per recording of a section's ``clips``."""
    clips = part["clips"]
    if len(clips) != len(part["recordings"]):
        raise ValueError(f"{path}: {len(clips)} clip lists for {len(part['recordings'])} "
                         "recordings")
    out = []
    for rec, cl in zip(part["recordings"], clips):
        if not cl:
            out.append((np.zeros(0), np.zeros(0)))
            continue
        a = np.asarray(cl, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] < 2:
            raise ValueError(f"{path}: recording {rec!r}: each clip must be [score, label, "
                             f"...], got {cl[0]!r}")
        out.append((a[:, 0], a[:, 1]))
    return out


def _clip_fn(metric: str):
    from ..metrics import ranking

    return getattr(ranking, CLIP_METRICS[metric])


def _row(seeds: list, recs: list, empty: float, metric: str):
    """One row's :class:`~H.Ratios` (or :class:`~H.Clips`) over ``recs`` (zero sums, no
    clips, where a seed did not test a recording)."""
    pos = {r: i for i, r in enumerate(recs)}
    if isinstance(seeds[0][1], list):
        none = (np.zeros(0), np.zeros(0))
        clips = [[none] * len(recs) for _ in seeds]
        for s, (rs, cl) in enumerate(seeds):
            for r, c in zip(rs, cl):
                clips[s][pos[r]] = c
        return H.Clips(clips, _clip_fn(metric), empty)
    num, den = np.zeros((len(seeds), len(recs))), np.zeros((len(seeds), len(recs)))
    for s, (rs, (n, d)) in enumerate(seeds):
        idx = [pos[r] for r in rs]
        num[s, idx], den[s, idx] = n, d
    return H.Ratios(num, den, empty)


def _data_key(tab: dict | None, row: str) -> str:
    """Which test set a row is scored on: rows with a ``data_suffix`` read another
    dataset (docs/reproduce.md, ablation tables)."""
    spec = next((r for r in (tab or {}).get("rows", []) if r["name"] == row), {})
    return spec.get("data_suffix") or ""


def _load(sums: _Sums, tab, parts: list):
    """``{"rows", "groups", "keys", "seeds", "recordings"}`` for :func:`H.two_level` from
    ``parts``, ``(row, metric, initial)`` each; None when a part has no per-recording data."""
    loaded = [sums.seeds(row, metric, initial) for row, metric, initial in parts]
    if any(x is None for x in loaded):
        return None
    groups = [_data_key(tab, row) for row, _, _ in parts]
    union = {g: sorted({r for x, gx in zip(loaded, groups) if gx == g for recs, _ in x[0]
                        for r in recs}) for g in dict.fromkeys(groups)}
    rows = [_row(x[0], union[g], x[1], part[1]) for x, g, part in zip(loaded, groups, parts)]
    return {"rows": rows, "groups": groups, "keys": [sums.seed_key(r) for r, _, _ in parts],
            "seeds": {row: len(x[0]) for (row, _, _), x in zip(parts, loaded)},
            "recordings": min(len(u) for u in union.values())}


def _test(data: dict, fn, levels: str = "both", support=None) -> H.Test:
    return H.two_level(data["rows"], fn, groups=data["groups"], seed_keys=data["keys"],
                       method=METHOD, levels=levels, support=support)


def _values(r: dict, metric: str) -> list:
    key = "initial" if r.get("source") == "initial" else "metrics"
    return [s[key].get(metric) for s in r["seeds"].values() if s[key].get(metric) is not None]


def _bounds(iv) -> list | None:
    return [iv.low, iv.high] if iv is not None and np.isfinite([iv.low, iv.high]).all() \
        else None


def support(metric: str):
    """The values ``metric`` can take, for its cells' intervals: ``(0, 1)`` for fractions,
    ``(0, inf)`` for errors in mm, None (unbounded) otherwise."""
    from ..training.scoring import UNITS

    unit = UNITS.get(metric, "")
    return (0.0, 1.0) if unit == "fraction" else (0.0, math.inf) if unit.startswith("mm") \
        else None


def summarise(tab: dict, res: dict) -> dict:
    """Adds to each row of ``res["results"]`` (from :func:`.runner.run_table` with seeds):
    ``metrics`` and ``initial`` (means over seeds), ``std`` (sample std over seeds, None
    for one seed), ``interval`` (``[low, high]``: the 95 % two-level interval of the mean
    over seeds, seeds and test recordings resampled) and ``interval_seeds`` (over seeds
    only, the recordings fixed) per metric of the table, inside the values the metric can
    take (:func:`support`); absent where undefined (one seed, no per-recording data). Adds ``res["statistics"]`` (:func:`statistics`). Returns ``res``."""
    sums = _Sums(res)
    for name, r in res["results"].items():
        r["metrics"], r["std"], r["initial"] = {}, {}, {}
        r["interval"], r["interval_seeds"] = {}, {}
        for m in tab["metrics"]:
            vals = _values(r, m)
            r["metrics"][m] = float(np.mean(vals)) if vals else None
            r["std"][m] = float(np.std(vals, ddof=1)) if len(vals) > 1 else None
            data = _load(sums, tab, [(name, m, False)])
            for key, levels in (("interval", "both"), ("interval_seeds", "seeds")):
                b = _bounds(_test(data, lambda v: v[0], levels, support(m)) if data else None)
                if b is not None:
                    r[key][m] = b
            init = [s["initial"].get(m) for s in r["seeds"].values()
                    if s["initial"].get(m) is not None]
            r["initial"][m] = float(np.mean(init)) if init else None
        r["baseline"] = next(iter(r["seeds"].values())).get("baseline")
    res["statistics"] = statistics(res)
    return res


# ---------------------------------------------------------------------- findings
def _relation(rel: str, margin: float):
    """(offset, side) of ``a - b`` for a ``compare`` relation: the statistic is
    ``a - b + offset`` and it must lie on ``side`` of zero."""
    return {">": (-margin, 1), ">=": (margin, 1), "<": (margin, -1), "<=": (-margin, -1)}[rel]


def _pieces(tab, f) -> list:
    """``[(label, parts, fn, side, pair)]``: the comparisons of one finding; ``pair``: the
    two parts whose P(first beats second) is reported, or None."""
    m, sign, k = f["metric"], _sign(tab, f["metric"]), f["kind"]
    out = []
    if k == "order":
        for a, b in zip(f["rows"], f["rows"][1:]):
            out.append((difference_label(a, b), [(a, m, False), (b, m, False)],
                        lambda v: v[0] - v[1], sign, (0, 1)))
    elif k == "compare":
        off, side = _relation(f.get("relation", ">="), f.get("margin", 0.0))
        out.append((difference_label(f["a"], f["b"], off),
                    [(f["a"], m, False), (f["b"], m, False)],
                    lambda v: v[0] - v[1] + off, side, (0, 1)))
    elif k == "drop":
        out.append(("loss", [(f["base"], m, False), (f["other"], m, False)],
                    lambda v: sign * (v[0] - v[1]), 1, (0, 1)))
    elif k == "robuster":
        (a0, a1), (b0, b1) = f["a"], f["b"]
        out.append(("extra loss of b", [(a0, m, False), (a1, m, False), (b0, m, False),
                                        (b1, m, False)],
                    lambda v: sign * (v[2] - v[3]) - sign * (v[0] - v[1]), 1, None))
    elif k == "at_least":
        out.append((threshold_label(tab, f),
                    [(f["row"], m, False)], lambda v: v[0] - f["value"], 1, None))
    elif k == "fails":
        base = "f1_constant" if f.get("baseline") == "constant" else m
        margin = f.get("margin", 0.0)
        out.append((fails_label(f["row"], fails_baseline(tab, f), margin),
                    [(f["row"], m, False), (f["row"], base, True)],
                    lambda v: sign * (v[0] - v[1]) - margin, -1, (0, 1)))
    else:  # beats_initial
        for r in f["rows"]:
            out.append((difference_label(r, "trivial"), [(r, m, False), (r, m, True)],
                        lambda v: v[0] - v[1], sign, (0, 1)))
    return out


def _margin(tab: dict, f: dict) -> float:
    """The equivalence margin of a ``drop`` finding's size, checked."""
    where = f"{tab.get('path', tab.get('table'))}: finding {f['text']!r}"
    if "tolerance" in f:
        raise ValueError(f"{where}: 'tolerance' is now 'equivalence_margin' (the interval "
                         "must lie inside report ± margin, not merely overlap it)")
    margin = f.get("equivalence_margin", DEFAULT_MARGIN * abs(f["report"]))
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not margin >= 0:
        raise ValueError(f"{where}: equivalence_margin must be a number >= 0, got {margin!r}")
    return float(margin)


def _compute(tab, f, sums: _Sums, have) -> dict:
    """One finding's comparisons: each its two-level test, seeds-only interval and P(first
    row beats second); or ``{"na": reason}``."""
    pieces = _pieces(tab, f)
    if any(row not in have for _, parts, _, _, _ in pieces for row, _, _ in parts):
        return {"na": "rows not run"}
    out, seeds, recordings = [], {}, []
    for label, parts, fn, side, pair in pieces:
        data = _load(sums, tab, parts)
        if data is None:
            return {"na": "no per-recording sums"}
        seeds.update(data["seeds"])
        recordings.append(data["recordings"])
        poi, sign = None, _sign(tab, f["metric"])
        if pair is not None and sign:
            i, j = pair
            poi = H.probability_of_improvement(
                data["rows"][i], data["rows"][j], sign,
                groups=[data["groups"][i], data["groups"][j]],
                seed_keys=[data["keys"][i], data["keys"][j]])
        # the rules bind each comparison by its own rows: an ordering with one under-seeded
        # row is still not reproduced when a comparison of other rows goes against it
        test = _test(data, fn)
        why = [U.rule(data["seeds"], data["recordings"]), _modes(sums, parts),
               H.ZERO_SE if test.se == 0 else None]
        out.append({"label": label, "side": side, "test": test, "values": [
                        float(np.nanmean(p.values(np.ones((1, p.shape[1])))[0]))
                        for p in data["rows"]],
                    "seeds_only": _test(data, fn, "seeds"), "poi": poi,
                    "rule": "; ".join(w for w in why if w) or None})
    extra = [w for q in out for w in (q["rule"] or "").split("; ")
             if w and not w.startswith("fewer than")]
    rule = "; ".join(dict.fromkeys([w for w in [U.rule(seeds, min(recordings))] if w]
                                   + extra)) or None
    return {"pieces": out, "rule": rule, "seeds": seeds}


def _modes(sums: _Sums, parts: list) -> str | None:
    """The rule for rows whose seeds split into modes (:data:`COLLAPSED_SHARE`): some
    but not all of a row's seeds predict one class, or None."""
    split = {}
    for row, _, initial in parts:
        got = sums.collapsed(row, initial)
        if got and len(got) < len(sums.res["results"][row]["seeds"]):
            split[row] = got
    if not split:
        return None
    return ("seeds in two modes (one predicted class on >= "
            f"{COLLAPSED_SHARE:.0%} of test clips: "
            + ", ".join(f"{r} {'/'.join(s)}" for r, s in split.items()) + ")")


def _finding(tab, f, c: dict) -> dict:
    """The fields of one computed finding (``c["pieces"]`` carry their Holm-adjusted p as
    ``p_holm``) and its ``ours`` cell (:func:`bsp_fast.reporting.findings.seeds_text`)."""
    pieces = c["pieces"]
    marks = [U.UNSURE if q["rule"] else U.decide(q["test"].value, q["p_holm"], q["side"])
             for q in pieces]
    status = U.combine_marks(marks)
    first = pieces[0]["test"]
    # the rule is printed where it decided the mark (a finding left inconclusive)
    out = {"status": status, "rule": c["rule"] if status == U.UNSURE else None,
           "seeds": c["seeds"],
           "difference": first.value, "interval": [first.low, first.high],
           "interval_seeds": [pieces[0]["seeds_only"].low, pieces[0]["seeds_only"].high],
           "recordings": first.n, "p": [q["test"].p for q in pieces],
           "p_holm": [q["p_holm"] for q in pieces], "marks": marks,
           "p_improvement": [None if q["poi"] is None else
                             {"value": q["poi"].value, "interval": [q["poi"].low, q["poi"].high]}
                             for q in pieces]}
    size = baseline = None
    if f["kind"] == "drop" and f.get("report") is not None:
        margin = _margin(tab, f)
        verdict = None if pieces[0]["rule"] else U.equivalence(first, f["report"], margin)
        size = (margin, verdict)
        out["size"] = {"report": f["report"], "equivalence_margin": margin, "verdict": verdict}
    if f["kind"] == "fails":  # the baseline's value, which the table's columns may not show
        baseline = (fails_baseline(tab, f), pieces[0]["values"][1])
    out["ours"] = seeds_text(tab, f, pieces, marks, size=size, baseline=baseline)
    return out


def evaluate_findings(tab: dict, res: dict) -> list:
    """``[{"text", "ours", "report", "status", "rule", "difference", "interval",
    "interval_seeds", "recordings", "seeds", "p", "p_holm", "marks", "p_improvement",
    ("size")}]``:
    each finding marked from the two-level t test on the variance components of seeds and
    test recordings (:data:`METHOD`; ``res`` from :func:`summarise`):
    decided when its Holm-adjusted p is below 0.05 and no rule (:func:`~U.rule`) makes it
    inconclusive; ``marks`` holds each comparison's mark, ``status`` their combination.
    Holm's family: every comparison of the table's confirmatory findings
    (:func:`.protocol.confirmatory`); the exploratory ones form a family of their own. The
    report column is :func:`findings.evaluate_findings`'s, on the report's numbers."""
    from .findings import evaluate_findings as point_findings

    point = point_findings(tab, {n: {"metrics": r["metrics"], "initial": r["initial"]}
                                 for n, r in res["results"].items()})
    sums, have = _Sums(res), set(res["results"])
    computed = [_compute(tab, f, sums, have) for f in tab["findings"]]
    main = set(confirmatory(tab))
    for family in ([c for i, c in enumerate(computed) if i in main],
                   [c for i, c in enumerate(computed) if i not in main]):
        pieces = [q for c in family for q in c.get("pieces", [])]
        for q, p in zip(pieces, U.holm([q["test"].p for q in pieces])):
            q["p_holm"] = p
    out = []
    for f, p, c in zip(tab["findings"], point, computed):
        base = {"text": f["text"], "report": p["report"]}
        if "na" in c:
            out.append({**base, "ours": c["na"], "status": "n/a", "rule": None,
                        "difference": None, "interval": None, "recordings": None})
            continue
        out.append({**base, **_finding(tab, f, c)})
    return out


def rerun_difference(res_a: dict, row_a: str, res_b: dict, row_b: str, metric: str, *,
                     paired_seeds: bool = True) -> H.Test:
    """``b - a`` of ``metric`` for one row trained twice under other options (e.g. float32
    against ``--precision auto``'s bf16: ``experiments/precision_retrain.py``), from two
    results (``results.json``) on the same test split: recordings drawn jointly, seeds
    within each row, or with ``paired_seeds`` the same seed numbers drawn together (a seed
    fixes the initial weights and the data order under both options)."""
    ra, rb = res_a["results"][row_a], res_b["results"][row_b]
    if paired_seeds and list(ra["seeds"]) != list(rb["seeds"]):
        raise ValueError(f"paired seeds need the same seeds in both results, got "
                         f"{list(ra['seeds'])} and {list(rb['seeds'])}")
    res = {"results": {"a": {"seeds": ra["seeds"], "source": ra.get("source")},
                       "b": {"seeds": rb["seeds"], "source": rb.get("source")}}}
    data = _load(_Sums(res), None, [("a", metric, False), ("b", metric, False)])
    if data is None:
        raise ValueError(f"{metric}: a seed of {row_a!r} or {row_b!r} has no per-recording "
                         "test data")
    if paired_seeds:
        data["keys"] = ["seeds", "seeds"]
    return _test(data, lambda v: v[1] - v[0])
