"""Intervals over seeds and recordings (#37, bsp_fast.metrics.hierarchical): known answers,
a hand-computed probability of improvement, and the coverage simulation's smoke run."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from bsp_fast.metrics import uncertainty as U
from bsp_fast.metrics.hierarchical import (probability_of_improvement, row_values,
                                           seed_recording_interval, simulate_coverage)

ROOT = Path(__file__).resolve().parents[2]


def _row(values, clips=30):
    """(num, den) of per-(seed, recording) mean values with ``clips`` clips each."""
    v = np.asarray(values, np.float64)
    den = np.full(v.shape, float(clips))
    return v * den, den


def test_row_values_are_ratios_of_sums():
    num, den = np.array([[1.0, 3.0], [2.0, 2.0]]), np.array([[2.0, 2.0], [1.0, 3.0]])
    np.testing.assert_allclose(row_values(num, den), [1.0, 1.0])


def test_ratios_from_per_seed_sections_align_the_recordings():
    from bsp_fast.metrics.hierarchical import Ratios

    # seed 0 scored recordings b and a, seed 1 a and c: columns a, b, c; 0 / 0 where a
    # seed has no clip of a recording
    s0 = {"recordings": ["b", "a"], "metrics": {"pck": {"num": [3, 1], "den": [4, 2]}}}
    s1 = {"recordings": ["a", "c"], "metrics": {"pck": {"num": [2, 5], "den": [2, 5]}}}
    r = Ratios.from_sections([s0, s1], "pck")
    np.testing.assert_array_equal(r.num, [[1, 3, 0], [2, 0, 5]])
    np.testing.assert_array_equal(r.den, [[2, 4, 0], [2, 0, 5]])
    np.testing.assert_allclose(row_values(r.num, r.den), [4 / 6, 7 / 7])
    with pytest.raises(ValueError, match="not in the per-recording sums"):
        Ratios.from_sections([s0], "f1")


def test_identical_rows_are_inconclusive():
    rng = np.random.default_rng(0)
    a = _row(0.5 + rng.normal(0, 0.05, (5, 20)))
    iv = seed_recording_interval([a, a], lambda v: v[1] - v[0])
    assert iv.value == 0.0 and iv.low <= 0 <= iv.high and U.mark(iv) == U.UNSURE


def test_seeds_that_disagree_wildly_are_inconclusive_where_recordings_alone_are_not():
    rng = np.random.default_rng(1)
    base = 0.5 + rng.normal(0, 0.002, 20)  # recordings barely differ
    a = _row(base + np.array([[-0.2], [0.0], [0.25], [-0.1], [0.1]]))
    b = _row(base + 0.03 + np.array([[0.3], [-0.25], [0.0], [0.2], [-0.15]]))
    two = seed_recording_interval([a, b], lambda v: v[1] - v[0])
    assert U.mark(two) == U.UNSURE and two.high - two.low > 0.2
    # the seeds held fixed (recordings resampled only): a tight, overconfident interval
    one = U.paired_interval([(a[0].sum(0), a[1].sum(0)), (b[0].sum(0), b[1].sum(0))],
                            lambda v: v[1] - v[0])
    assert U.mark(one) == U.YES


def test_a_large_constant_shift_is_reproduced():
    rng = np.random.default_rng(2)
    a = _row(0.5 + rng.normal(0, 0.02, (5, 20)))
    b = _row(np.asarray(a[0] / a[1]) + 0.2)
    for method in ("percentile", "corrected", "t"):
        iv = seed_recording_interval([a, b], lambda v: v[1] - v[0], method=method)
        assert iv.value == pytest.approx(0.2) and U.mark(iv) == U.YES, method


def test_probability_of_improvement_by_hand():
    # seeds of a: 1, 2, 3; of b: 0, 2, 4 (one recording each, one clip): of the 9 pairs
    # a wins (1,0) (2,0) (3,0) (3,2), ties (2,2): (4 + 0.5) / 9
    a, b = _row([[1.0], [2.0], [3.0]], 1), _row([[0.0], [2.0], [4.0]], 1)
    assert probability_of_improvement(a, b).value == pytest.approx(0.5)
    assert probability_of_improvement(a, b, better=-1).value == pytest.approx(0.5)
    c = _row([[5.0, 5.0], [6.0, 6.0]])
    d = _row([[1.0, 1.0], [2.0, 2.0]])
    iv = probability_of_improvement(c, d)
    assert iv.value == 1.0 and iv.low == 1.0
    assert probability_of_improvement(c, d, better=-1).value == 0.0


def test_rows_must_share_their_recordings():
    with pytest.raises(ValueError, match="aligned on the same recordings"):
        seed_recording_interval([_row(np.ones((2, 3))), _row(np.ones((2, 4)))])
    with pytest.raises(ValueError, match="method must be one of"):
        seed_recording_interval([_row(np.ones((2, 3)))], method="bca")


def test_coverage_simulation_sees_what_fixed_seeds_miss():
    """Seed variance three times the recordings': the recordings-only interval covers a
    true difference of 0 rarely, the two-level one far more often (the full grid with 1000
    simulations: experiments/coverage_simulation.py, docs/reproduce.md)."""
    r = simulate_coverage(seeds=5, recordings=20, seed_sd=0.03, recording_sd=0.01, sims=60,
                          n_resamples=200, method="t")
    assert r["coverage_recordings_only"] < 0.5 < 0.85 < r["coverage_seeds_and_recordings"]
    assert r["width_seeds_and_recordings"] > 3 * r["width_recordings_only"]


def test_coverage_experiment_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "coverage_simulation", ROOT / "experiments" / "coverage_simulation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    argv = ["--out", str(tmp_path), "--sims", "10", "--resamples", "50", "--seeds", "3",
            "--deltas", "0", "--methods", "t"]
    assert mod.main(argv) == 0
    rows = json.loads((tmp_path / "coverage.json").read_text())["rows"]
    assert len(rows) == 3 and {r["method"] for r in rows} == {"t"}
    assert "| t | 3 | 20 |" in (tmp_path / "coverage.md").read_text()
    assert mod.main(argv + ["--resume"]) == 0  # nothing left to do: the rows are kept
    assert len(json.loads((tmp_path / "coverage.json").read_text())["rows"]) == 3


def test_a_dominant_mean_square_bounds_the_degrees_of_freedom():
    from bsp_fast.metrics.hierarchical import bounded_df, satterthwaite

    # seed term 0.8 of the variance on 2 df beside a recording term on 199 df:
    # Satterthwaite says 1 / (0.8^2 / 2 + 0.2^2 / 199) = 3.12 df; the bound keeps 2
    terms = [(1.0, 0.8, 2, "seed"), (1.0, 0.2, 199, "recording")]
    assert satterthwaite(terms)[1] == pytest.approx(1 / (0.64 / 2 + 0.04 / 199))
    assert bounded_df(terms) == (pytest.approx(1.0), 2.0)
    # no term carries half: Satterthwaite's df unchanged (0.4 on 4 df, 0.6 split in two)
    terms = [(1.0, 0.4, 4, "seed"), (1.0, 0.3, 19, "recording"), (1.0, 0.3, 19, "other")]
    assert bounded_df(terms) == satterthwaite(terms)
    # the share is of the whole variance, a negative interaction term included
    terms = [(1.0, 0.5, 4, "seed"), (1.0, 0.6, 19, "recording"),
             (-1.0, 0.1, 76, "interaction")]
    assert bounded_df(terms)[1] == 4.0
