"""Intervals over test recordings and the marks of a finding (docs/reproduce.md, "Seeds,
intervals and marks").

Every metric of the tasks is a ratio of global sums, ``value = sum(num) / sum(den)``
(errors / joints, correct / joints, 2TP / (2TP + FP + FN) ...). A test split's clips come
from a few recordings and overlap (sliding windows), so the units that may be resampled
are the recordings: ``num`` and ``den`` are kept per recording
(:mod:`bsp_fast.training.per_recording`) and the bootstrap (``scipy.stats.bootstrap``,
percentile intervals) resamples recordings with all their clips. Two or more rows scored
on the same recordings are resampled *jointly* (``paired=True``): the interval of a
difference then reflects only how the rows differ recording by recording. These intervals
hold the training seeds fixed; the tables use :mod:`.hierarchical` (seeds and recordings).

A finding's mark (:func:`decide`): **reproduced** when its statistic is decided on the
report's side of zero, **not reproduced** when on the other side, **inconclusive**
otherwise; decided means a Holm-adjusted p-value (:func:`holm`, over the table's family)
below ``1 - CONFIDENCE``, and never with fewer than :data:`MIN_SEEDS` seeds in a row or
:data:`MIN_RECORDINGS` test recordings (:func:`rule`). :func:`mark` reads an interval
alone (identical rows give an interval [0, 0]: inconclusive).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..defaults import SEED

__all__ = ["Interval", "CONFIDENCE", "N_RESAMPLES", "YES", "NO", "UNSURE", "pool",
           "align", "ratio", "ratio_interval", "paired_interval", "grouped_interval", "mark",
           "combine_marks", "holm", "decide", "rule", "equivalence", "MIN_SEEDS",
           "MIN_RECORDINGS", "AGREES", "DIFFERS", "UNDETERMINED"]

CONFIDENCE = 0.95
N_RESAMPLES = 2000
YES, NO, UNSURE = "reproduced", "not reproduced", "inconclusive"
#: below these a finding is inconclusive by rule, whatever its interval: with fewer seeds
#: the seed variance is barely estimated (a t quantile with 2 degrees of freedom is 4.3),
#: with fewer recordings the recording-level bootstrap under-covers (docs/reproduce.md)
MIN_SEEDS, MIN_RECORDINGS = 5, 10
AGREES, DIFFERS, UNDETERMINED = "agrees", "differs", "undetermined"


@dataclass(frozen=True)
class Interval:
    """A statistic on the full test set and its bootstrap interval (NaN when it cannot be
    computed: fewer than two recordings)."""
    value: float
    low: float
    high: float
    n: int  # recordings resampled


def pool(sections, metric: str) -> tuple:
    """``(recordings, num, den)``: the per-recording sums of ``metric`` added over several
    runs (seeds) of one row. ``sections``: ``{"recordings": [...], "metrics": {metric:
    {"num": [...], "den": [...]}}}`` each (a ``test`` or ``initial`` section of
    ``test_per_recording.json``); a recording tested by several seeds sums their terms."""
    sums: dict = {}
    for sec in sections:
        if metric not in sec["metrics"]:
            raise ValueError(f"metric {metric!r} not in the per-recording sums; allowed: "
                             + ", ".join(sorted(sec["metrics"])))
        m = sec["metrics"][metric]
        if not (len(m["num"]) == len(m["den"]) == len(sec["recordings"])):
            raise ValueError(f"metric {metric!r}: num, den and recordings differ in length")
        for rec, a, b in zip(sec["recordings"], m["num"], m["den"]):
            a0, b0 = sums.get(rec, (0.0, 0.0))
            sums[rec] = (a0 + float(a), b0 + float(b))
    recs = sorted(sums)
    return recs, np.array([sums[r][0] for r in recs]), np.array([sums[r][1] for r in recs])


def align(pooled: list) -> tuple:
    """The recordings common to every ``(recordings, num, den)`` of ``pooled`` and each
    one's ``(num, den)`` on them, in one order: ``(recordings, [(num, den), ...])``."""
    common = sorted(set.intersection(*(set(p[0]) for p in pooled))) if pooled else []
    out = []
    for recs, num, den in pooled:
        pos = {r: i for i, r in enumerate(recs)}
        idx = np.array([pos[r] for r in common], dtype=np.int64)
        out.append((num[idx], den[idx]))
    return common, out


