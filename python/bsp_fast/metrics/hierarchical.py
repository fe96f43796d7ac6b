"""Intervals over training seeds *and* test recordings (#37): a two-level bootstrap.

:mod:`.uncertainty` resamples the test recordings with the seeds held fixed, so the
seed-to-seed spread of a row (often the largest source here) is outside its intervals.
Here both vary, as the data were made: each bootstrap replicate draws the test recordings
with replacement (one draw shared by every row, so comparisons of rows scored on the same
recordings stay paired) and, for every row independently, its seeds with replacement; a
row's value in a replicate is the mean over its drawn seeds of ``sum(num) / sum(den)``
over the drawn recordings (every metric is such a ratio, :mod:`.uncertainty`). Intervals
are percentile intervals of ``fn`` over the replicates. Pure functions over arrays, no
training code (the layout of rliable's ``library.py``); how well the intervals cover is
measured by :func:`simulate_coverage` (``experiments/coverage_simulation.py``,
docs/reproduce.md).
"""
from __future__ import annotations

import numpy as np

from ..defaults import SEED
from .uncertainty import CONFIDENCE, N_RESAMPLES, Interval

__all__ = ["seed_recording_interval", "probability_of_improvement", "simulate_coverage",
           "row_values", "METHODS"]


def _rows(rows) -> list:
    out = []
    for k, (num, den) in enumerate(rows):
        num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
        if num.ndim != 2 or num.shape != den.shape:
            raise ValueError(f"row {k}: num and den must be (seeds, recordings) arrays of one "
                             f"shape, got {num.shape} and {den.shape}")
        out.append((num, den))
    if not out:
        raise ValueError("no rows")
    if len({n.shape[1] for n, _ in out}) != 1:
        raise ValueError("rows must be aligned on the same recordings (one column each): "
                         + ", ".join(str(n.shape) for n, _ in out))
    return out


def row_values(num, den) -> np.ndarray:
    """Per-seed values ``sum(num) / sum(den)`` over the recordings (the last axis)."""
    num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num.sum(-1) / den.sum(-1)


def _per_seed(rows: list, n_resamples: int, rng) -> tuple:
    """``(rec, [(B, S) values])``: per replicate the drawn recordings (one draw for every
    row), and each row's drawn seeds' values ``sum(num) / sum(den)`` over them."""
    R = rows[0][0].shape[1]
    rec = rng.integers(0, R, size=(n_resamples, R))
    out = []
    for num, den in rows:
        seeds = rng.integers(0, num.shape[0], size=(n_resamples, num.shape[0]))
        n = num[seeds[:, :, None], rec[:, None, :]].sum(-1)  # (B, S) over drawn recordings
        d = den[seeds[:, :, None], rec[:, None, :]].sum(-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            out.append(n / d)
    return rec, out


def _replicates(rows: list, n_resamples: int, rng, correct: bool = False) -> list:
    """``[(B,) row values]``: the mean of each row's drawn seeds (:func:`_per_seed`).
    ``correct``: each row's seed-resampling deviation (from the mean of all its seeds on
    the same drawn recordings) scaled by sqrt(S / (S - 1)), the bootstrap's known
    shrinkage of a mean's variance over S seeds."""
    rec, per_seed = _per_seed(rows, n_resamples, rng)
    out = []
    for (num, den), values in zip(rows, per_seed):
        S = num.shape[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            drawn = np.nanmean(values, axis=1)
            if correct and S > 1:
                every = np.nanmean(num[:, rec].sum(-1) / den[:, rec].sum(-1), axis=0)
                drawn = every + np.sqrt(S / (S - 1)) * (drawn - every)
        out.append(drawn)
    return out


METHODS = ("percentile", "corrected", "t")


def seed_recording_interval(rows, fn=lambda v: v[0], *, confidence: float = CONFIDENCE,
                            n_resamples: int = N_RESAMPLES, seed: int = SEED,
                            method: str = "percentile") -> Interval:
    """The value and interval of ``fn(row values)`` where ``rows`` are ``(num, den)``
    arrays of shape (seeds, recordings), aligned on the same recordings, and a row's value
    is its mean over seeds of ``sum(num) / sum(den)``. ``fn`` takes the list of row values
    (floats, or arrays of replicates: it must work elementwise, e.g. ``lambda v: v[0] -
    v[1]``). ``method``: ``percentile`` (quantiles of the replicates), ``corrected`` (the
    same with each row's seed deviations scaled by sqrt(S / (S - 1))) or ``t`` (value ±
    a t quantile with sum(S - 1) degrees of freedom times the corrected replicates' standard
    deviation). ``n``: the recordings. NaN bounds with fewer than two recordings."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    rows = _rows(rows)
    value = float(fn([float(np.mean(row_values(n, d))) for n, d in rows]))
    R = rows[0][0].shape[1]
    if R < 2:
        return Interval(value, float("nan"), float("nan"), R)
    reps = np.asarray(fn(_replicates(rows, n_resamples, np.random.default_rng(seed),
                                     correct=method != "percentile")), np.float64)
    reps = reps[np.isfinite(reps)]
    if reps.size < 2:
        return Interval(value, float("nan"), float("nan"), R)
    alpha = (1 - confidence) / 2
    if method == "t":
        from .._extras import require

        df = max(1, sum(n.shape[0] - 1 for n, _ in rows))
        half = require("scipy.stats", "seed and recording intervals").t.ppf(1 - alpha, df) \
            * float(np.std(reps, ddof=1))
        return Interval(value, value - half, value + half, R)
    low, high = np.quantile(reps, [alpha, 1 - alpha])
    return Interval(value, float(low), float(high), R)


def probability_of_improvement(a, b, better: int = 1, *, confidence: float = CONFIDENCE,
                               n_resamples: int = N_RESAMPLES, seed: int = SEED) -> Interval:
    """P(a run of row ``a`` beats a run of row ``b``): the share of (seed of a, seed of b)
    pairs where ``a``'s value is better (``better`` +1: higher, -1: lower), ties counting a
    half (the Mann-Whitney statistic rliable and Bouthillier et al. 2021 report), over the
    recordings given; its interval resamples seeds and recordings as above."""
    (na, da), (nb, db) = _rows([a, b])
    if better not in (1, -1):
        raise ValueError(f"better must be 1 (higher) or -1 (lower), got {better!r}")

    def p(va, vb):
        diff = better * (va[..., :, None] - vb[..., None, :])
        return ((diff > 0) + 0.5 * (diff == 0)).mean(axis=(-2, -1))

    value = float(p(row_values(na, da), row_values(nb, db)))
    R = na.shape[1]
    if R < 2:
        return Interval(value, float("nan"), float("nan"), R)
    _, vals = _per_seed([(na, da), (nb, db)], n_resamples, np.random.default_rng(seed))
    reps = p(vals[0], vals[1])
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
