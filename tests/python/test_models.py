"""bsp_fast.models: registry, shapes, parameter counts, determinism, gradients, options."""
import numpy as np
import pytest
import torch

from bsp_fast import models, skeleton as sk
from bsp_fast.models.graph import skeleton_adjacency

torch.set_num_threads(1)

ALL = [(t, n) for t in models.TASKS for n in models.available(t)]
CONTEXT = {"lstm_relative_rot": ("age", "gender")}
# widths that keep the batch-64 shape checks quick (same code paths as the defaults)
SMALL = {"poseformer": dict(embed_dim_ratio=8, depth=1),
         "pose_cnn": dict(width=8, hidden=16), "baseline_3d": dict(linear_size=64),
         "pose_temporal": dict(width=4),
         "simple_transformer": dict(dim_feedforward=64),
         "simple_transformer_pe": dict(dim_feedforward=64)}


def make_inputs(task, B, L, S=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    if task == "pose_estimation":
        x = torch.randint(0, 256, (B, L, 3, S, S), generator=g, dtype=torch.uint8)
    else:
        x = torch.randn(B, L, 26, 2, generator=g)
    visible = torch.rand(B, L, 26, generator=g) > 0.2
    return x, visible


def context(name, B):
    if name not in CONTEXT:
        return {}
    return {"age": ["adult", "child"] * (B // 2) + ["adult"] * (B % 2),
            "gender": ["female", "male", "male", "female"] * (B // 4) + ["male"] * (B % 4)}


def expected_shape(task, model, B, L):
    if task == "classification":
        return (B, 2) if model.name == "lstm" else (B,)
    s = model.frame_slice(L)
    return (B, s.stop - s.start, 26, 3 if task == "lifting" else 2)


def test_registry_lists_every_model():
    assert set(models.available("classification")) == {"lstm", "pedestrian_graph"}
    assert set(models.available("autoencoder")) == {"simple_transformer", "simple_transformer_pe"}
    assert set(models.available("lifting")) == {"baseline_3d", "lstm", "poseformer",
                                                "lstm_relative_rot"}
    assert set(models.available("pose_estimation")) == {"pose_cnn", "pose_temporal"}
    assert len(models.available()) == 10 and "lifting/poseformer" in models.available()


def test_bad_names_and_hparams_raise_listing_what_is_allowed():
    with pytest.raises(ValueError, match=r"allowed tasks: \['classification'"):
        models.create("segmentation", "lstm")
    with pytest.raises(ValueError, match=r"allowed: \['lstm', 'pedestrian_graph'\]"):
        models.create("classification", "resnet")
    with pytest.raises(ValueError, match=r"allowed: \['dim_feedforward', 'dropout', 'nhead'"):
        models.create("autoencoder", "simple_transformer", heads=2)
    with pytest.raises(ValueError, match=r"nhead must divide d_model 52: one of \[1, 2, 4, 13, "
                                         r"26, 52\], got 3"):
        models.create("autoencoder", "simple_transformer", nhead=3)
    with pytest.raises(ValueError, match="num_heads must divide embed_dim_ratio 32"):
        models.create("lifting", "poseformer", num_heads=5)
    with pytest.raises(ValueError, match="receptive_field must be odd"):
        models.create("lifting", "poseformer", receptive_field=8)
    with pytest.raises(ValueError, match=r"head must be one of \['regression', 'heatmap'\]"):
        models.create("pose_estimation", "pose_cnn", head="argmax")
    with pytest.raises(ValueError, match="dropout must be a number in"):
        models.create("lifting", "baseline_3d", dropout=1.5)
    with pytest.raises(ValueError, match="use_visible must be True or False"):
        models.create("classification", "lstm", use_visible="yes")


@pytest.mark.parametrize("task,name", ALL)
def test_hparams_round_trip(task, name):
    m = models.create(task, name, **SMALL.get(name, {}))
    assert m.task == task and m.name == name
    defaults = models.hparams_of(task, name)
    assert set(m.hparams) == set(defaults)
    assert {**defaults, **SMALL.get(name, {})} == m.hparams
    again = models.create(task, name, **m.hparams)
    assert {k: v.shape for k, v in again.state_dict().items()} == \
           {k: v.shape for k, v in m.state_dict().items()}


def lstm_params(inp, hidden, layers):
    n = 0
    for k in range(layers):
        n += 4 * hidden * ((inp if k == 0 else hidden) + hidden) + 8 * hidden
    return n


def block_params(d, mlp_ratio=2):  # pre-norm block: 2 LayerNorms, qkv, proj, MLP
    h = int(d * mlp_ratio)
    return 4 * d + (3 * d * d + 3 * d) + (d * d + d) + (d * h + h) + (h * d + d)


PARAMS = {
    ("classification", "lstm"): lstm_params(52, 64, 2) + 64 * 2 + 2,
    ("classification", "pedestrian_graph"): (2 * 64 + 64) + (64 * 32 + 32) + 26 + 1,
    # per layer: in_proj 52x156+156, out_proj 52x52+52, FF 52x2048+2048 and 2048x52+52,
    # two LayerNorms: 6 layers = 1,357,944 (the report's ~1.36 M)
    ("autoencoder", "simple_transformer"): 6 * (52 * 156 + 156 + 52 * 52 + 52 + 52 * 2048 + 2048
                                                + 2048 * 52 + 52 + 4 * 52),
    ("autoencoder", "simple_transformer_pe"): 1_357_944,
    ("lifting", "baseline_3d"): (52 * 1024 + 1024 + 2048) + 2 * 2 * (1024 * 1024 + 1024 + 2048)
    + 1024 * 78 + 78,
    ("lifting", "lstm"): lstm_params(52, 64, 2) + 64 * 78 + 78,
    ("lifting", "lstm_relative_rot"): lstm_params(52, 64, 2) + 64 * 156 + 156,
    ("lifting", "poseformer"): (2 * 32 + 32) + 26 * 32 + 9 * 832 + 4 * block_params(32)
    + 4 * block_params(832) + 2 * 32 + 2 * 832 + (9 + 1) + 2 * 832 + 832 * 78 + 78,
    # convolutions without bias + GroupNorm affine, Linear(8w*16 -> 256), BiGRU(256, 128),
    # Linear(256 -> 52), w = 32; heatmap head (default): Conv1x1(128 -> 26), the soft-argmax
    # temperature, Linear(256 + 52 -> 256)
    ("pose_estimation", "pose_cnn"): sum(9 * a * b + 2 * b for a, b in [
        (3, 32), (32, 64), (64, 64), (64, 128), (128, 128), (128, 256), (256, 256)])
    + (256 * 16 * 256 + 256) + 2 * (3 * 128 * (256 + 128) + 6 * 128) + 256 * 52 + 52
    + (128 * 26 + 26) + 1 + (308 * 256 + 256),
    # the hand count is in test_pose_temporal.py (test_parameters_by_hand_...)
    ("pose_estimation", "pose_temporal"): 763_179,
}


@pytest.mark.parametrize("key", sorted(PARAMS))
def test_parameter_counts(key):
    m = models.create(*key)
    assert sum(p.numel() for p in m.parameters()) == PARAMS[key]
    if key[1] == "simple_transformer":
        assert PARAMS[key] == 1_357_944


@pytest.mark.parametrize("task,name", ALL)
@pytest.mark.parametrize("B,L", [(1, 16), (1, 30), (64, 16), (64, 30)])
def test_forward_shapes(task, name, B, L):
    hp = SMALL.get(name, {}) if B > 1 else {}
    torch.manual_seed(0)
    m = models.create(task, name, **hp).eval()
    x, vis = make_inputs(task, B, L, S=32 if B > 1 else 64)
    with torch.no_grad():
        out = m(x, vis, **context(name, B))
    assert tuple(out.shape) == expected_shape(task, m, B, L)
    assert out.dtype == torch.float32 and torch.isfinite(out).all()


@pytest.mark.parametrize("task,name", ALL)
def test_same_seed_same_model_and_output(task, name):
    hp = SMALL.get(name, {})
    x, vis = make_inputs(task, 4, 12)
    outs = []
    for _ in range(2):
        torch.manual_seed(1234)
        m = models.create(task, name, **hp)
        torch.manual_seed(99)  # dropout / stochastic depth draws in train mode
        outs.append(m(x, vis, **context(name, 4)).detach())
    torch.testing.assert_close(outs[0], outs[1], atol=0, rtol=0)
    m.eval()
    with torch.no_grad():
        torch.testing.assert_close(m(x, vis, **context(name, 4)), m(x, vis, **context(name, 4)),
                                   atol=0, rtol=0)
    torch.manual_seed(4321)
    other = models.create(task, name, **hp).eval()
    with torch.no_grad():
        assert not torch.equal(other(x, vis, **context(name, 4)), m(x, vis, **context(name, 4)))


def fake_batch(task, name, B, L, seed=0):
    x, vis = make_inputs(task, B, L, seed=seed)
    g = torch.Generator().manual_seed(seed + 1)
    batch = {"inputs": x, "visible": vis, "meta": context(name, B) or {}}
    if task == "classification":
        batch["targets"] = torch.tensor([0, 1] * (B // 2))
    elif task == "autoencoder":
        batch["targets"] = torch.randn(B, L, 26, 2, generator=g)
    elif task == "lifting":
        batch["targets"] = torch.randn(B, L, 26, 3, generator=g)
    else:
        batch["targets"] = torch.rand(B, L, 26, 2, generator=g) * x.shape[-1]
    return batch


@pytest.mark.parametrize("task,name", ALL)
def test_gradients_reach_every_parameter(task, name):
    torch.manual_seed(0)
    m = models.create(task, name, **({"width": 8} if name == "pose_cnn" else {}))
    L = 9 if name == "poseformer" else 6
    batch = fake_batch(task, name, 4, L)
    loss = m.loss(m.forward_batch(batch), batch)
    assert loss.ndim == 0 and torch.isfinite(loss)
    loss.backward()
    for pname, p in m.named_parameters():
        assert p.grad is not None, pname
        assert torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0, pname


@pytest.mark.parametrize("task,name", [k for k in ALL if k[0] != "pose_estimation"])
def test_use_visible_adds_the_mask(task, name):
    torch.manual_seed(0)
    m = models.create(task, name, use_visible=True, **SMALL.get(name, {})).eval()
    L = 10
    x, vis = make_inputs(task, 2, L)
    ctx = context(name, 2)
    with torch.no_grad():
        a = m(x, vis, **ctx)
        hidden = vis.clone()
        hidden[:, :, 5] = ~hidden[:, :, 5]
        b = m(x, hidden, **ctx)
        assert tuple(a.shape) == expected_shape(task, m, 2, L)
        assert not torch.allclose(a, b)  # the mask is an input
    with pytest.raises(ValueError, match="use_visible=True"):
        m(x, None, **ctx)
    plain = models.create(task, name, **SMALL.get(name, {})).eval()
    with torch.no_grad():  # the default ignores the mask, as the original
        torch.testing.assert_close(plain(x, vis, **ctx), plain(x, hidden, **ctx))


def test_bad_input_shapes_raise():
    m = models.create("classification", "lstm")
    with pytest.raises(ValueError, match=r"\(B, L, 26, 2\)"):
        m(torch.zeros(2, 8, 25, 2))
    with pytest.raises(ValueError, match="visible must be a"):
        m(torch.zeros(2, 8, 26, 2), torch.ones(2, 8, 25, dtype=torch.bool))
    # PoseFormer pads short clips at their edges: 8 frames in, 8 predicted
    assert models.create("lifting", "poseformer", **SMALL["poseformer"])(
        torch.zeros(1, 8, 26, 2)).shape == (1, 8, 26, 3)
    with pytest.raises(ValueError, match=r"\(B, L, 3, S, S\)"):
        models.create("pose_estimation", "pose_cnn")(torch.zeros(1, 2, 26, 2))
    with pytest.raises(ValueError, match="needs age and gender"):
        models.create("lifting", "lstm_relative_rot")(torch.zeros(1, 4, 26, 2))
    with pytest.raises(ValueError, match="allowed ages"):
        models.create("lifting", "lstm_relative_rot")(torch.zeros(1, 4, 26, 2), age=["old"],
                                                       gender=["male"])


def test_poseformer_predicts_each_frame_from_the_window_centred_on_it():
    torch.manual_seed(0)
    m = models.create("lifting", "poseformer", **SMALL["poseformer"]).eval()
    x, _ = make_inputs("lifting", 2, 13)
    assert m.frame_slice(13) == slice(0, 13) and m.centre_slice(13) == slice(4, 9)
    with torch.no_grad():
        out = m(x)
        assert out.shape == (2, 13, 26, 3)
        # the clip padded by replicating its first/last frame 4 times: frame t = the
        # window [t, t + 9) of the padded clip, its centre frame (index 4 of a 9-frame clip)
        padded = torch.cat([x[:, :1].expand(2, 4, 26, 2), x, x[:, -1:].expand(2, 4, 26, 2)], 1)
        for t in range(13):
            torch.testing.assert_close(out[:, t], m(padded[:, t:t + 9])[:, 4], atol=1e-5,
                                       rtol=1e-5)


def test_simple_transformer_is_frame_order_equivariant_without_encoding():
    x, _ = make_inputs("autoencoder", 2, 10)
    perm = torch.randperm(10, generator=torch.Generator().manual_seed(0))
    for name, equivariant in (("simple_transformer", True), ("simple_transformer_pe", False)):
        torch.manual_seed(0)
        m = models.create("autoencoder", name, **SMALL[name]).eval()
        with torch.no_grad():
            same = torch.allclose(m(x)[:, perm], m(x[:, perm]), atol=1e-5)
        assert same == equivariant, name


def test_pedestrian_graph_is_the_intended_pooling():
    """Per-sample reference: explicit neighbour sums, mean over frames and channels."""
    torch.manual_seed(0)
    m = models.create("classification", "pedestrian_graph").eval()
    x, _ = make_inputs("classification", 3, 5)
    nbrs = {i: [j for j in range(26) if (i, j) in sk.EDGES or (j, i) in sk.EDGES]
            for i in range(26)}
    assert skeleton_adjacency().sum() == 50 and skeleton_adjacency().diag().sum() == 0
    with torch.no_grad():
        out = m(x)
        for b in range(3):
            h = x[b]
            for conv in (m.conv1, m.conv2):
                h = torch.relu(torch.stack([sum(h[:, j] @ conv.weight for j in nbrs[i])
                                            for i in range(26)], 1) + conv.bias)
            pooled = h.mean(dim=(0, 2))  # (26,) per joint
            torch.testing.assert_close(out[b], m.fc(pooled)[0], atol=1e-5, rtol=1e-5)
            torch.testing.assert_close(out[b], m(x[b:b + 1])[0], atol=1e-5, rtol=1e-5)


def test_losses_by_task():
    out = torch.tensor([[2.0, 0.0], [0.0, 1.0]])
    batch = {"targets": torch.tensor([0, 0])}
    want = -(torch.log_softmax(out, 1)[:, 0]).mean()
    torch.testing.assert_close(models.create("classification", "lstm").loss(out, batch), want)
    g = models.create("classification", "pedestrian_graph")
    logit = torch.tensor([0.0, 2.0])
    want = -(np.log(0.5) + np.log(1 - 1 / (1 + np.exp(-2.0)))) / 2
    assert abs(g.loss(logit, {"targets": torch.tensor([1, 0])}).item() - want) < 1e-6
    # pose estimation: MSE per coordinate over visible joints only
    pe = models.create("pose_estimation", "pose_cnn", width=4, hidden=4)
    pred = torch.zeros(1, 1, 26, 2)
    tgt = torch.zeros(1, 1, 26, 2)
    tgt[0, 0, 3] = torch.tensor([3.0, 4.0])
    tgt[0, 0, 4] = torch.tensor([100.0, 0.0])
    vis = torch.zeros(1, 1, 26, dtype=torch.bool)
    vis[0, 0, :4] = True
    assert pe.loss(pred, {"targets": tgt, "visible": vis}).item() == pytest.approx(25 / 8)


def test_configure_optimizers_report_defaults():
    cases = {("classification", "lstm"): (1e-4, 1e-8, None),
             ("autoencoder", "simple_transformer"): (1e-3, 1e-2, "CosineAnnealingWarmRestarts"),
             ("lifting", "poseformer"): (4e-4, 0.1, "ExponentialLR")}
    for (task, name), (lr, wd, sched) in cases.items():
        m = models.create(task, name, **SMALL.get(name, {}))
        conf = m.configure_optimizers()  # Lightning's own format
        opt = conf["optimizer"]
        assert isinstance(opt, torch.optim.AdamW)
        assert opt.param_groups[0]["lr"] == lr and opt.param_groups[0]["weight_decay"] == wd
        if sched is None:
            assert set(conf) == {"optimizer"}
        else:
            assert set(conf) == {"optimizer", "lr_scheduler"}
            assert set(conf["lr_scheduler"]) == {"scheduler", "interval"}
            assert conf["lr_scheduler"]["interval"] == "epoch"
            assert type(conf["lr_scheduler"]["scheduler"]).__name__ == sched
            assert conf["lr_scheduler"]["scheduler"].optimizer is opt
    conf = models.create("autoencoder", "simple_transformer",
                         dim_feedforward=8).configure_optimizers(lr=0.5)
    s = conf["lr_scheduler"]["scheduler"]
    assert conf["optimizer"].param_groups[0]["lr"] == 0.5 and s.T_0 == 30 and s.eta_min == 1e-8
    assert models.create("lifting", "poseformer", **SMALL["poseformer"]) \
        .configure_optimizers()["lr_scheduler"]["scheduler"].gamma == 0.99


def test_trivial_baselines():
    with pytest.raises(ValueError, match="task must be one of"):
        models.trivial_baseline("detection")
    maj = models.trivial_baseline("classification").fit(
        [{"targets": torch.tensor([1, 1, 0])}, {"targets": torch.tensor([1])}])
    out = maj(torch.zeros(5, 4, 26, 2))
    assert out.shape == (5, 2) and (out.argmax(1) == 1).all() and maj.majority == 1
    torch.testing.assert_close(out[0].softmax(0), torch.tensor([0.25, 0.75]), atol=1e-3, rtol=0)
    ident = models.trivial_baseline("autoencoder").fit([])
    x = torch.randn(2, 3, 26, 2)
    torch.testing.assert_close(ident(x), x)
    mean = models.trivial_baseline("lifting").fit(
        [{"targets": torch.ones(2, 3, 26, 3)}, {"targets": torch.full((1, 3, 26, 3), 4.0)}])
    torch.testing.assert_close(mean(x), torch.full((2, 3, 26, 3), 2.0))
    crop = models.trivial_baseline("pose_estimation")
    t = torch.zeros(1, 2, 26, 2)
    t[0, 0, 0] = 10.0
    t[0, 1, 0] = 99.0
    vis = torch.ones(1, 2, 26, dtype=torch.bool)
    vis[0, 1, 0] = False
    crop.fit([{"targets": t, "visible": vis}])
    pred = crop(torch.zeros(3, 4, 3, 16, 16, dtype=torch.uint8))
    assert pred.shape == (3, 4, 26, 2) and (pred[..., 0, :] == 10.0).all()


def test_pose_cnn_regression_starts_at_the_mean_training_skeleton():
    crops = torch.zeros(2, 3, 3, 32, 32, dtype=torch.uint8)
    t = torch.rand(2, 3, 26, 2) * 32
    base = models.trivial_baseline("pose_estimation").fit(
        [{"inputs": crops, "targets": t, "visible": torch.ones(2, 3, 26, dtype=torch.bool)}])
    assert base.crop_size == 32
    torch.manual_seed(0)
    m = models.create("pose_estimation", "pose_cnn", width=4, hidden=8,
                      head="regression").eval()
    torch.nn.init.zeros_(m.out.weight)  # the head's output is then exactly its anchor
    with torch.no_grad():
        assert torch.allclose(m(crops), torch.full((2, 3, 26, 2), 16.0))  # the centre
        m.init_from_baseline(base)
        torch.testing.assert_close(m(crops), t.mean(dim=(0, 1)).expand(2, 3, 26, 2))
    assert "anchor" in m.state_dict()  # travels with checkpoints
    heat = models.create("pose_estimation", "pose_cnn", width=4, hidden=8, head="heatmap")
    heat.init_from_baseline(base)  # soft-argmax head: nothing to anchor
    assert (heat.anchor == 0.5).all()


@pytest.mark.parametrize("task,name", ALL)
def test_bf16_autocast_training_step(task, name):
    """Every model runs under torch.autocast("cpu", bfloat16), also on CPUs without a bf16
    LSTM kernel (LSTM layers fall back to float32); the loss is float32 and close."""
    torch.manual_seed(0)
    m = models.create(task, name, **SMALL.get(name, {}))
    L = 9 if name == "poseformer" else 6
    batch = fake_batch(task, name, 4, L)
    m.eval()
    with torch.no_grad():
        ref = m.loss(m.forward_batch(batch), batch)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            low = m.loss(m.forward_batch(batch), batch)
    assert low.dtype == torch.float32
    assert abs(low.item() - ref.item()) <= 0.05 * abs(ref.item()) + 1e-3
    m.train()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        loss = m.loss(m.forward_batch(batch), batch)
    loss.backward()
    assert all(torch.isfinite(p.grad).all() for p in m.parameters() if p.grad is not None)
