"""Intervals and tests over training seeds *and* test recordings (#37): a two-level bootstrap.

:mod:`.uncertainty` resamples the test recordings with the seeds held fixed, so the
seed-to-seed spread of a row (often the largest source here) is outside its intervals.
Here both vary, as the data were made: each bootstrap replicate draws the test recordings
with replacement (one draw shared by every row of one test set, so comparisons of rows
scored on the same recordings stay paired; rows of different test sets are drawn
independently) and, for every row, its seeds with replacement (rows that are the same runs,
e.g. a model and its trivial baseline, share one seed draw). A row's value in a replicate is
the mean over its drawn seeds of each seed's value on the drawn recordings: ``sum(num) /
sum(den)`` for the ratio metrics (:class:`Ratios`), or a function of the drawn recordings'
clips for the per-clip ones such as AUROC (:class:`Clips`).

Methods: ``percentile`` (quantiles of the replicates), ``corrected`` (each row's seed
deviations scaled by sqrt(S / (S - 1)), the bootstrap's known shrinkage of a mean's
variance over S seeds) and ``t`` (value ± a t quantile with sum(S - 1) degrees of freedom
times the corrected replicates' standard deviation; its p-value is the matching t test).
:func:`simulate_coverage` measures how well they cover (``experiments/coverage_simulation.py``,
docs/reproduce.md): only ``t`` reached 93-97 % there. The tables use ``vc``
(:func:`variance_components`: seed, recording and interaction components, Satterthwaite's
df bounded by a dominant mean square's, :func:`bounded_df`), whose coverage where the
tables live is ``experiments/coverage_study.py``'s. Pure functions over arrays, no training
code (the layout of rliable's ``library.py``).
"""
from __future__ import annotations

from dataclasses import dataclass
import warnings

import numpy as np

from ..defaults import SEED
from .uncertainty import CONFIDENCE, N_RESAMPLES, Interval

__all__ = ["Ratios", "Clips", "Test", "two_level", "seed_recording_interval",
           "variance_components", "pseudo_values", "bounded_interval", "satterthwaite",
           "bounded_df", "DOMINANT", "ZERO_SE",
           "probability_of_improvement", "simulate_coverage", "row_values", "METHODS",
           "LEVELS"]

METHODS = ("percentile", "corrected", "t", "vc")
#: ``both``: seeds and recordings resampled; ``seeds``: seeds only, the recordings fixed
LEVELS = ("both", "seeds")


class Ratios:
    """A row whose metric is a ratio of sums: ``num``, ``den`` of shape (seeds, recordings);
    a seed's value on recordings drawn ``counts`` times is ``sum(counts * num) /
    sum(counts * den)``, ``empty`` where that denominator is 0."""

    def __init__(self, num, den, empty: float = float("nan")):
        self.num, self.den = np.asarray(num, np.float64), np.asarray(den, np.float64)
        if self.num.ndim != 2 or self.num.shape != self.den.shape:
            raise ValueError(f"num and den must be (seeds, recordings) arrays of one shape, "
                             f"got {self.num.shape} and {self.den.shape}")
        self.shape, self.empty = self.num.shape, float(empty)

    @classmethod
    def from_sections(cls, sections, metric: str) -> "Ratios":
        """A row from its seeds' per-recording sums of ``metric`` (one section of
        ``test_per_recording.json`` per seed, :func:`.uncertainty.pool`'s input), on the
        union of their recordings in sorted order: 0 / 0 where a seed has no clip of one."""
        from .uncertainty import pool

        pooled = [pool([sec], metric) for sec in sections]
        recs = sorted({r for rs, _, _ in pooled for r in rs})
        num, den = np.zeros((len(pooled), len(recs))), np.zeros((len(pooled), len(recs)))
        for i, (rs, n, d) in enumerate(pooled):
            idx = [recs.index(r) for r in rs]
            num[i, idx], den[i, idx] = n, d
        return cls(num, den)

    def values(self, counts: np.ndarray) -> np.ndarray:
        """(B, S) values for (B, R) recording counts."""
        n, d = counts @ self.num.T, counts @ self.den.T
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(d > 0, n / np.where(d > 0, d, 1.0), self.empty)