def ratio(num, den, axis: int = -1, empty: float = float("nan")):
    """``sum(num) / sum(den)`` along ``axis``; ``empty`` where the denominator is 0."""
    n, d = np.sum(num, axis=axis), np.sum(den, axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(d > 0, n / np.where(d > 0, d, 1.0), empty)


def _check(confidence: float, n_resamples: int) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, int) or n_resamples < 1:
        raise ValueError(f"n_resamples must be an integer >= 1, got {n_resamples!r}")


def ratio_interval(num, den, *, empty: float = float("nan"), confidence: float = CONFIDENCE,
                   n_resamples: int = N_RESAMPLES, seed: int = SEED) -> Interval:
    """``sum(num) / sum(den)`` over the recordings and its bootstrap interval."""
    return paired_interval([(num, den)], lambda v: v[0], empty=empty, confidence=confidence,
                           n_resamples=n_resamples, seed=seed)


def paired_interval(rows: list, fn, *, empty=float("nan"), confidence: float = CONFIDENCE,
                    n_resamples: int = N_RESAMPLES, seed: int = SEED) -> Interval:
    """A statistic of several rows on the same recordings: ``rows`` is a list of
    ``(num, den)`` arrays aligned on the recordings (:func:`align`); ``fn(values)`` maps
    the list of row values (arrays over resamples) to the statistic, e.g. ``lambda v: v[0]
    - v[1]``. The recordings are resampled jointly for all rows. ``empty``: one value, or
    one per row, for a row whose resampled denominator is 0."""
    _check(confidence, n_resamples)
    arrays = [np.asarray(a, dtype=np.float64) for nd in rows for a in nd]
    n = {a.shape for a in arrays}
    if len(n) != 1 or len(next(iter(n))) != 1:
        raise ValueError(f"every num and den must be a 1-d array of the same length (one "
                         f"entry per recording), got shapes {sorted(n)}")
    # one test set is the one-group case: recordings resampled jointly for every row
    # (scipy resamples a paired bootstrap's indices the same way)
    return grouped_interval([rows], fn, empty=empty, confidence=confidence,
                            n_resamples=n_resamples, seed=seed)


def grouped_interval(groups: list, fn, *, empty=float("nan"),
                     confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES,
                     seed: int = SEED) -> Interval:
    """Like :func:`paired_interval` for rows scored on **different** test sets (e.g. two
    datasets): ``groups`` is a list of groups, each a list of ``(num, den)`` rows aligned
    on that group's recordings. Recordings are resampled jointly within a group and
    independently between groups (``scipy.stats.bootstrap`` with ``paired=False`` over
    each group's recording indices). ``fn`` gets the row values in group order; ``empty``
    one value or one per row in that order. ``n`` is the smallest group's count."""
    from .._extras import require

    bootstrap = require("scipy.stats", "bootstrap intervals (bsp-reproduce)").bootstrap
    _check(confidence, n_resamples)
    groups = [[tuple(np.asarray(a, dtype=np.float64) for a in nd) for nd in g] for g in groups]
    sizes = []
    for g in groups:
        n = {a.shape for nd in g for a in nd}
        if not g or len(n) != 1 or len(next(iter(n))) != 1:
            raise ValueError(f"each group's num and den must be 1-d arrays of one length "
                             f"(one entry per recording), got shapes {sorted(n)}")
        sizes.append(next(iter(n))[0])
    n_rows = sum(len(g) for g in groups)
    empties = list(empty) if isinstance(empty, (list, tuple)) else [empty] * n_rows

    def statistic(*idx, axis=-1):
        values, k = [], 0
        for g, ix in zip(groups, idx):
            ix = np.asarray(ix, dtype=np.int64)
            for num, den in g:
                values.append(ratio(num[ix], den[ix], -1, empties[k]))
                k += 1
        return np.asarray(fn(values), dtype=np.float64)

    full = [np.arange(n) for n in sizes]
    value = float(statistic(*full))
    if min(sizes) < 2 or not np.isfinite(value):
        return Interval(value, float("nan"), float("nan"), min(sizes))
    res = bootstrap(tuple(full), statistic, paired=False, vectorized=True, axis=-1,
                    method="percentile", confidence_level=confidence,
                    n_resamples=n_resamples, random_state=np.random.default_rng(seed))
    return Interval(value, float(res.confidence_interval.low),
                    float(res.confidence_interval.high), min(sizes))


