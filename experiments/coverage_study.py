#!/usr/bin/env python3
"""Does the tables' interval cover what it claims, where the tables live (#56)?

Simulated per-seed x per-recording sums with known answers are fed to
``bsp_fast.metrics.hierarchical.variance_components`` exactly as ``reproduction/evidence.py``
calls it (a cell: one row, its interval inside the metric's range; a difference: two rows
on the same recordings, paired on their seed numbers). Grid: seeds S in {3, 5, 10}, test
recordings R in {10, 20, 43, 200}; variance regimes seed-dominant, balanced and
recording-dominant (sd of the seed, recording and seed x recording effects: 0.03/0.01/0.01,
0.02/0.02/0.01, 0.01/0.03/0.01 on a 0-1 scale); two metrics:

* ``mean``: a mean per clip (PCK-like, 0.6), 5-60 clips per recording (unequal), a clip's
  noise sd 0.1; the answer is 0.6 (a difference: 0.02).
* ``f1``: F1 from binomial counts, one label per recording (45 % crossing recordings),
  5-60 clips each; a seed's rate of saying "crossing" is ``expit(2.2 + a_s + b_r + e_sr)``
  on crossing recordings and ``expit(-2.2 - a_s + b_r + e_sr)`` on the others, the effects
  10x the regime's sd on the logit; the answer is the mean over seeds of the F1 over
  infinitely many recordings (Gauss-Hermite quadrature); a difference: rows at 2.2 and 1.8.

The rows of a difference share half their recording effects (the recording level does not
cancel) and half their seed effects (same seed numbers). Variants: ``unequal seeds`` (one
row carries all the seed variance, twice the regime's sd, the other none); ``collapse``
(F1 cells whose seeds each predict "not crossing" on every clip with probability 0.2, as
PedestrianGraph's batch-64 seeds do; the answer is the mixture's mean). Rule (as the
tables): a row with some but not all seeds predicting one class on >= 95 % of clips is
inconclusive; the coverage is of the tables the method is used on, with the share marked
inconclusive beside it. Target 93-97 % (1,000 tables a cell: Monte Carlo sd 0.7 p.p.).

    python experiments/coverage_study.py --out docs/results [--sims 1000] [--resume]

writes ``coverage_study.json`` and ``coverage_study.md`` as each cell finishes.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REGIMES = {"seed-dominant": (0.03, 0.01, 0.01), "balanced": (0.02, 0.02, 0.01),
           "recording-dominant": (0.01, 0.03, 0.01)}
SEEDS, RECORDINGS = (3, 5, 10), (10, 20, 43, 200)
CLIPS, CLIP_SD, MEAN, DELTA = (5, 60), 0.1, 0.6, 0.02
CROSSING, LOGIT, LOGIT_SCALE = 0.45, (2.2, 1.8), 10.0
SHARE = 0.5  # the share of seed and of recording variance two rows of a difference share
COLLAPSE = 0.2
TARGET = (0.93, 0.97)


def _effects(rng, n, sds, shared=SHARE):
    """(rows, n) effects, one row per sd: correlation ``shared`` between rows (where both
    vary)."""
    common = rng.normal(0, 1, n)
    own = rng.normal(0, 1, (len(sds), n))
    return np.asarray(sds)[:, None] * (np.sqrt(shared) * common + np.sqrt(1 - shared) * own)


def _seed_sds(regime, rows, variant):
    s = REGIMES[regime][0]
    if variant == "unequal seeds":
        return [0.0, 2 * s][:rows]
    return [s] * rows


def mean_rows(rng, S, R, regime, rows, variant=""):
    """``[(num, den)]`` of ``rows`` rows of a clip-mean metric, and the true value of the
    cell (one row) or of row 1 - row 0."""
    _, rec_sd, int_sd = REGIMES[regime]
    a = _effects(rng, S, _seed_sds(regime, rows, variant))  # (rows, S)
    b = _effects(rng, R, [rec_sd] * rows)
    den = np.broadcast_to(rng.integers(CLIPS[0], CLIPS[1] + 1, R).astype(float), (S, R))
    out = []
    for k in range(rows):
        mean = (MEAN + k * DELTA + a[k][:, None] + b[k][None, :]
                + rng.normal(0, int_sd, (S, R)) + rng.normal(0, CLIP_SD, (S, R)) / np.sqrt(den))
        out.append((mean * den, den.copy()))
    return out, (MEAN if rows == 1 else DELTA)


def _expit(x):
    return 1 / (1 + np.exp(-x))


def f1_truth(mu: float, regime: str, sd_seed: float, collapse: float = 0.0) -> float:
    """The mean over seeds of a seed's F1 over infinitely many recordings."""
    _, rec_sd, int_sd = (LOGIT_SCALE * x for x in REGIMES[regime])
    x, w = np.polynomial.hermite_e.hermegauss(60)
    w = w / w.sum()
    u = np.sqrt(rec_sd ** 2 + int_sd ** 2) * x  # recording + interaction, one normal
    seeds = LOGIT_SCALE * sd_seed * x if sd_seed > 0 else np.zeros(1)
    ws = w if sd_seed > 0 else np.ones(1)
    f1 = []
    for a in seeds:
        tp = CROSSING * np.sum(w * _expit(mu + a + u))
        fp = (1 - CROSSING) * np.sum(w * _expit(-mu - a + u))
        f1.append(2 * tp / (2 * tp + fp + (CROSSING - tp)))
    return (1 - collapse) * float(np.sum(ws * np.asarray(f1)))


