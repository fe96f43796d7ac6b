"""A table trained with several seeds, as evidence: each cell the mean ± std over seeds and
a 95 % interval from a bootstrap over test recordings (the seeds' per-recording sums
pooled), each of the report's findings marked by a paired bootstrap over the same
recordings: reproduced, not reproduced or inconclusive (:mod:`bsp_fast.metrics.uncertainty`),
with the difference and its interval beside the mark. See docs/reproduce.md.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..metrics import uncertainty as U
from .findings import better as _sign, format_value

__all__ = ["summarise", "evaluate_findings", "DROP_TOLERANCE"]

#: tolerance on an effect size the report gives when its finding states none: half of it
DROP_TOLERANCE = 0.5


class _Sums:
    """The per-recording sums of a result's rows, loaded once."""

    def __init__(self, res: dict):
        self.res, self.docs = res, {}

    def _doc(self, path):
        if path not in self.docs:
            self.docs[path] = json.loads(Path(path).read_text(encoding="utf-8"))
        return self.docs[path]

    def _parts(self, row: str, metric: str, initial: bool):
        """``(sections, empty)``: the ``test`` (or ``initial``) section of each seed's
        per-recording file and the metric's value for no data; None when a seed has no
        file or its section lacks ``metric``."""
        r = self.res["results"][row]
        section = "initial" if (initial or r.get("source") == "initial") else "test"
        parts, empty = [], None
        for i, s in enumerate(r["seeds"].values()):
            if not s.get("per_recording"):
                return None
            d = self._doc(s["per_recording"])
            part = d.get(section)
            if not part or metric not in part["metrics"]:
                return None
            parts.append(part)
            if i == 0:  # the first seed's file says it
                empty = d.get("empty", {}).get(metric)
        return parts, float("nan") if empty is None else empty

    def pooled(self, row: str, metric: str, initial: bool = False):
        """``(recordings, num, den, empty)`` of ``row`` over its seeds (``initial``: its
        trivial baseline's), or None when a run has no per-recording file."""
        found = self._parts(row, metric, initial)
        if found is None:
            return None
        parts, empty = found
        return (*U.pool(parts, metric), empty)

    def per_seed(self, row: str, metric: str, initial: bool = False):
        """``[(recordings, num, den, empty), ...]``, one per seed of ``row``, when every seed
        was tested on the same recordings (the split fixed); else None (the caller pools)."""
        found = self._parts(row, metric, initial)
        if found is None:
            return None
        parts, empty = found
        out = [(*U.pool([part], metric), empty) for part in parts]
        return out if len({tuple(o[0]) for o in out}) == 1 else None


def _seed_mean(counts: list, fn):
    """``fn`` of the per-row means over seeds: ``values`` holds each row's seeds in turn
    (``counts`` of them per row)."""
    def stat(values):
        means, i = [], 0
        for c in counts:
            means.append(np.mean(np.stack([np.asarray(v) for v in values[i:i + c]]), axis=0))
            i += c
        return fn(means)
    return stat


def _grouped(items: list, keys, stat):
    """The interval of ``stat(values in items' order)`` where ``items`` are ``(recordings,
    num, den, empty)``: aligned on the recordings common to each key's group (one test
    set), resampled jointly within a group and independently between groups (rows of
    different datasets share no recordings); one key (the default) is the paired case."""
    keys = list(keys) if keys is not None else [0] * len(items)
    groups, perm = [], []
    for key in dict.fromkeys(keys):
        idx = [i for i, k in enumerate(keys) if k == key]
        groups.append(U.align([items[i][:3] for i in idx])[1])
        perm += idx
    back = np.argsort(perm)  # group order -> items' order

    def in_order(values):
        return stat([values[j] for j in back])
    return U.grouped_interval(groups, in_order, empty=[items[i][3] for i in perm])


