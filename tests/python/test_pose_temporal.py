"""pose_estimation/pose_temporal (#38): shapes and options, sub-pixel decoding against
known peaks, the temporal block's reach, a short fit, and the training augmentation it
relies on (flips with the left/right swap, rotation, draws per clip)."""
import copy

import numpy as np
import pytest
import torch

from bsp_fast import models, skeleton as sk
from bsp_fast.data import BSPDataModule, ClipDataset, ImageAugment
from bsp_fast.data.testing import write_clip_file
from bsp_fast.models.cost import flops_per_clip, parameter_count
from bsp_fast.models.pose_temporal import dark_decode, gaussian_heatmaps, soft_argmax
from bsp_fast.models.testing import paint_joint_crops
from bsp_fast.training.tasks import get_task

torch.set_num_threads(1)
FLIP = list(sk.FLIP_PERMUTATION)
TINY = dict(width=4, depth=3)


def create(**hp):
    return models.create("pose_estimation", "pose_temporal", **hp)


def crops(B, L, S, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (B, L, 3, S, S), generator=g, dtype=torch.uint8)


# ---------------------------------------------------------------------- model and options
@pytest.mark.parametrize("S,depth", [(32, 3), (64, 4), (96, 4), (96, 5), (128, 4)])
def test_output_shapes_and_heatmaps_at_half_the_crop(S, depth):
    m = create(width=4, depth=depth).eval()
    with torch.no_grad():
        out = m(crops(2, 3, S))
        maps = m.heatmaps(crops(2, 3, S))
    assert out.shape == (2, 3, 26, 2) and out.dtype == torch.float32
    assert maps.shape == (6, 26, S // 2, S // 2)
    assert torch.isfinite(out).all() and (out >= 0).all() and (out <= S).all()


def test_bad_options_and_crop_sizes_raise_saying_what_is_allowed():
    for hp, match in ((dict(decode="argmax"), r"decode must be one of \['soft_argmax', 'dark'\]"),
                      (dict(loss="l2"), r"loss must be one of \['integral', 'heatmap'\]"),
                      (dict(temporal="gru"), r"temporal must be one of \['conv', 'none'\]"),
                      (dict(temporal_kernel=4), "temporal_kernel must be odd"),
                      (dict(temporal_kernel=0), "temporal_kernel must be an integer >= 1"),
                      (dict(depth=1), "depth must be an integer >= 2"),
                      (dict(depth=7), r"depth must be an integer in \[2, 6\]"),
                      (dict(sigma=0.0), r"sigma must be a number in \[0.25, 8.0\]"),
                      (dict(occluded_weight=1.5), r"occluded_weight must be a number in"),
                      (dict(width=True), "width must be an integer"),
                      (dict(norm="layer"), r"norm must be one of \['group', 'batch'\]")):
        with pytest.raises(ValueError, match=match):
            create(**hp)
    with pytest.raises(ValueError, match=r"crop size 40 must be a multiple of 2\*\*depth = 16"):
        create(width=4)(crops(1, 1, 40))


def test_parameters_by_hand_and_flops_proportional_to_pixels_and_frames():
    """Parameters of the defaults (width 16, depth 4, kernel 5, GroupNorm): convolutions
    without bias + GroupNorm's two vectors; the temporal block's two Conv1d (the second
    with bias); 1x1 projections; the 1x1 head with bias; the soft-argmax temperature."""
    ch = [16, 32, 64, 128]

    def conv(a, b):
        return 9 * a * b + 2 * b

    def res(c):
        return 2 * conv(c, c)

    want = conv(3, 16) + res(16) + sum(conv(ch[k - 1], ch[k]) + res(ch[k]) for k in (1, 2, 3))
    want += 2 * 128 * 128 * 5 + 2 * 128 + 128
    want += sum(ch[k] * ch[k - 1] + 2 * ch[k - 1] + res(ch[k - 1]) for k in (1, 2, 3))
    want += 16 * 26 + 26 + 1
    m = create()
    assert parameter_count(m) == want == 763_179
    # every counted FLOP is a convolution whose output grows with the pixels and frames:
    # 128 x 128 crops cost exactly 4x 64 x 64 ones, 30 frames exactly 30x one frame
    f64 = flops_per_clip(m, {"inputs": crops(1, 2, 64)})
    assert flops_per_clip(m, {"inputs": crops(1, 2, 128)}) == 4 * f64
    assert flops_per_clip(m, {"inputs": crops(1, 30, 64)}) == 15 * f64
    assert 2.0e9 < 15 * f64 < 3.0e9  # docs/models.md: about 2.4 GFLOPs per 30-frame clip


def test_temporal_none_is_the_per_frame_network():
    torch.manual_seed(0)
    m = create(temporal="none", **TINY)
    x = crops(2, 5, 32)
    for mode in (True, False):  # GroupNorm: the same function in training and evaluation
        m.train(mode)
        clip = m(x).detach()
        one = torch.cat([m(x[:, t:t + 1]).detach() for t in range(5)], 1)
        torch.testing.assert_close(clip, one, atol=1e-5, rtol=0)
    assert not any("temporal" in k for k in m.state_dict())


def test_temporal_block_sees_the_neighbouring_frames_only():
    """Two Conv1d of kernel 3: frame t sees frames t-2 .. t+2; with replicated edges a
    change of frame 0 moves frames 0, 1, 2 and leaves frames 3.. exactly as they were."""
    torch.manual_seed(0)
    m = create(temporal_kernel=3, **TINY).eval()
    torch.nn.init.normal_(m.temporal.conv2.weight, std=0.1)  # trained-sized, not ~0
    x = crops(1, 7, 32)
    y = x.clone()
    y[:, 0] = crops(1, 1, 32, seed=5)[:, 0]
    with torch.no_grad():
        a, b = m(x), m(y)
    moved = (a - b).abs().amax((0, 2, 3))
    assert (moved[:3] > 1e-4).all(), moved
    assert (moved[3:] == 0).all(), moved
    plain = create(temporal="none", **TINY).eval()
    with torch.no_grad():
        assert ((plain(x) - plain(y)).abs().amax((0, 2, 3))[1:] == 0).all()


# ---------------------------------------------------------------------- decoding
PEAKS = torch.tensor([[[16.37, 20.81], [30.5, 17.12], [18.93, 29.06]]], dtype=torch.float64)


def test_decoders_recover_a_known_sub_pixel_peak():
    """Gaussian maps (sigma 1.5 cells) centred on hand-picked points >= 6 sigma from every
    edge of a 48 x 48 map. The log of a Gaussian is a quadratic, so DARK's Newton step is
    exact up to float32 (1e-4 cells); smoothing by a Gaussian keeps the centre (1e-3). The
    soft-argmax of the log-map is the mean of the sampled Gaussian, which equals its centre
    up to a tail and sampling error far below 1e-3 cells (Poisson summation:
    exp(-2 pi^2 sigma^2) ~ 1e-19). The plain argmax is off by up to half a cell."""
    maps = gaussian_heatmaps(PEAKS, 48, 48, 1.5)
    assert maps.shape == (1, 3, 48, 48)
    torch.testing.assert_close(dark_decode(maps, None).double(), PEAKS, atol=1e-4, rtol=0)
    torch.testing.assert_close(dark_decode(maps, 1.5).double(), PEAKS, atol=1e-3, rtol=0)
    torch.testing.assert_close(soft_argmax(torch.log(maps)).double(), PEAKS, atol=1e-3, rtol=0)
    at = maps.flatten(2).argmax(-1)
    argmax = torch.stack([at % 48 + 0.5, at // 48 + 0.5], -1).double()
    assert (argmax - PEAKS).abs().max() > 0.3


def test_dark_by_hand_on_a_three_by_three_quadratic():
    """log h = -(x - 1.8)^2 / 2 - (y - 1.3)^2 / 2 at cell centres 0.5, 1.5, 2.5: the maximum
    cell is (1, 1) (centre 1.5, 1.5); gradient (0.3, -0.2), Hessian -I: the step is
    (+0.3, -0.2) and the answer (1.8, 1.3). A flat map keeps its first cell's centre."""
    c = torch.tensor([0.5, 1.5, 2.5])
    logh = -(c[None, :] - 1.8) ** 2 / 2 - (c[:, None] - 1.3) ** 2 / 2
    got = dark_decode(logh.exp().view(1, 1, 3, 3), None)
    torch.testing.assert_close(got, torch.tensor([[[1.8, 1.3]]]), atol=1e-5, rtol=0)
    flat = dark_decode(torch.ones(1, 1, 4, 4), None)
    torch.testing.assert_close(flat, torch.tensor([[[0.5, 0.5]]]))


def test_dark_takes_the_stronger_mode_where_the_soft_argmax_averages_two():
    """A left/right confusion: two peaks, one twice as high. DARK (no smoothing) decodes the
    higher one; the soft-argmax of the log-map is the mass-weighted mean, between them
    (2/3 of the way: 10 + 20 x 2/3 for equal widths)."""
    a = gaussian_heatmaps(torch.tensor([[[10.0, 24.0]]]), 48, 48, 1.5)
    b = gaussian_heatmaps(torch.tensor([[[30.0, 24.0]]]), 48, 48, 1.5)
    maps = a + 2 * b
    torch.testing.assert_close(dark_decode(maps, None)[0, 0], torch.tensor([30.0, 24.0]),
                               atol=1e-3, rtol=0)
    soft = soft_argmax(torch.log(maps))[0, 0]
    torch.testing.assert_close(soft, torch.tensor([10 + 20 * 2 / 3, 24.0]), atol=1e-3, rtol=0)


@pytest.mark.parametrize("decode,loss", [("soft_argmax", "integral"), ("dark", "integral"),
                                         ("dark", "heatmap"), ("soft_argmax", "heatmap")])
def test_the_model_decodes_its_heatmaps_into_crop_pixels(decode, loss):
    """Heatmaps forced to Gaussians at known cells: the output is the peak in crop pixels
    (2 per cell at S/2), with every decoding and loss."""
    m = create(decode=decode, loss=loss, **TINY).eval()
    cells = torch.rand(2 * 3, 26, 2, generator=torch.Generator().manual_seed(1),
                       dtype=torch.float64) * 4 + 6  # 6..10 of 16 cells: >= 4 sigma inside
    g = gaussian_heatmaps(cells, 16, 16, 1.5).float()
    forced = g if loss == "heatmap" else torch.log(g)  # integral: log-probabilities
    m.heatmaps = lambda inputs: forced
    out = m(crops(2, 3, 32))
    tol = 0.02 if (decode, loss) == ("soft_argmax", "heatmap") else 2e-3
    torch.testing.assert_close(out.double(), 2 * cells.view(2, 3, 26, 2), atol=tol, rtol=0)


@pytest.mark.parametrize("decode", ["soft_argmax", "dark"])
def test_flip_test_averages_with_the_mirrored_crop_mapped_back_by_the_data_flip(decode):
    """flip_test = the mean of the plain prediction and the mirrored crop's prediction
    mapped back by the data pipeline's own flip (u -> S - u, left/right swapped), in eval
    only; the validation loss scores the averaged joints."""
    from bsp_fast.data import flip_horizontal

    torch.manual_seed(3)
    m = create(decode=decode, **TINY).eval()
    x = crops(2, 3, 32, seed=4)
    with torch.no_grad():
        plain, mirrored = m(x).numpy(), m(x.flip(-1)).numpy()
        m.flip_test = True
        both = m(x).numpy()
    want = (plain + flip_horizontal(mirrored, 32)) / 2
    np.testing.assert_allclose(both, want, atol=1e-4, rtol=0)
    assert np.abs(both - plain).max() > 0.05  # an untrained net is not mirror-symmetric
    b = {"inputs": x, "targets": torch.as_tensor(want), "visible": None}
    if decode == "soft_argmax":  # the loss's soft-argmax joints are the averaged ones
        with torch.no_grad():
            assert float(m.loss(m.forward_batch(b), b)) < 1e-4
    m.train()
    with torch.no_grad():  # training never flips (the augmentation does)
        np.testing.assert_allclose(m(x).numpy(), plain, atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="flip_test must be true or false"):
        create(flip_test=1)


def test_the_activations_layout_changes_speed_not_the_function(monkeypatch):
    """MEMORY_FORMAT (NCHW under bf16, channels_last in float32 by default) only picks the
    kernels: outputs and gradients agree across layouts to float32 rounding."""
    import bsp_fast.models.pose_temporal as PT

    torch.manual_seed(5)
    m = create(**TINY)
    b = batch_for(m)
    got = {}
    for fmt in (torch.contiguous_format, torch.channels_last, None):
        monkeypatch.setattr(PT, "MEMORY_FORMAT", fmt)
        m.zero_grad()
        out = m.forward_batch(b)
        m.loss(out, b).backward()
        got[fmt] = (out.detach(), [p.grad.clone() for p in m.parameters()])
    ref_out, ref_grad = got[None]
    for out, grad in got.values():
        torch.testing.assert_close(out, ref_out, atol=1e-4, rtol=0)
        for a, g in zip(grad, ref_grad):
            torch.testing.assert_close(a, g, atol=1e-4, rtol=1e-3)
    captured = []
    monkeypatch.setattr(PT, "MEMORY_FORMAT", None)
    h = m.stem.register_forward_hook(lambda mod, inp, outp: captured.append(
        inp[0].is_contiguous()))
    with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16):
        m(b["inputs"])
    with torch.no_grad():
        m(b["inputs"])
    h.remove()
    assert captured == [True, False]  # bf16: NCHW; float32: channels_last


def test_bench_memory_format_smoke(capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_memory_format.py"
    spec = importlib.util.spec_from_file_location("bench_memory_format", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--models", "pose_temporal", "--crop", "32", "--clips", "1",
                       "--frames", "2", "--steps", "1"]) == 0
    out = capsys.readouterr().out
    assert "| pose_temporal | float32 |" in out and "| pose_temporal | bf16 |" in out
    rows = [line for line in out.splitlines() if line.startswith("| pose_temporal |")]
    assert [r.rsplit("|", 2)[1].strip() for r in rows] == ["channels_last", "NCHW"]
    import bsp_fast.models.pose_temporal as PT
    assert PT.MEMORY_FORMAT is None  # restored


# ---------------------------------------------------------------------- loss
def batch_for(m, B=2, L=3, S=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    return {"inputs": crops(B, L, S, seed), "targets": torch.rand(B, L, 26, 2, generator=g) * S,
            "visible": torch.rand(B, L, 26, generator=g) > 0.3}


@pytest.mark.parametrize("loss", ["integral", "heatmap"])
def test_loss_masks_frames_without_a_crop_and_weights_hidden_joints(loss):
    torch.manual_seed(0)
    m = create(loss=loss, occluded_weight=0.0, **TINY)
    b = batch_for(m)
    b["targets"][0, 1] = float("nan")  # a frame without a crop
    value = m.loss(m.forward_batch(b), b)
    value.backward()
    assert torch.isfinite(value) and all(torch.isfinite(p.grad).all() for p in m.parameters())
    moved = dict(b, targets=b["targets"].clone())
    hidden = ~b["visible"][1, 2]
    moved["targets"][1, 2, hidden] += 7.0  # hidden joints, weight 0: no change
    with torch.no_grad():
        torch.testing.assert_close(m.loss(m.forward_batch(moved), moved),
                                   m.loss(m.forward_batch(b), b))
        moved["targets"][1, 2, ~hidden] += 7.0
        assert m.loss(m.forward_batch(moved), moved) != m.loss(m.forward_batch(b), b)


def test_loss_needs_its_own_forward_and_copies_drop_it():
    m = create(**TINY)
    b = batch_for(m)
    out = m.forward_batch(b)
    with pytest.raises(ValueError, match="latest forward pass"):
        m.loss(out.clone(), b)
    m.loss(out, b).backward()
    twin = copy.deepcopy(m)  # non-leaf tensors of the last forward are not copied
    assert twin._last is None and torch.equal(twin(b["inputs"]), m(b["inputs"]))


def test_heatmap_loss_by_hand():
    """The heatmap loss of the target maps themselves is 0; of all-zero maps, the mean of
    the squared target Gaussians over the cells, here for joints far from the edges:
    sum g^2 = pi sigma^2 (the integral of exp(-d^2 / sigma^2)) over 16 x 16 cells."""
    m = create(loss="heatmap", **TINY)
    b = batch_for(m)
    b["targets"] = torch.full((2, 3, 26, 2), 16.0) + torch.rand(2, 3, 26, 2) * 2
    out = m.forward_batch(b)
    cells = b["targets"] / 2
    perfect = gaussian_heatmaps(cells.view(-1, 26, 2), 16, 16, 1.5)
    m._last = (out, perfect, None)
    assert m.loss(out, b).item() < 1e-12
    m._last = (out, torch.zeros_like(perfect), None)
    torch.testing.assert_close(m.loss(out, b).item(), np.pi * 1.5 ** 2 / 256, atol=1e-6, rtol=0)


def test_a_short_fit_learns_more_than_the_mean_skeleton(tmp_path):
    """Painted joints (one coloured blob per joint) on 32 x 32 crops, zoomed, shifted and
    rotated once per clip so that the mean skeleton is a poor answer: 100 steps of the
    default (integral) loss bring the mean pixel error on these clips below half the mean
    skeleton's (measured: 10.3 px before, 1.5 px after, mean skeleton 4.3 px)."""
    path = tmp_path / "fit.h5"
    write_clip_file(path, clips=(24, 2, 2), clip_length=8, media=True, crop_size=32, seed=3)
    paint_joint_crops(path, ("train",), seed=3)
    ds = ClipDataset(path, "train", "pose_estimation", seed=0, augment=True, image_scale=0.2,
                     image_shift=0.15, image_rotation=30.0, color_jitter=0.0)
    data = [ds[i:i + 8] for i in range(0, len(ds), 8)]  # epoch 0: the same draws each time
    t = torch.cat([b["targets"] for b in data])
    mean_err = (t - t.mean((0, 1))).norm(dim=-1).mean().item()
    torch.manual_seed(0)
    m = create(width=8, depth=3)

    def error():
        m.eval()
        with torch.no_grad():
            return torch.cat([(m.forward_batch(b) - b["targets"]).norm(dim=-1)
                              for b in data]).mean().item()

    before = error()
    opt = m.configure_optimizers(lr=3e-3)["optimizer"]
    losses = []
    m.train()
    for step in range(100):
        b = data[step % len(data)]
        loss = m.loss(m.forward_batch(b), b)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    after = error()
    assert np.mean(losses[-10:]) < 0.3 * np.mean(losses[:10]), losses
    assert after < 0.5 * mean_err < before, (before, after, mean_err)


# ---------------------------------------------------------------------- augmentation
def test_flip_permutation_swaps_left_and_right_and_is_an_involution():
    names = sk.JOINT_NAMES
    assert [FLIP[i] for i in FLIP] == list(range(26))
    for i, j in enumerate(FLIP):
        assert names[j] == names[i].replace("__L", "__X").replace("__R", "__L").replace(
            "__X", "__R")
    assert FLIP[sk.JOINT_INDEX["crl_hand__L"]] == sk.JOINT_INDEX["crl_hand__R"] == 15


def test_flipping_crops_twice_is_the_identity_and_swaps_the_hands():
    rng = np.random.default_rng(0)
    S = 32
    img = rng.integers(0, 256, (2, 3, S, S, 3), dtype=np.uint8)
    joints = rng.uniform(1, S - 1, (2, 3, 26, 2)).astype(np.float32)
    vis = np.ones((2, 3, 26), bool)
    flip = ImageAugment(flip_p=1.0, scale=0.0, shift=0.0, color_jitter=0.0)
    out, j1, v1, _ = flip(img, joints, vis, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(out, img.transpose(0, 1, 4, 2, 3)[..., ::-1])
    left, right = sk.JOINT_INDEX["crl_hand__L"], sk.JOINT_INDEX["crl_hand__R"]
    np.testing.assert_allclose(j1[..., right, :], np.stack(
        [S - joints[..., left, 0], joints[..., left, 1]], -1), atol=1e-5)
    back = np.rint(out).astype(np.uint8).transpose(0, 1, 3, 4, 2)
    out2, j2, v2, _ = flip(back, j1, v1, rng=np.random.default_rng(2))
    np.testing.assert_array_equal(out2, img.transpose(0, 1, 4, 2, 3))
    np.testing.assert_allclose(j2, joints, atol=1e-5)
    assert v2.all()


class _Fixed:
    """An rng whose uniforms are fixed: ``angle`` for the rotation draw, 0 for the rest."""

    def __init__(self, angle):
        self.angle = angle

    def random(self, size):
        return np.ones(size)  # no flip

    def uniform(self, lo, hi, size):
        return np.full(size, self.angle) if hi == 90.0 else np.zeros(size)


def test_rotation_by_hand_moves_pixels_and_joints_together():
    """90 degrees about the crop centre (16, 16) of a 32 x 32 crop, from +u towards +v:
    the joint (20.5, 16.5) -> (15.5, 20.5); the bright pixel under it moves along."""
    img = np.zeros((1, 1, 32, 32, 3), np.uint8)
    img[0, 0, 16, 20] = 255  # pixel (u=20, v=16), centre (20.5, 16.5)
    joints = np.full((1, 1, 26, 2), 16.0, np.float32)
    joints[0, 0, 0] = (20.5, 16.5)
    aug = ImageAugment(flip_p=0.0, scale=0.0, shift=0.0, color_jitter=0.0, rotation=90.0)
    out, j, vis, _ = aug(img, joints, np.ones((1, 1, 26), bool), rng=_Fixed(90.0))
    np.testing.assert_allclose(j[0, 0, 0], (15.5, 20.5), atol=1e-4)
    assert out[0, 0, :, 20, 15].min() > 250 and out.sum() < 256 * 3 * 1.01
    assert vis.all()
    with pytest.raises(ValueError, match=r"rotation must lie in \[0, 180.0\]"):
        ImageAugment(rotation=200.0)


def test_zero_rotation_leaves_the_other_draws_as_they_were():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (4, 2, 16, 16, 3), dtype=np.uint8)
    joints = rng.uniform(2, 14, (4, 2, 26, 2)).astype(np.float32)
    vis = np.ones((4, 2, 26), bool)
    old = ImageAugment()(img, joints, vis, rng=np.random.default_rng(9))
    new = ImageAugment(rotation=0.0)(img, joints, vis, rng=np.random.default_rng(9))
    for a, b in zip(old[:3], new[:3]):
        np.testing.assert_array_equal(a, b)


@pytest.fixture(scope="module")
def media_h5(tmp_path_factory):
    path = tmp_path_factory.mktemp("pose_temporal") / "clips.h5"
    write_clip_file(path, clips=(20, 4, 4), clip_length=4, media=True, crop_size=32, seed=5)
    return path


def test_augmentation_draws_are_per_clip_whatever_the_batch(media_h5):
    opts = dict(augment=True, image_rotation=20.0, seed=7)
    ds = ClipDataset(media_h5, "train", "pose_estimation", **opts)
    n = len(ds)
    ref = ds[list(range(n))]
    for size in (1, 3, 8):
        ds = ClipDataset(media_h5, "train", "pose_estimation", **opts)
        loader = ds.loader(size, shuffle=True, sampler_seed=size)
        loader.sampler.set_epoch(0)
        for b in loader:
            for k, r in enumerate(b["meta"]["row"].tolist()):
                for key in ("inputs", "targets", "visible"):
                    np.testing.assert_array_equal(b[key][k].numpy(), ref[key][r].numpy())
    plain = ClipDataset(media_h5, "train", "pose_estimation", seed=7)[list(range(n))]
    assert not np.allclose(plain["targets"].numpy(), ref["targets"].numpy())


def test_image_augment_option_reaches_the_train_split_only(media_h5):
    task = get_task("pose_estimation")
    assert task.dataset_options({"image_augment": False}) == {}
    opts = task.dataset_options({"image_augment": True, "image_rotation": 20.0,
                                 "box_jitter_scale": 0.0})
    assert opts == {"augment": True, "image_rotation": 20.0}
    dm = BSPDataModule(h5_path=media_h5, task="pose_estimation", clip_length=4,
                       dataset_options=opts, verbose=False)
    dm.setup("fit")
    train, val = dm.datasets["train"], dm.datasets["val"]
    assert train.augment and train._augment.rotation == 20.0
    assert not val.augment


# ---------------------------------------------------------------------- learning rate
def test_cosine_schedule_by_hand_and_constant_has_none():
    assert "lr_scheduler" not in create(width=4).configure_optimizers(total_steps=10)
    m = create(width=4, lr_schedule="cosine")
    conf = m.configure_optimizers(lr=1e-3, total_steps=4)
    opt, sched = conf["optimizer"], conf["lr_scheduler"]["scheduler"]
    assert conf["lr_scheduler"]["interval"] == "step"
    rates = []
    for _ in range(5):
        rates.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    # 1e-3 * (1 + cos(pi k / 4)) / 2 for k = 0..4
    np.testing.assert_allclose(rates, [1e-3, 8.5355339e-4, 5e-4, 1.4644661e-4, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="lr_schedule='cosine' ends with the run's budget"):
        m.configure_optimizers(total_steps=None)
    with pytest.raises(ValueError, match="lr_schedule"):
        create(width=4, lr_schedule="step")


def test_cosine_schedule_ends_with_the_runs_budget_in_bsp_train(media_h5, tmp_path):
    import bsp_fast

    out = tmp_path / "run"
    bsp_fast.train("pose_estimation", "pose_temporal", data=media_h5, out=out, epochs=3,
                   max_steps=7, batch_size=4, crop_size=32, accelerator="cpu", precision="32",
                   threads=1, early_stop=0, seed=3, hp={"width": 4, "depth": 3,
                                                        "lr_schedule": "cosine"})
    ck = torch.load(out / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=False)
    # 20 train clips at batch 4: 5 updates an epoch, so max_steps (7) ends the run
    assert ck["global_step"] == 7
    (state,) = ck["lr_schedulers"]
    assert state["T_max"] == 7 and state["last_epoch"] == 7
    assert ck["optimizer_states"][0]["param_groups"][0]["lr"] == pytest.approx(0.0, abs=1e-12)