def f1_rows(rng, S, R, regime, rows, variant=""):
    """``[(num, den)]`` of F1 (2 TP, 2 TP + FP + FN) per seed and recording, the predicted
    positive share of each row's seeds, and the true value."""
    _, rec_sd, int_sd = (LOGIT_SCALE * x for x in REGIMES[regime])
    sds = _seed_sds(regime, rows, variant)
    a = _effects(rng, S, [LOGIT_SCALE * s for s in sds])
    b = _effects(rng, R, [rec_sd] * rows)
    n = rng.integers(CLIPS[0], CLIPS[1] + 1, R)
    crossing = rng.random(R) < CROSSING
    out, shares = [], []
    for k in range(rows):
        sign = np.where(crossing, 1.0, -1.0)[None, :]
        rate = _expit(sign * (LOGIT[k] + a[k][:, None]) + b[k][None, :]
                      + rng.normal(0, int_sd, (S, R)))
        said = rng.binomial(np.broadcast_to(n, (S, R)), rate).astype(float)
        if variant == "collapse":
            said[rng.random(S) < COLLAPSE] = 0.0  # "not crossing" on every clip
        tp = np.where(crossing, said, 0.0)
        fp = np.where(crossing, 0.0, said)
        fn = np.where(crossing, n - said, 0.0)
        out.append((2 * tp, 2 * tp + fp + fn))
        shares.append(said.sum(1) / n.sum())
    truth = [f1_truth(LOGIT[k], regime, sds[k], COLLAPSE if variant == "collapse" else 0)
             for k in range(rows)]
    if variant == "collapse":  # also the answer of the seeds' main mode (no collapse)
        truth = [(t, f1_truth(LOGIT[k], regime, sds[k])) for k, t in enumerate(truth)]
    return out, shares, (truth[0] if rows == 1 else truth[1] - truth[0])


def split_modes(shares, limit: float = 0.95) -> bool:
    """The tables' rule: some but not all seeds of a row predict one class on >= limit of
    their clips."""
    for s in shares:
        one = np.maximum(s, 1 - s) >= limit
        if one.any() and not one.all():
            return True
    return False


def one_table(rng, cell: dict, levels: str = "both"):
    """``(covered, width, df, covered_mode)`` of one simulated table (``covered_mode``: of
    the main mode's answer, ``collapse`` only), or None when inconclusive by rule."""
    from bsp_fast.metrics.hierarchical import variance_components

    rows = 1 if cell["target"] == "cell" else 2
    if cell["metric"] == "mean":
        data, truth = mean_rows(rng, cell["seeds"], cell["recordings"], cell["regime"], rows,
                                cell["variant"])
    else:
        data, shares, truth = f1_rows(rng, cell["seeds"], cell["recordings"], cell["regime"],
                                      rows, cell["variant"])
        if split_modes(shares):
            return None
    fn = (lambda v: v[0]) if rows == 1 else (lambda v: v[1] - v[0])
    t = variance_components(data, fn, seed_keys=[0] * rows, levels=levels,
                            support=(0.0, 1.0) if rows == 1 else None)
    if not np.isfinite(t.p):  # no variance: inconclusive by rule (ZERO_SE)
        return None
    truth, mode = truth if isinstance(truth, tuple) else (truth, None)
    return (t.low <= truth <= t.high, t.high - t.low, t.df,
            None if mode is None else t.low <= mode <= t.high)