class Clips:
    """A row whose metric is not a ratio of per-recording sums (AUROC, average precision):
    ``clips[s][r]`` is ``(scores, labels)`` of seed s on recording r; a seed's value on
    drawn recordings is ``fn(scores, labels)`` of the drawn recordings' clips concatenated
    (a recording drawn k times counts k times), ``empty`` where ``fn`` raises
    ``ValueError`` (e.g. one class only)."""

    def __init__(self, clips, fn, empty: float = float("nan")):
        self.clips = [[(np.asarray(s, np.float64).ravel(), np.asarray(y).ravel())
                       for s, y in seed] for seed in clips]
        if not self.clips or len({len(c) for c in self.clips}) != 1:
            raise ValueError("clips must hold one list per seed, each with one (scores, "
                             "labels) pair per recording")
        self.shape, self.fn, self.empty = (len(self.clips), len(self.clips[0])), fn, empty
        # each seed's clips in recording order with their recording's index: a draw is one
        # np.repeat by per-clip counts (the jackknife's R draws were R x R small repeats)
        self._flat = [(np.concatenate([s for s, _ in seed]), np.concatenate([y for _, y in seed]),
                       np.repeat(np.arange(len(seed)), [len(s) for s, _ in seed]))
                      for seed in self.clips]

    def _one(self, flat: tuple, counts: np.ndarray) -> float:
        scores, labels, recording = flat
        times = np.asarray(counts).astype(np.int64)[recording]
        if not times.any():
            return self.empty
        try:
            return float(self.fn(np.repeat(scores, times), np.repeat(labels, times)))
        except ValueError:
            return self.empty

    def values(self, counts: np.ndarray) -> np.ndarray:
        return np.array([[self._one(flat, c) for flat in self._flat] for c in counts])


@dataclass(frozen=True)
class Test(Interval):
    """An :class:`Interval` with the test of "the statistic is 0" that matches it: ``p``
    two-sided (``t``, ``vc``: the t test with ``df`` degrees of freedom and standard error
    ``se``; otherwise twice the share of replicates beyond 0), NaN when undefined (``vc``:
    also when ``se`` is 0, see :data:`ZERO_SE`). ``components``: ``vc``'s variance
    components of the statistic (:func:`variance_components`), else None."""
    p: float = float("nan")
    se: float = float("nan")
    df: float = 0
    components: dict | None = None


def _part(p):
    return p if isinstance(p, (Ratios, Clips)) else Ratios(*p)


def _draws(parts, groups, seed_keys, n_resamples: int, rng, levels: str) -> tuple:
    """``(counts, seeds)``: per part its (B, R) recording counts (one draw per group, in the
    order groups first appear; all ones for ``levels='seeds'``) and its (B, S) drawn seed
    indices (one draw per seed key)."""
    counts, by_group = [], {}
    for p, g in zip(parts, groups):
        R = p.shape[1]
        if g not in by_group:
            if levels == "seeds":
                by_group[g] = np.ones((1, R))
            else:
                rec = rng.integers(0, R, size=(n_resamples, R))
                flat = (rec + R * np.arange(n_resamples)[:, None]).ravel()
                by_group[g] = np.bincount(flat, minlength=n_resamples * R).reshape(
                    n_resamples, R).astype(np.float64)
        if by_group[g].shape[1] != R:
            raise ValueError(f"rows of one test set must be aligned on the same recordings "
                             f"(one column each), got {by_group[g].shape[1]} and {R}")
        counts.append(by_group[g])
    seeds, by_key = [], {}
    for p, k in zip(parts, seed_keys):
        S = p.shape[0]
        if k not in by_key:
            by_key[k] = rng.integers(0, S, size=(n_resamples, S))
        if by_key[k].shape[1] != S:
            raise ValueError(f"rows that share seeds must have as many: {by_key[k].shape[1]} "
                             f"and {S}")
        seeds.append(by_key[k])
    return counts, seeds


def _per_seed(parts, counts, seeds) -> list:
    """``[(every, drawn)]``: each part's (B, S) values of all its seeds on the drawn
    recordings, and of its drawn seeds."""
    out = []
    for p, c, s in zip(parts, counts, seeds):
        every = np.broadcast_to(p.values(c), s.shape)
        out.append((every, np.take_along_axis(every, s, axis=1)))
    return out


