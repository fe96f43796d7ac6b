"""models/dropout.py: the CPU dropout mask drawn from numpy's PCG64 bits."""
from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from bsp_fast import models
from bsp_fast.models.dropout import Dropout, keep_mask, replace_dropout


@pytest.mark.parametrize("p", [0.5, 0.1, 0.3, 0.9])
def test_keep_rate_and_scale(p):
    torch.manual_seed(3)
    n = 1 << 20
    keep, scale = keep_mask((n,), p)
    assert keep.dtype == torch.bool and keep.shape == (n,)
    rate = keep.double().mean().item()
    # 6 binomial standard deviations around 1 - p
    assert abs(rate - (1 - p)) < 6 * math.sqrt(p * (1 - p) / n)
    # the expectation is kept exactly: scale x P(keep) = 1 for the quantised P(keep)
    bits = 16 if float(p * 65536).is_integer() else 32
    p_keep = 1 - round(p * 2 ** bits) / 2 ** bits
    assert scale * p_keep == pytest.approx(1.0, abs=1e-15)
    assert abs(p_keep - (1 - p)) <= 2.0 ** -(bits + 1)
    if p == 0.5:
        assert scale == 2.0


def test_values_kept_scaled_or_zero_and_gradient_is_the_mask():
    torch.manual_seed(0)
    x = torch.randn(64, 16, 26, 8, requires_grad=True)
    d = Dropout(0.25).train()
    y = d(x)
    kept = y != 0
    scale = torch.tensor(1 / 0.75)  # float32, as the mask holds it
    torch.testing.assert_close(y[kept], x[kept] * scale, rtol=0, atol=0)
    y.sum().backward()
    want = kept.float() * scale
    torch.testing.assert_close(x.grad, want, rtol=0, atol=0)
    # the mask differs from call to call, roughly a quarter dropped
    y2 = d(x)
    assert not torch.equal(y2 != 0, kept)
    assert abs((y2 == 0).float().mean().item() - 0.25) < 0.01


def test_a_function_of_torchs_seed_whatever_the_thread_count():
    x = torch.randn(32, 100)
    outs = []
    for threads in (1, 2):
        old = torch.get_num_threads()
        torch.set_num_threads(threads)
        try:
            torch.manual_seed(7)
            outs.append(Dropout(0.5).train()(x))
        finally:
            torch.set_num_threads(old)
    assert torch.equal(outs[0], outs[1])
    torch.manual_seed(8)
    assert not torch.equal(Dropout(0.5).train()(x), outs[0])


def test_identity_in_eval_and_at_p_zero_and_bf16():
    x = torch.randn(4, 5)
    assert torch.equal(Dropout(0.5).eval()(x), x)
    assert torch.equal(Dropout(0.0).train()(x), x)
    xb = x.bfloat16()
    y = Dropout(0.5).train()(xb)
    assert y.dtype == torch.bfloat16
    assert torch.equal(y[y != 0], (xb * 2)[y != 0])
    # a scale bf16 cannot hold (1 / 0.9) is applied as torch's scalar product applies it,
    # not rounded to bf16 first (1.109: a 0.16 % bias)
    xb = torch.randn(10_000).bfloat16()
    y = Dropout(0.1).train()(xb)
    kept = y != 0
    assert y.dtype == torch.bfloat16
    assert torch.equal(y[kept], xb[kept] * (1 / 0.9))
    ratio = (y[kept].double() / xb[kept].double()).mean().item()
    assert ratio == pytest.approx(1 / 0.9, rel=5e-4)  # the rounded scale: 1.6e-3 off


def test_inplace_like_nn_dropout():
    torch.manual_seed(1)
    x = torch.randn(1000)
    ref = x.clone()
    y = Dropout(0.5, inplace=True).train()(x)
    assert y.data_ptr() == x.data_ptr()
    assert torch.equal(y[y != 0], ref[y != 0] * 2)


def test_replace_dropout_and_the_models_use_it():
    enc = nn.TransformerEncoder(nn.TransformerEncoderLayer(8, 2, 16, 0.1, batch_first=True),
                                2, enable_nested_tensor=False)
    replace_dropout(enc)
    drops = [m for m in enc.modules() if isinstance(m, nn.Dropout)]
    assert drops and all(type(m) is Dropout and m.p == 0.1 for m in drops)
    for task, name in (("classification", "pedestrian_graph"), ("autoencoder", "simple_transformer"),
                       ("lifting", "baseline_3d"), ("lifting", "poseformer")):
        net = models.create(task, name)
        assert not [m for m in net.modules() if type(m) is nn.Dropout], name
        # no state of its own: checkpoints from before load unchanged
        assert not [k for k in net.state_dict() if "drop" in k], name


def test_training_step_reproducible_for_a_seed():
    """PedestrianGraph trained two steps from one seed twice: identical weights; another
    seed: other dropout masks, other weights."""
    a, b, c = _two_steps(5), _two_steps(5), _two_steps(6)
    assert all(torch.equal(u, v) for u, v in zip(a, b))
    assert not all(torch.equal(u, v) for u, v in zip(a, c))


def _two_steps(seed: int) -> list:
    torch.manual_seed(seed)
    net = models.create("classification", "pedestrian_graph").train()
    opt = torch.optim.AdamW(net.parameters(), lr=1e-2)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(8, 16, 26, 2, generator=g)
    t = torch.randint(0, 2, (8,), generator=g)
    for _ in range(2):
        loss = net.loss(net(x), {"targets": t})
        opt.zero_grad()
        loss.backward()
        opt.step()
    return [p.detach().clone() for p in net.parameters()]


def test_bench_dropout_smoke(capsys, monkeypatch, tmp_path):
    """benchmarks/bench_dropout.py on PedestrianGraph, two rounds of two steps: its three
    variants, the old GCN layout computing the same layer as the new one."""
    import importlib
    import json
    import types
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    bench = importlib.import_module("bench_dropout")
    out = tmp_path / "rows.jsonl"
    assert bench.main(["--models", "classification/pedestrian_graph", "--rounds", "2",
                       "--steps", "2", "--json", str(out)]) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["variant"] for r in rows] == ["nn.Dropout + permuted GCN", "nn.Dropout", "bsp"]
    assert all(r["step_cpu_s"] > 0 for r in rows) and rows[1]["vs_nn_dropout"] == 1.0
    assert "| classification/pedestrian_graph | 64 | bsp |" in capsys.readouterr().out
    # the benchmark's "before" layer is the same function as the model's
    torch.manual_seed(0)
    net = models.create("classification", "pedestrian_graph").eval()
    x = torch.randn(3, 5, 26, 2)
    with torch.no_grad():
        new = net(x)
        for conv in (net.conv1, net.conv2):
            conv.forward = types.MethodType(bench._permuted_gcn, conv)
        torch.testing.assert_close(net(x), new, rtol=1e-5, atol=1e-6)
    # and the variant really swaps torch's dropout back in
    swapped = bench._variant(models.create("classification", "pedestrian_graph"), "nn.Dropout")
    assert type(swapped.dropout) is nn.Dropout