def run_cell(cell: dict, sims: int, seed: int = 0, levels: str = "both") -> dict:
    rng = np.random.default_rng([seed, cell["seeds"], cell["recordings"],
                                 list(REGIMES).index(cell["regime"]),
                                 ["mean", "f1"].index(cell["metric"]),
                                 ["cell", "difference"].index(cell["target"]),
                                 ["", "unequal seeds", "collapse"].index(cell["variant"])])
    got = [one_table(rng, cell, levels) for _ in range(sims)]
    used = [g for g in got if g is not None]
    cov = float(np.mean([g[0] for g in used])) if used else float("nan")
    return dict(cell, levels=levels, sims=sims, used=len(used),
                inconclusive=1 - len(used) / sims, coverage=cov,
                width=float(np.mean([g[1] for g in used])) if used else float("nan"),
                df=float(np.median([g[2] for g in used])) if used else float("nan"),
                coverage_main_mode=float(np.mean([g[3] for g in used]))
                if used and used[0][3] is not None else None)


def grid() -> list:
    cells = [{"metric": m, "target": t, "regime": g, "seeds": S, "recordings": R,
              "variant": ""} for m in ("mean", "f1") for t in ("cell", "difference")
             for g in REGIMES for S in SEEDS for R in RECORDINGS]
    cells += [{"metric": m, "target": "difference", "regime": "balanced", "seeds": S,
               "recordings": R, "variant": "unequal seeds"} for m in ("mean", "f1")
              for S in SEEDS for R in RECORDINGS]
    cells += [{"metric": "f1", "target": "cell", "regime": "balanced", "seeds": S,
               "recordings": R, "variant": "collapse"} for S in SEEDS for R in RECORDINGS]
    return cells


def verdict(r: dict) -> str:
    """``in target``, ``under`` or ``over``; a collapse cell's names the rule that marks
    the tables where a collapse is seen (the others cannot show a mode no seed showed)."""
    if r["used"] == 0:
        return "all inconclusive by rule"
    lo, hi = TARGET
    if lo <= r["coverage"] <= hi:
        return "in target"
    out = "under" if r["coverage"] < lo else "over"
    if r["variant"] == "collapse":
        out += " (rule: seeds in two modes, where a collapse is seen)"
    return out


def markdown(rows: list) -> str:
    out = ["| metric | target | variance | variant | S | R | nominal | measured | "
           "inconclusive by rule | median df | mean width | verdict |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['metric']} | {r['target']} | {r['regime']} | {r['variant'] or '–'} "
                   f"| {r['seeds']} | {r['recordings']} | 95 % | "
                   f"{100 * r['coverage']:.1f} % | {100 * r['inconclusive']:.1f} % | "
                   f"{r['df']:.1f} | {r['width']:.4f} | {verdict(r)}"
                   + (f" (main mode covered {100 * r['coverage_main_mode']:.1f} %)"
                      if r.get("coverage_main_mode") is not None else "") + " |")
    return "\n".join(out)


def _key(r: dict) -> tuple:
    return (r["metric"], r["target"], r["regime"], r["variant"], r["seeds"], r["recordings"])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--sims", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resume", action="store_true")
    p.add_argument("--only", nargs="*", default=None,
                   help="metric/target pairs to run, e.g. mean/cell f1/difference")
    args = p.parse_args(argv)
    from bsp_fast.atomic import write_text

    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "coverage_study.json"
    rows = json.loads(path.read_text())["rows"] if args.resume and path.exists() else []
    done = {_key(r) for r in rows}
    t0 = time.perf_counter()
    for cell in grid():
        if _key(cell) in done or (args.only and f"{cell['metric']}/{cell['target']}"
                                  not in args.only):
            continue
        rows.append(run_cell(cell, args.sims, args.seed))
        doc = {"command": "python3 experiments/coverage_study.py " + " ".join(
            a if not Path(a).is_absolute() else Path(a).name for a in (argv or sys.argv[1:])),
            "method": "variance_components (bsp_fast.metrics.hierarchical): Satterthwaite "
                      "df bounded by a dominant mean square's (bounded_df)",
            "target": list(TARGET), "rows": rows,
            "seconds": round(time.perf_counter() - t0, 1)}
        write_text(path, json.dumps(doc, indent=1) + "\n")
        write_text(args.out / "coverage_study.md", markdown(rows) + "\n")
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