def _setup(rows, groups, seed_keys) -> tuple:
    parts = [_part(p) for p in rows]
    if not parts:
        raise ValueError("no rows")
    groups = [0] * len(parts) if groups is None else list(groups)
    keys = list(range(len(parts))) if seed_keys is None else list(seed_keys)
    if len(groups) != len(parts) or len(keys) != len(parts):
        raise ValueError(f"groups and seed_keys need one entry per row ({len(parts)})")
    return parts, groups, keys


def _mean(a, axis):
    """``nanmean`` without its warning for a slice of NaN only (its value is then NaN)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(a, axis=axis)


def two_level(rows, fn=lambda v: v[0], *, groups=None, seed_keys=None,
              confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES,
              seed: int = SEED, method: str = "t", levels: str = "both",
              support=None) -> Test:
    """The value, interval and test of ``fn(row values)``. ``rows``: :class:`Ratios`,
    :class:`Clips` or ``(num, den)`` pairs of shape (seeds, recordings); a row's value is
    its mean over seeds. ``fn`` takes the list of row values (floats, or arrays of
    replicates: it must work elementwise, e.g. ``lambda v: v[0] - v[1]``). ``groups``: one
    test-set key per row (rows of one key share their recordings' columns and draw;
    default: one test set); ``seed_keys``: one key per row, rows of one key share their
    seed draw (the same runs; default: every row its own). ``levels``: :data:`LEVELS`.
    ``n``: the smallest test set's recordings. NaN bounds and p with fewer than two
    recordings, or (``t``) when no row has two seeds. ``method='vc'``: no resampling, see
    :func:`variance_components` (``support`` is its argument)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    if levels not in LEVELS:
        raise ValueError(f"levels must be one of {list(LEVELS)}, got {levels!r}")
    if method == "vc":
        return variance_components(rows, fn, groups=groups, seed_keys=seed_keys,
                                   confidence=confidence, levels=levels, support=support)
    parts, groups, keys = _setup(rows, groups, seed_keys)
    full = [_mean(p.values(np.ones((1, p.shape[1]))), 1)[0] for p in parts]
    value = float(fn(full))
    R = min(p.shape[1] for p in parts)
    df = sum(dict((k, p.shape[0] - 1) for p, k in zip(parts, keys)).values())
    undefined = Test(value, float("nan"), float("nan"), R, df=df)
    if R < 2 or (method == "t" and df < 1):
        return undefined
    counts, seeds = _draws(parts, groups, keys, n_resamples, np.random.default_rng(seed),
                           levels)
    reps = []
    for p, (every, drawn) in zip(parts, _per_seed(parts, counts, seeds)):
        mean, S = _mean(drawn, 1), p.shape[0]
        if method != "percentile" and S > 1:
            everyone = _mean(every, 1)
            mean = everyone + np.sqrt(S / (S - 1)) * (mean - everyone)
        reps.append(mean)
    reps = np.asarray(fn(reps), np.float64)
    reps = reps[np.isfinite(reps)]
    if reps.size < 2 or not np.isfinite(value):
        return undefined
    alpha = (1 - confidence) / 2
    if method == "t":
        from .._extras import require

        t = require("scipy.stats", "seed and recording intervals").t
        se = float(np.std(reps, ddof=1))
        half = float(t.ppf(1 - alpha, df)) * se
        # a zero-width interval (no variance at either level) bounds nothing: no p (ZERO_SE)
        tiny = 1e-12 * max(1.0, abs(value))
        p = float(2 * t.sf(abs(value) / se, df)) if se > tiny else float("nan")
        return Test(value, value - half, value + half, R, p, se, df)
    low, high = np.quantile(reps, [alpha, 1 - alpha])
    p = min(1.0, 2 * min(float(np.mean(reps <= 0)), float(np.mean(reps >= 0))))
    return Test(value, float(low), float(high), R, p, float(np.std(reps, ddof=1)), df)


# ---------------------------------------------------------------- variance components
#: why a ``vc`` test has no p-value (its mark is inconclusive by this rule)
ZERO_SE = "standard error 0 (no variation at either level: the sums bound no variance)"


