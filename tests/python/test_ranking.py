"""Exact AUROC and average precision of the crossing class (bsp_fast.metrics.ranking): cases
computed by hand (ties included), agreement with torchmetrics' exact-threshold forms, the
streaming RankingMetrics giving the one-shot value bit for bit whatever the batches, and
clear errors."""
import numpy as np
import pytest

from bsp_fast.metrics import ranking as R

torch = pytest.importorskip("torch")


def test_hand_computed_values_with_ties():
    # crossing clips score 0.9, 0.8, 0.5; the others 0.8, 0.5, 0.2. Pairs (crossing,
    # other): 0.9 beats all three (3); 0.8 ties 0.8 and beats 0.5, 0.2 (2.5); 0.5 loses to
    # 0.8, ties 0.5, beats 0.2 (1.5) -> AUROC 7/9.
    # Thresholds, highest first: 0.9 -> P 1/1, R 1/3; 0.8 -> P 2/3, R 2/3; 0.5 -> P 3/5,
    # R 1; 0.2 adds no recall -> AP = (1 + 2/3 + 3/5) / 3 = 34/45.
    s = np.array([0.9, 0.8, 0.8, 0.5, 0.5, 0.2])
    y = np.array([1, 0, 1, 1, 0, 0])
    assert R.auroc(s, y) == pytest.approx(7 / 9, abs=1e-15)
    assert R.average_precision(s, y) == pytest.approx(34 / 45, abs=1e-15)
    # the clips' order changes nothing (tied clips swapped, everything reversed)
    for order in ([0, 2, 1, 4, 3, 5], [5, 4, 3, 2, 1, 0]):
        assert R.auroc(s[order], y[order]) == R.auroc(s, y)
        assert R.average_precision(s[order], y[order]) == R.average_precision(s, y)


def test_all_tied_perfect_and_reversed_scores():
    y = np.array([1, 0, 0, 1, 0])
    # one threshold: every pair a tie (AUROC 1/2), precision = crossing share 2/5 at recall 1
    assert R.auroc(np.full(5, 0.3), y) == 0.5
    assert R.average_precision(np.full(5, 0.3), y) == pytest.approx(0.4, abs=1e-15)
    perfect = np.where(y == 1, 0.9, 0.1)
    assert R.auroc(perfect, y) == 1.0 and R.average_precision(perfect, y) == 1.0
    assert R.auroc(1 - perfect, y) == 0.0
    # reversed: the crossing clips come last -> thresholds 0.9 (P 0/3), 0.1 (P 2/5, R 1)
    assert R.average_precision(1 - perfect, y) == pytest.approx(0.4, abs=1e-15)


def test_undefined_is_nan_and_bad_input_is_named():
    assert np.isnan(R.auroc([0.2, 0.3], [1, 1]))
    assert np.isnan(R.auroc([], []))
    assert np.isnan(R.average_precision([0.2, 0.3], [0, 0]))
    assert R.average_precision([0.2, 0.3], [0, 1]) == 1.0  # defined without negatives too
    with pytest.raises(ValueError, match="scores: .* got 1 NaN"):
        R.auroc([0.1, np.nan], [0, 1])
    with pytest.raises(ValueError, match="labels: .*labels outside"):
        R.average_precision([0.1, 0.2], [0, 2])
    with pytest.raises(ValueError, match="labels: .*N = 3"):
        R.auroc([0.1, 0.2, 0.3], [0, 1])
    with pytest.raises(ValueError, match="scores: .*shape"):
        R.auroc(np.zeros((3, 2)), [0, 1, 0])


def test_agrees_with_torchmetrics_exact_thresholds():
    from torchmetrics.classification import BinaryAUROC, BinaryAveragePrecision

    rng = np.random.default_rng(7)
    for n in (20, 333):
        s = np.round(rng.random(n), 2)  # many ties
        y = rng.integers(0, 2, n)
        st, yt = torch.tensor(s), torch.tensor(y)
        auc = BinaryAUROC(thresholds=None)(st, yt)
        ap = BinaryAveragePrecision(thresholds=None)(st, yt)
        # torchmetrics builds its curves in float32: equal to its precision
        assert R.auroc(s, y) == pytest.approx(float(auc), abs=1e-6)
        assert R.average_precision(s, y) == pytest.approx(float(ap), abs=1e-6)


def test_crossing_probability_of_one_and_two_logits():
    two = np.array([[0.0, 0.0], [0.0, np.log(3.0)], [2.0, 1.0]], np.float32)
    p = R.crossing_probability(torch.tensor(two))
    assert p.dtype == np.float64
    np.testing.assert_allclose(p, [0.5, 0.75, 1 / (1 + np.e)], rtol=1e-7)
    np.testing.assert_allclose(p, torch.softmax(torch.tensor(two, dtype=torch.float64),
                                                -1)[:, 1].numpy(), rtol=1e-7)
    assert R.crossing_probability(np.array([0.0, np.log(3.0)])).tolist() == \
        pytest.approx([0.5, 0.75])
    with pytest.raises(ValueError, match="output"):
        R.crossing_probability(np.zeros((2, 3), np.float32))
    with pytest.raises(ValueError, match="NaN"):
        R.crossing_probability(np.array([0.0, np.nan]))


def test_streaming_metric_is_the_one_shot_value_for_any_batching():
    from bsp_fast.metrics import RankingMetrics

    rng = np.random.default_rng(3)
    n = 101
    s = np.round(rng.random(n), 2)
    y = rng.integers(0, 2, n)
    tte = rng.integers(30, 62, n)
    rows = rng.permutation(n)
    want = {"auroc": R.auroc(s, y), "ap": R.average_precision(s, y)}
    for size in (1, 7, 64, n):
        m = RankingMetrics()
        for a in range(0, n, size):
            sl = slice(a, a + size)
            m.update(torch.tensor(s[sl]), torch.tensor(y[sl]), tte=torch.tensor(tte[sl]),
                     row=torch.tensor(rows[sl]))
        got = {k: float(v) for k, v in m.compute().items()}
        assert got == want  # bit for bit
        c = m.clips()  # ordered by row: clip i of the split is row i
        assert c["row"].tolist() == list(range(n))
        back = np.argsort(rows)
        assert c["score"].tolist() == s[back].tolist()
        assert c["tte"].tolist() == tte[back].tolist()
    m = RankingMetrics()
    m.update(torch.tensor([0.2, 0.4]), torch.tensor([0, 1]))  # no tte/row: -1
    assert m.clips()["tte"].tolist() == [-1, -1]
    with pytest.raises(ValueError, match="tte has 1 values for 2 scores"):
        m.update(torch.tensor([0.2, 0.4]), torch.tensor([0, 1]), tte=torch.tensor([3]))
