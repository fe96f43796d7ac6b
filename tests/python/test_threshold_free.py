"""Threshold-free metrics (AUROC, AP, PCK-AUC) and model cost (parameters, FLOPs), on
cases computed by hand."""
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from bsp_fast.metrics import threshold_free as T  # noqa: E402


def test_auroc_and_ap_by_hand():
    # positives score 0.35 and 0.8, negatives 0.1 and 0.4: of the 4 (pos, neg) pairs, 3 are
    # ordered right -> AUROC 3/4. Ranked: 0.8 (+, P=1, R=1/2), 0.4 (-), 0.35 (+, P=2/3,
    # R=1) -> AP = 1/2 * 1 + 1/2 * 2/3 = 5/6.
    s, t = np.array([0.1, 0.4, 0.35, 0.8]), np.array([0, 0, 1, 1])
    assert T.auroc(s, t) == pytest.approx(0.75)
    assert T.average_precision(s, t) == pytest.approx(5 / 6)


def test_ties_count_half_and_two_logits_rank_by_difference():
    # (N, 2) logits: the score is logit_1 - logit_0 = [0, 1, 1, 2]; one positive ties a
    # negative at 1 -> pairs: (1 vs 0) ok, (1 vs 1) half, (2 vs 0) ok, (2 vs 1) ok = 3.5/4
    logits = torch.tensor([[0.0, 0.0], [0.0, 1.0], [1.0, 2.0], [-1.0, 1.0]])
    t = torch.tensor([0, 0, 1, 1])
    assert T.auroc(logits, t) == pytest.approx(3.5 / 4)


def test_single_class_is_nan_and_bad_input_is_named():
    assert np.isnan(T.auroc([0.2, 0.3], [1, 1]))
    assert np.isnan(T.average_precision([0.2, 0.3], [0, 0]))
    with pytest.raises(ValueError, match="pred"):
        T.auroc(np.zeros((3, 3)), [0, 1, 0])
    with pytest.raises(ValueError, match="labels outside"):
        T.auroc([0.1, 0.2], [0, 2])


def _poses(err_px):
    """One frame: ground truth on a 100 px square's diagonal (bbox diagonal 100*sqrt(2)),
    each joint's prediction err_px[j] px to the right."""
    gt = np.zeros((26, 2))
    gt[:, 0] = np.linspace(10, 110, 26)
    gt[:, 1] = np.linspace(10, 110, 26)
    pred = gt.copy()
    pred[:, 0] += err_px
    return pred, gt


def test_pck_curve_and_auc_by_hand():
    S = 100 * np.sqrt(2)
    err = np.zeros(26)
    err[:13] = 0.1 * S  # half the joints 0.1 S away, half exact
    pred, gt = _poses(err)
    alphas = [0.0, 0.05, 0.1, 0.15, 0.2]
    curve = T.pck_curve(pred, gt, alphas=alphas)
    np.testing.assert_allclose(curve, [0.5, 0.5, 1.0, 1.0, 1.0])
    # trapezoids: 0.05*(0.5+0.5)/2 + 0.05*(0.5+1)/2 + 0.05*1 + 0.05*1 = 0.1625 -> / 0.2
    assert T.pck_auc(pred, gt, alphas=alphas) == pytest.approx(0.1625 / 0.2)
    exact, _ = _poses(np.zeros(26))
    assert T.pck_auc(exact, gt) == pytest.approx(1.0)
    far, _ = _poses(np.full(26, 0.3 * S))
    assert T.pck_auc(far, gt) == pytest.approx(0.0)
    with pytest.raises(ValueError, match="alphas"):
        T.pck_auc(pred, gt, alphas=[0.1, 0.05])


def test_parameter_and_flop_counts_by_hand():
    from bsp_fast.models import create
    from bsp_fast.models.cost import flops_per_clip, parameter_count

    lin = torch.nn.Linear(10, 5)
    assert parameter_count(lin) == 55
    assert flops_per_clip(lin, {"inputs": torch.zeros(4, 10)}) == 2 * 10 * 5
    # 3DPoseBaseline per frame: 52->1024, 4 x 1024->1024, 1024->78 (BN/ReLU not counted)
    net = create("lifting", "baseline_3d")
    L = 16
    batch = {"inputs": torch.zeros(3, L, 26, 2), "visible": torch.ones(3, L, 26, dtype=bool)}
    per_frame = 2 * (52 * 1024 + 4 * 1024 * 1024 + 1024 * 78)
    assert flops_per_clip(net, batch) == per_frame * L
    assert net.training  # mode restored


def test_auroc_and_ap_are_exact_in_float64():
    # positives ranked 1st, 4th and 8th of 10 (scores falling): they beat 7, 5 and 2 of
    # the 7 negatives -> AUROC 14/21; AP = (1/1 + 2/4 + 3/8) / 3 = 0.625. A float32
    # curve (torchmetrics) is off by ~1e-8 on such fractions.
    s = np.array([0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.05])
    t = np.array([1, 0, 0, 1, 0, 0, 0, 1, 0, 0])
    assert T.auroc(s, t) == 14 / 21
    assert T.average_precision(s, t) == pytest.approx(0.625, rel=1e-15)
    # tied thresholds: one positive and one negative share 0.5 -> half a pair each way
    s2, t2 = np.array([0.5, 0.5, 0.2, 0.9]), np.array([1, 0, 0, 1])
    assert T.auroc(s2, t2) == 3.5 / 4
    # AP over distinct thresholds: 0.9 (1/1, recall 1/2), 0.5 (2/3, recall 1)
    assert T.average_precision(s2, t2) == pytest.approx(0.5 * 1 + 0.5 * 2 / 3, rel=1e-15)


def test_flops_of_lstms_and_transformers_are_counted():
    # the fused LSTM kernel and the transformer's inference fast path are invisible to
    # FlopCounterMode (both counted 0 before): products from the shapes, by hand
    from bsp_fast.models.cost import flops_per_clip

    lstm = torch.nn.LSTM(10, 20, num_layers=2, batch_first=True)
    B, T = 3, 7
    per_step = 2 * 4 * 20 * (10 + 20) + 2 * 4 * 20 * (20 + 20)
    assert flops_per_clip(lstm, {"inputs": torch.zeros(B, T, 10)}) == T * per_step
    bi = torch.nn.LSTM(10, 20, batch_first=True, bidirectional=True)
    assert flops_per_clip(bi, {"inputs": torch.zeros(B, T, 10)}) == T * 2 * 2 * 4 * 20 * 30
    layer = torch.nn.TransformerEncoderLayer(16, 2, 32, batch_first=True)
    enc = torch.nn.TransformerEncoder(layer, 1, enable_nested_tensor=False)
    S = 5
    # q,k,v and out projections 4 x 16x16, scores and weighted sum 2 x S x 16, FFN 16x32x2
    per_token = 2 * (4 * 16 * 16 + 2 * S * 16 + 2 * 16 * 32)
    assert flops_per_clip(enc, {"inputs": torch.zeros(2, S, 16)}) == S * per_token
    assert torch.backends.mha.get_fastpath_enabled()  # restored