def pseudo_values(part) -> np.ndarray:
    """(S, R) linearised values of one row: ``z[s, r]`` averages over the recordings to
    seed s's value, and its spread over recordings is the first-order spread of that
    value when the recordings are resampled. :class:`Ratios`: the delta method for a ratio
    of sums, ``v_s + R (num - v_s den) / D_s`` (Woodruff 1971); a seed with no
    denominator is its ``empty`` value everywhere. :class:`Clips`: the jackknife
    pseudo-values ``R v_s - (R - 1) v_s(-r)`` over recordings (Quenouille-Tukey)."""
    S, R = part.shape
    full = part.values(np.ones((1, R)))[0]
    if isinstance(part, Ratios):
        D = part.den.sum(1, keepdims=True)
        v = full[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            z = v + R * (part.num - v * part.den) / np.where(D > 0, D, 1.0)
        return np.where(D > 0, z, np.broadcast_to(v, z.shape))
    loo = part.values(1.0 - np.eye(R))  # (R, S): each recording left out
    return R * full[:, None] - (R - 1) * loo.T


def _gradient(fn, full) -> np.ndarray:
    """``fn``'s derivative in each row's value at ``full`` (central differences; the
    findings' functions are linear, so exact up to rounding)."""
    full = np.asarray(full, np.float64)
    g = np.zeros(len(full))
    for k in range(len(full)):
        h = 1e-6 * max(1.0, abs(full[k])) if np.isfinite(full[k]) else 1e-6
        up, down = full.copy(), full.copy()
        up[k] += h
        down[k] -= h
        g[k] = (float(fn(list(up))) - float(fn(list(down)))) / (2 * h)
    return np.where(np.abs(g) < 1e-9, 0.0, g)


def _blocks(parts, groups, keys, grad) -> dict:
    """``{(seed key, test set): W}``: the linearised statistic's (S, R) terms, the rows of
    one seed key on one test set summed with their weights (rows of weight 0 left out)."""
    blocks, width = {}, {}
    for p, grp, k, w in zip(parts, groups, keys, grad):
        if w == 0:
            continue
        if width.setdefault(grp, p.shape[1]) != p.shape[1]:
            raise ValueError(f"rows of one test set must be aligned on the same recordings "
                             f"(one column each), got {width[grp]} and {p.shape[1]}")
        z = w * pseudo_values(p)
        have = blocks.get((k, grp))
        if have is not None and have.shape != z.shape:
            raise ValueError(f"rows that share seeds must have as many: {have.shape[0]} "
                             f"and {z.shape[0]}")
        blocks[(k, grp)] = z if have is None else have + z
    return blocks


def _terms(blocks: dict, levels: str) -> list:
    """``[(coefficient, mean square, df, level)]`` whose sum of coefficient x mean square
    is the unbiased variance of the statistic in the crossed model ``W[s, r] = m + a_s +
    b_r + e_sr`` of each block (seeds and recordings random): per test set the variance of
    its recording means over R; per seed key the variance of its seed totals over S, less
    the interaction's share of it (a seed key whose seed component comes out negative is
    taken as 0: its terms are dropped). ``levels='seeds'``: the recordings fixed, the
    seed totals' variance over S only."""
    terms, by_group, by_key = [], {}, {}
    for (k, grp), W in blocks.items():
        by_group.setdefault(grp, []).append(W)
        by_key.setdefault(k, []).append(W)
    if levels == "both":
        for Ws in by_group.values():
            R = Ws[0].shape[1]
            terms.append((1.0 / R, float(np.var(sum(W.mean(0) for W in Ws), ddof=1)),
                          R - 1, "recording"))
    for Ws in by_key.values():
        S = Ws[0].shape[0]
        seed = [(1.0 / S, float(np.var(sum(W.mean(1) for W in Ws), ddof=1)), S - 1, "seed")]
        for W in Ws if levels == "both" else []:
            R = W.shape[1]
            seed.append((-1.0 / (R * S), _interaction(W), (S - 1) * (R - 1), "interaction"))
        if levels == "seeds" or sum(c * m for c, m, _, _ in seed) > 0:
            terms += seed
    return terms


def _interaction(W: np.ndarray) -> float:
    """The seed x recording mean square of one block (two-way ANOVA, one value a cell)."""
    e = W - W.mean(1, keepdims=True) - W.mean(0, keepdims=True) + W.mean()
    return float((e ** 2).sum()) / ((W.shape[0] - 1) * (W.shape[1] - 1))


def _components(blocks: dict) -> dict:
    """The statistic's variance components at one seed and one recording: ``seed``,
    ``recording``, ``interaction`` (each unbiased, negative ones taken as 0), so that its
    variance at S seeds and R recordings is about ``seed / S + recording / R +
    interaction / (S R)`` (the power analysis's input), with the sizes they came from
    (the smallest row's; other rows' components are scaled to them)."""
    S = min(W.shape[0] for W in blocks.values())
    R = min(W.shape[1] for W in blocks.values())
    by_group, by_key = {}, {}
    for (k, grp), W in blocks.items():
        by_group.setdefault(grp, []).append(W)
        by_key.setdefault(k, []).append(W)
    inter = sum(_interaction(W) * S * R / W.size for W in blocks.values())
    rec = sum(max(0.0, float(np.var(sum(W.mean(0) for W in Ws), ddof=1))
                  - sum(_interaction(W) / W.shape[0] for W in Ws)) * R / Ws[0].shape[1]
              for Ws in by_group.values())
    seed = sum(max(0.0, float(np.var(sum(W.mean(1) for W in Ws), ddof=1))
                   - sum(_interaction(W) / W.shape[1] for W in Ws)) * S / Ws[0].shape[0]
               for Ws in by_key.values())
    return {"seed": seed, "recording": rec, "interaction": inter, "seeds": S,
            "recordings": R}


def satterthwaite(terms) -> tuple:
    """``(variance, df)`` of a linear combination of mean squares, ``terms`` ``[(c, ms,
    df, ...)]``: Satterthwaite's (1946) degrees of freedom ``V^2 / sum((c ms)^2 / df)``."""
    var = sum(t[0] * t[1] for t in terms)
    den = sum((t[0] * t[1]) ** 2 / t[2] for t in terms if t[2] > 0)
    return float(var), (float(var ** 2 / den) if den > 0 else float("inf"))


#: a mean square carrying at least this share of the estimated variance bounds the degrees
#: of freedom by its own (:func:`bounded_df`)
DOMINANT = 0.5


def bounded_df(terms) -> tuple:
    """``(variance, df)``: :func:`satterthwaite`'s, the df no larger than that of a mean
    square carrying at least :data:`DOMINANT` of the variance. Where one mean square of
    few df dominates, Satterthwaite's df rises exactly when that mean square comes out
    small by chance (the interval is then short *and* its t quantile small: liberal, 91-93 %
    at 3 seeds in experiments/coverage_study.py); the bound is the conservative df of the
    Behrens-Fisher problem (the smaller sample's, Hsu 1938, Scheffé 1970) applied to the
    term that carries most of the variance, and changes nothing where none does."""
    var, df = satterthwaite(terms)
    for t in terms:
        if var > 0 and t[2] > 0 and t[0] * t[1] >= DOMINANT * var:
            df = min(df, float(t[2]))
    return var, df


def bounded_interval(value: float, se: float, df: float, support=None, n: int = 0,
                     confidence: float = CONFIDENCE) -> tuple:
    """``(low, high)`` of a t interval (``df``) that respects the statistic's range
    ``support`` without clipping: ``(0, 1)``: the Clopper-Pearson interval at the
    effective sample size ``value (1 - value) / se^2`` scaled by ``(z / t_df)^2`` (Korn &
    Graubard 1998), which at a value of 0 or 1 with ``se`` 0 takes the ``n`` counted units
    (e.g. 19 of 19 perfect recordings: [0.823, 1]); ``(0, inf)``: the t interval of the
    log (a ratio scale); otherwise (None) the symmetric t interval."""
    from .._extras import require

    st = require("scipy.stats", "seed and recording intervals")
    a = (1 - confidence) / 2
    q = float(st.t.ppf(1 - a, df)) if np.isfinite(df) else float(st.norm.ppf(1 - a))
    lo_s, hi_s = support if support is not None else (-np.inf, np.inf)
    if (lo_s, hi_s) == (0.0, 1.0) and 0 <= value <= 1:
        if se > 0 and 0 < value < 1:
            n_eff = value * (1 - value) / se ** 2 * (float(st.norm.ppf(1 - a)) / q) ** 2
        else:
            n_eff = float(n)
        if n_eff <= 0:
            return float("nan"), float("nan")
        x = value * n_eff
        low = 0.0 if x <= 0 else float(st.beta.ppf(a, x, n_eff - x + 1))
        high = 1.0 if x >= n_eff else float(st.beta.ppf(1 - a, x + 1, n_eff - x))
        return low, high
    if (lo_s, hi_s) == (0.0, np.inf) and value > 0:
        f = float(np.exp(q * se / value))
        return value / f, value * f
    return value - q * se, value + q * se


def variance_components(rows, fn=lambda v: v[0], *, groups=None, seed_keys=None,
                        confidence: float = CONFIDENCE, levels: str = "both",
                        support=None) -> Test:
    """The value, interval and t test of ``fn(row values)`` from the rows' seed,
    recording and seed x recording variance components (arguments as :func:`two_level`;
    no resampling). Each row is linearised (:func:`pseudo_values`), the statistic too (its
    derivative in each row); rows of one ``seed_keys`` key are paired on their seeds (the
    same runs, or runs that share seed numbers), rows of one ``groups`` key on their
    recordings; the variance is :func:`_terms`'s, the df :func:`bounded_df`'s
    (Satterthwaite's, bounded by a dominant mean square's), the interval
    :func:`bounded_interval`'s. NaN bounds and p with fewer than two recordings
    or a row of fewer than two seeds; p NaN (:data:`ZERO_SE`) when the variance is 0."""
    parts, groups, keys = _setup(rows, groups, seed_keys)
    full = [_mean(p.values(np.ones((1, p.shape[1]))), 1)[0] for p in parts]
    value = float(fn(full))
    R = min(p.shape[1] for p in parts)
    undefined = Test(value, float("nan"), float("nan"), R, df=float("nan"))
    grad = _gradient(fn, full)
    used = [p for p, w in zip(parts, grad) if w != 0]
    if R < 2 or not np.isfinite(value) or any(p.shape[0] < 2 for p in used):
        return undefined
    with np.errstate(invalid="ignore"):
        blocks = _blocks(parts, groups, keys, grad)
    if not blocks:  # fn does not depend on the rows: a constant
        return Test(value, value, value, R, float("nan"), 0.0, float("nan"))
    terms = _terms(blocks, levels)
    if not np.all(np.isfinite([t[1] for t in terms])):
        return undefined
    var, df = bounded_df(terms)
    se = float(np.sqrt(max(var, 0.0)))
    comps = _components(blocks) if levels == "both" else None
    low, high = bounded_interval(value, se, df, support, R, confidence)
    if se <= 1e-9 * max([1.0] + [abs(x) for x in full if np.isfinite(x)]):  # rounding
        low, high = bounded_interval(value, 0.0, df, support, R, confidence)
        return Test(value, low, high, R, float("nan"), 0.0, df, comps)
    from .._extras import require

    p = float(2 * require("scipy.stats", "seed and recording intervals").t.sf(
        abs(value) / se, df))
    return Test(value, low, high, R, p, se, df, comps)


def row_values(num, den) -> np.ndarray:
    """Per-seed values ``sum(num) / sum(den)`` over the recordings (the last axis)."""
    num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num.sum(-1) / den.sum(-1)


def seed_recording_interval(rows, fn=lambda v: v[0], *, confidence: float = CONFIDENCE,
                            n_resamples: int = N_RESAMPLES, seed: int = SEED,
                            method: str = "percentile") -> Test:
    """:func:`two_level` for rows on one test set, each with its own seeds (the coverage
    simulation's case)."""
    rows = [_part(r) for r in rows]
    if len({r.shape[1] for r in rows}) > 1:
        raise ValueError("rows must be aligned on the same recordings (one column each): "
                         + ", ".join(str(r.shape) for r in rows))
    return two_level(rows, fn, confidence=confidence, n_resamples=n_resamples, seed=seed,
                     method=method)


def probability_of_improvement(a, b, better: int = 1, *, groups=None, seed_keys=None,
                               confidence: float = CONFIDENCE,
                               n_resamples: int = N_RESAMPLES, seed: int = SEED) -> Interval:
    """P(a run of row ``a`` beats a run of row ``b``): the share of (seed of a, seed of b)
    pairs where ``a``'s value is better (``better`` +1: higher, -1: lower), ties counting a
    half (the Mann-Whitney statistic rliable and Bouthillier et al. 2021 report), over the
    recordings given; its percentile interval resamples seeds and recordings as
    :func:`two_level` does (``groups``, ``seed_keys`` as there)."""
    if better not in (1, -1):
        raise ValueError(f"better must be 1 (higher) or -1 (lower), got {better!r}")
    parts, groups, keys = _setup([a, b], groups, seed_keys)
    if groups[0] == groups[1] and parts[0].shape[1] != parts[1].shape[1]:
        raise ValueError("rows must be aligned on the same recordings (one column each): "
                         f"{parts[0].shape} and {parts[1].shape}")

    def p(va, vb):
        diff = better * (va[..., :, None] - vb[..., None, :])
        return ((diff > 0) + 0.5 * (diff == 0)).mean(axis=(-2, -1))

    full = [q.values(np.ones((1, q.shape[1])))[0] for q in parts]
    value = float(p(*full))
    R = min(q.shape[1] for q in parts)
    if R < 2:
        return Interval(value, float("nan"), float("nan"), R)
    counts, seeds = _draws(parts, groups, keys, n_resamples, np.random.default_rng(seed),
                           "both")
    (_, da), (_, db) = _per_seed(parts, counts, seeds)
    reps = p(da, db)
    alpha = (1 - confidence) / 2
    low, high = np.quantile(reps, [alpha, 1 - alpha])
    return Interval(value, float(low), float(high), R)


def simulate_coverage(*, seeds: int, recordings: int, seed_sd: float, recording_sd: float,
                      delta: float = 0.0, sims: int = 200, n_resamples: int = 500,
                      clips=(20, 60), noise_sd: float = 0.05, rng_seed: int = 0,
                      confidence: float = CONFIDENCE, method: str = "percentile") -> dict:
    """How often the interval of ``row1 - row0`` covers the true difference ``delta``, in
    ``sims`` synthetic tables with known answers: per recording r a difficulty
    ``N(0, recording_sd)`` shared by both rows, per (row, seed) an offset ``N(0, seed_sd)``
    (each row's seeds drawn anew in every table: the population a finding is about), per
    (seed, recording) ``clips`` uniform in ``clips`` and a mean per-clip value ``base +
    row effect + seed offset + difficulty + N(0, noise_sd) / sqrt(clips)``. Returns the
    coverage of the two-level interval and, beside it, of the recordings-only interval
    that holds the seeds fixed (what :mod:`.uncertainty` computes), with the mean widths."""
    rng = np.random.default_rng(rng_seed)
    hit2 = hit1 = 0
    width2 = width1 = 0.0
    for k in range(sims):
        difficulty = rng.normal(0, recording_sd, recordings)
        rows = []
        for effect in (0.0, delta):
            offset = rng.normal(0, seed_sd, (seeds, 1))
            den = rng.integers(clips[0], clips[1] + 1, (seeds, recordings)).astype(float)
            mean = 0.5 + effect + offset + difficulty + rng.normal(0, noise_sd,
                                                                  (seeds, recordings)) \
                / np.sqrt(den)
            rows.append((mean * den, den))
        two = seed_recording_interval(rows, lambda v: v[1] - v[0], confidence=confidence,
                                      n_resamples=n_resamples, seed=rng_seed + k,
                                      method=method)
        hit2 += two.low <= delta <= two.high
        width2 += two.high - two.low
        # seeds held fixed: recordings resampled, every seed kept (the pooled means)
        rec = np.random.default_rng(rng_seed + k).integers(
            0, recordings, (n_resamples, recordings))
        reps = []
        for num, den in rows:
            n, d = num[:, rec].sum(-1), den[:, rec].sum(-1)  # (S, B)
            reps.append((n / d).mean(0))
        diff = reps[1] - reps[0]
        lo, hi = np.quantile(diff, [(1 - confidence) / 2, 1 - (1 - confidence) / 2])
        hit1 += lo <= delta <= hi
        width1 += hi - lo
    return {"method": method, "seeds": seeds, "recordings": recordings, "seed_sd": seed_sd,
            "recording_sd": recording_sd, "delta": delta, "sims": sims,
            "coverage_seeds_and_recordings": hit2 / sims,
            "coverage_recordings_only": hit1 / sims,
            "width_seeds_and_recordings": width2 / sims, "width_recordings_only": width1 / sims}