def _seed_interval(sums: "_Sums", parts: list, fn, data_keys=None):
    """The bootstrap interval of ``fn`` of the rows' **means over seeds** (the tables'
    cells), resampling the test recordings jointly for every row and seed of one dataset
    (``data_keys``: one key per part; parts of different keys are resampled
    independently); None when a row has no per-recording sums or its seeds saw different
    recordings (``--split-seeds``)."""
    per = [sums.per_seed(row, metric, initial) for row, metric, initial in parts]
    if any(p is None for p in per):
        return None
    flat = [s for p in per for s in p]
    keys = None if data_keys is None else [k for k, p in zip(data_keys, per) for _ in p]
    return _grouped(flat, keys, _seed_mean([len(p) for p in per], fn))


def _values(r: dict, metric: str) -> list:
    key = "initial" if r.get("source") == "initial" else "metrics"
    return [s[key].get(metric) for s in r["seeds"].values() if s[key].get(metric) is not None]


def summarise(tab: dict, res: dict) -> dict:
    """Adds to each row of ``res["results"]`` (from :func:`seeds.reproduce_seeds`):
    ``metrics`` and ``initial`` (means over seeds), ``std`` (sample std over seeds, None
    for one seed) and ``interval`` (``[low, high]``: the bootstrap interval of the mean over
    seeds, the test recordings resampled jointly for every seed; with ``--split-seeds``, of
    the ratio pooled over seeds) per metric of the table. Returns ``res``."""
    sums = _Sums(res)
    for name, r in res["results"].items():
        r["metrics"], r["std"], r["interval"], r["initial"] = {}, {}, {}, {}
        for m in tab["metrics"]:
            vals = _values(r, m)
            r["metrics"][m] = float(np.mean(vals)) if vals else None
            r["std"][m] = float(np.std(vals, ddof=1)) if len(vals) > 1 else None
            iv = _seed_interval(sums, [(name, m, False)], lambda v: v[0])
            p = sums.pooled(name, m) if iv is None else None
            if p is not None:  # seeds on different splits: the pooled ratio's interval
                iv = U.ratio_interval(p[1], p[2], empty=p[3])
            if iv is not None:
                r["interval"][m] = [iv.low, iv.high]
            init = [s["initial"].get(m) for s in r["seeds"].values()
                    if s["initial"].get(m) is not None]
            r["initial"][m] = float(np.mean(init)) if init else None
        r["baseline"] = next(iter(r["seeds"].values())).get("baseline")
    return res


# ---------------------------------------------------------------------- findings
def _data_key(tab: dict, row: str) -> str:
    """Which test set a row is scored on: rows with a ``data_suffix`` read another
    dataset (docs/reproduce.md, ablation tables)."""
    spec = next((r for r in tab["rows"] if r["name"] == row), {})
    return spec.get("data_suffix") or ""


def _interval(sums: _Sums, parts: list, fn, tab: dict | None = None):
    """``parts``: ``(row, metric, initial)`` each; ``fn(values) -> statistic`` of the
    rows' means over seeds (pooled over seeds when the seeds' splits differ). Rows of
    different datasets (``tab``'s ``data_suffix``) are resampled independently."""
    keys = None if tab is None else [_data_key(tab, row) for row, _, _ in parts]
    iv = _seed_interval(sums, parts, fn, keys)
    if iv is not None:
        return iv
    pooled = [sums.pooled(row, metric, initial) for row, metric, initial in parts]
    if any(p is None for p in pooled):
        return None
    return _grouped(pooled, keys, fn)


def _text(tab, metric, label: str, iv) -> str:
    pp = " p.p." if tab["metrics"][metric].get("format") == "pct" else ""
    low, high = (format_value(tab, metric, v, True) for v in (iv.low, iv.high))
    return f"{label} {format_value(tab, metric, iv.value, True)}{pp} [{low}, {high}]"


def _relation(rel: str, margin: float):
    """(offset, side) of ``a - b`` for a ``compare`` relation: the statistic is
    ``a - b + offset`` and it must lie on ``side`` of zero."""
    return {">": (-margin, 1), ">=": (margin, 1), "<": (margin, -1), "<=": (-margin, -1)}[rel]