def mark(interval: Interval, side: int = 1) -> str:
    """``reproduced`` when the interval lies strictly on ``side`` (+1: above zero, -1:
    below) of zero, ``not reproduced`` when strictly on the other side, else
    ``inconclusive`` (also for an undefined interval)."""
    if side not in (1, -1):
        raise ValueError(f"side must be one of [1, -1], got {side!r}")
    lo, hi = side * interval.low, side * interval.high
    lo, hi = min(lo, hi), max(lo, hi)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return UNSURE
    if lo > 0:
        return YES
    if hi < 0:
        return NO
    return UNSURE


def combine_marks(marks: list) -> str:
    """A finding made of several parts (an ordering of rows: each adjacent pair):
    reproduced when every part is, not reproduced when any part is not, else
    inconclusive."""
    if any(m == NO for m in marks):
        return NO
    if marks and all(m == YES for m in marks):
        return YES
    return UNSURE


def holm(pvalues) -> list:
    """Holm-Bonferroni adjusted p-values, in the input's order: the k-th smallest of m is
    multiplied by (m - k + 1), made non-decreasing in that order and capped at 1 (a
    hypothesis is rejected at level a when its adjusted p < a; the family-wise error rate
    stays at a). NaN p-values (nothing tested) stay NaN and do not count in m."""
    p = np.asarray(pvalues, dtype=np.float64)
    out = np.full(p.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(p))
    if idx.size:
        if ((p[idx] < 0) | (p[idx] > 1)).any():
            raise ValueError(f"p-values must lie in [0, 1], got {p[idx].tolist()}")
        order = idx[np.argsort(p[idx], kind="stable")]
        m = idx.size
        adjusted = np.maximum.accumulate((m - np.arange(m)) * p[order])
        out[order] = np.minimum(adjusted, 1.0)
    return out.tolist()


def decide(value: float, p_adjusted: float, side: int = 1,
           level: float = round(1 - CONFIDENCE, 12)) -> str:
    """The mark of one comparison: decided when ``p_adjusted < level``, then reproduced
    when ``value`` lies on ``side`` of zero (+1 above, -1 below) and not reproduced when on
    the other side; else (or undefined) inconclusive."""
    if side not in (1, -1):
        raise ValueError(f"side must be one of [1, -1], got {side!r}")
    if not (np.isfinite(p_adjusted) and np.isfinite(value)) or p_adjusted >= level \
            or value == 0:
        return UNSURE
    return YES if side * value > 0 else NO


def rule(seeds: dict, recordings: int) -> str | None:
    """Why a finding is inconclusive whatever its interval, or None: ``seeds`` maps each
    row it needs to its number of seeds, ``recordings`` is its smallest test set's count."""
    few = {r: s for r, s in seeds.items() if s < MIN_SEEDS}
    why = []
    if few:
        why.append(f"fewer than {MIN_SEEDS} seeds (" + ", ".join(f"{r}: {s}" for r, s in
                                                                few.items()) + ")")
    if recordings < MIN_RECORDINGS:
        why.append(f"fewer than {MIN_RECORDINGS} test recordings ({recordings})")
    return "; ".join(why) or None


def equivalence(interval: Interval, target: float, margin: float) -> str:
    """Whether an effect's size agrees with ``target`` within ``margin`` (a TOST-style
    equivalence test): ``agrees`` when the whole interval lies inside ``[target - margin,
    target + margin]``, ``differs`` when it lies wholly outside, ``undetermined``
    otherwise (an overlap alone shows nothing: a wide interval overlaps every size)."""
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a number >= 0, got {margin!r}")
    lo, hi = interval.low, interval.high
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return UNDETERMINED
    if target - margin <= lo and hi <= target + margin:
        return AGREES
    if hi < target - margin or lo > target + margin:
        return DIFFERS
    return UNDETERMINED