def _finding(tab, f, sums: _Sums, have) -> tuple:
    """(ours text, status) of one finding."""
    m, sign, k = f["metric"], _sign(tab, f["metric"]), f["kind"]
    pieces = []  # (label, parts, fn, side)
    if k == "order":
        for a, b in zip(f["rows"], f["rows"][1:]):
            pieces.append((f"{a} − {b}", [(a, m, False), (b, m, False)],
                           lambda v: v[0] - v[1], sign))
    elif k == "compare":
        off, side = _relation(f.get("relation", ">="), f.get("margin", 0.0))
        pieces.append((f"{f['a']} − {f['b']}" + (f" {off:+g}" if off else ""),
                       [(f["a"], m, False), (f["b"], m, False)],
                       lambda v: v[0] - v[1] + off, side))
    elif k == "drop":
        pieces.append(("loss", [(f["base"], m, False), (f["other"], m, False)],
                       lambda v: sign * (v[0] - v[1]), 1))
    elif k == "robuster":
        (a0, a1), (b0, b1) = f["a"], f["b"]
        pieces.append(("extra loss of b", [(a0, m, False), (a1, m, False), (b0, m, False),
                                           (b1, m, False)],
                       lambda v: sign * (v[2] - v[3]) - sign * (v[0] - v[1]), 1))
    elif k == "at_least":
        pieces.append((f"{f['row']} − {format_value(tab, m, f['value'])}",
                       [(f["row"], m, False)], lambda v: v[0] - f["value"], 1))
    elif k == "fails":
        base = "f1_constant" if f.get("baseline") == "constant" else m
        margin = f.get("margin", 0.0)
        pieces.append((f"{f['row']} − (trivial {margin:+g})",
                       [(f["row"], m, False), (f["row"], base, True)],
                       lambda v: sign * (v[0] - v[1]) - margin, -1))
    else:  # beats_initial
        for r in f["rows"]:
            pieces.append((f"{r} − trivial", [(r, m, False), (r, m, True)],
                           lambda v: v[0] - v[1], sign))
    if any(row not in have for _, parts, _, _ in pieces for row, _, _ in parts):
        return "rows not run", "n/a", None
    texts, marks, first = [], [], None
    for label, parts, fn, side in pieces:
        iv = _interval(sums, parts, fn, tab)
        if iv is None:
            return "no per-recording sums", "n/a", None
        first = first or iv
        marks.append(U.mark(iv, side))
        texts.append(_text(tab, m, label, iv) + f" ({marks[-1]})" * (len(pieces) > 1))
    ours = "; ".join(texts)
    if k == "drop" and f.get("report") is not None:
        tol = f.get("tolerance", DROP_TOLERANCE * abs(f["report"]))
        lo, hi = f["report"] - tol, f["report"] + tol
        agrees = first.high >= lo and first.low <= hi
        ours += (f"; size {'agrees with' if agrees else 'differs from'} the report's "
                 f"{format_value(tab, m, f['report'])} ± {format_value(tab, m, tol)}")
    return ours, U.combine_marks(marks), first


def evaluate_findings(tab: dict, res: dict) -> list:
    """``[{"text", "ours", "report", "status", "difference", "interval"}]``: each finding
    marked by the bootstrap over test recordings (``res`` from :func:`summarise`). The
    report column is :func:`findings.evaluate_findings`'s, on the report's numbers."""
    from .findings import evaluate_findings as point_findings

    point = point_findings(tab, {n: {"metrics": r["metrics"], "initial": r["initial"]}
                                 for n, r in res["results"].items()})
    sums, out = _Sums(res), []
    for f, p in zip(tab["findings"], point):
        ours, status, iv = _finding(tab, f, sums, set(res["results"]))
        out.append({"text": f["text"], "ours": ours, "report": p["report"], "status": status,
                    "difference": None if iv is None else iv.value,
                    "interval": None if iv is None else [iv.low, iv.high],
                    "recordings": None if iv is None else iv.n})
    return out
