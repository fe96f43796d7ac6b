"""Detector-like box noise (#27): noisy boxes within the stated bounds, seeded, and cut out
of the stored context crops; zero noise gives the plain crops exactly."""
import h5py
import numpy as np
import pytest

from bsp_fast import conversion as cv
from bsp_fast.data import BSPDataModule, ClipDataset
from bsp_fast.data.images import BoxNoise, recrop

S = 32


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    from bsp_fast.synth import generate

    root = tmp_path_factory.mktemp("boxnoise")
    generate(root / "ds", "sample", clips=3, frames=90, size="480x180", seed=2, workers=1,
             progress=False)
    out = root / "clips.h5"
    with pytest.warns(UserWarning):
        cv.convert(root / "ds", out, clip_length=8, clip_offset=8, crop_size=S, val_frac=0.3,
                   test_frac=0.3, threads=2, crop_context=1.25)
    return out


def test_noisy_boxes_stay_within_the_stated_bounds_and_follow_the_seed():
    box = np.array([[100.0, 40.0, 164.0, 104.0]] * 20000)  # side 64, centre (132, 72)
    noise = BoxNoise(0.1, 0.05)
    a = noise(box, np.random.default_rng(7))
    np.testing.assert_array_equal(a, noise(box, np.random.default_rng(7)))
    assert not np.array_equal(a, noise(box, np.random.default_rng(8)))
    side = a[:, 2] - a[:, 0]
    np.testing.assert_allclose(a[:, 3] - a[:, 1], side)  # still squares
    f = side / 64
    move = ((a[:, :2] + a[:, 2:]) / 2 - [132, 72]) / 64
    assert f.min() >= 0.9 and f.max() <= 1.1 and np.abs(move).max() <= 0.05
    assert f.min() < 0.901 and f.max() > 1.099 and np.abs(move).max() > 0.0499  # uses the range
    np.testing.assert_array_equal(BoxNoise()(box[:3], np.random.default_rng(0)), box[:3])
    assert np.isnan(noise(np.full((1, 4), np.nan), np.random.default_rng(0))).all()
    with pytest.raises(ValueError, match="scale"):
        BoxNoise(0.6, 0.0)


def test_recrop_by_hand():
    """A context of 8 x 8 px over image box [10, 20, 18, 28] (1 image px per context px):
    the box [12, 22, 16, 26] at size 4 is the context's rows/columns 2..5 exactly; a box
    half outside is zero there."""
    ctx = np.arange(8 * 8 * 3, dtype=np.uint8).reshape(1, 8, 8, 3)
    cbox = np.array([[10, 20, 18, 28]], np.float32)
    out = recrop(ctx, cbox, np.array([[12.0, 22.0, 16.0, 26.0]]), 4)
    np.testing.assert_array_equal(out[0], ctx[0, 2:6, 2:6])
    half = recrop(ctx, cbox, np.array([[6.0, 20.0, 14.0, 28.0]]), 8)
    np.testing.assert_array_equal(half[0, :, :4], 0)
    np.testing.assert_array_equal(half[0, :, 4:], ctx[0, :, :4])


def test_context_crops_hold_the_plain_crop(converted):
    """Cut at the plain box, the stored context gives back the converter's crop up to
    resampling (INTER_AREA twice vs once): the geometry of context_box is right."""
    with h5py.File(converted) as f:
        g = f["train"]
        box, rgb = g["frames/crop_box"][()], g["frames/rgb"][()].astype(int)
        ctx, cbox = g["frames/context_rgb"][()], g["frames/context_box"][()]
    assert ctx.shape[1:] == (40, 40, 3)  # ceil(1.25 * 32)
    ok = np.isfinite(box).all(1)
    again = recrop(ctx[ok], cbox[ok], box[ok], S).astype(int)
    err = np.abs(again - rgb[ok]).mean()
    shifted = recrop(ctx[ok], cbox[ok], box[ok] + [2, 0, 2, 0], S).astype(int)
    assert err < 6 and np.abs(shifted - rgb[ok]).mean() > err + 2


def test_dataset_box_noise_zero_equals_plain_and_is_seeded(converted):
    plain = ClipDataset(converted, "test", "pose_estimation")
    zero = ClipDataset(converted, "test", "pose_estimation", box_noise=(0.0, 0.0))
    noisy = ClipDataset(converted, "test", "pose_estimation", box_noise=(0.1, 0.05))
    again = ClipDataset(converted, "test", "pose_estimation", box_noise=(0.1, 0.05))
    n = len(plain)
    idx = list(range(n))
    p, z, a, b = plain[idx], zero[idx], noisy[idx], again[idx]
    for k in ("inputs", "targets", "crop_box", "visible"):
        np.testing.assert_array_equal(p[k].numpy(), z[k].numpy())
        np.testing.assert_array_equal(a[k].numpy(), b[k].numpy())
    # the boxes of a clip do not depend on the batch it is read in
    np.testing.assert_array_equal(noisy[[n - 1]]["crop_box"].numpy()[0], a["crop_box"].numpy()[-1])
    pb, nb = p["crop_box"].numpy().astype(np.float64), a["crop_box"].numpy().astype(np.float64)
    ok = np.isfinite(pb).all(-1)
    side = pb[..., 2] - pb[..., 0]
    f = (nb[..., 2] - nb[..., 0])[ok] / side[ok]
    move = (((nb[..., :2] + nb[..., 2:]) - (pb[..., :2] + pb[..., 2:])) / 2)[ok] / side[ok][:, None]
    assert 0.9 - 1e-5 <= f.min() and f.max() <= 1.1 + 1e-5 and np.abs(move).max() <= 0.05 + 1e-5
    assert not np.array_equal(p["inputs"].numpy(), a["inputs"].numpy())
    # the joints follow the box: image pixels = crop pixels * side / S + corner
    back = a["targets"].numpy() * ((nb[..., 2] - nb[..., 0]) / S)[..., None, None] + nb[..., None, :2]
    img = p["targets"].numpy() * (side / S)[..., None, None] + pb[..., None, :2]
    np.testing.assert_allclose(back[ok], img[ok], atol=1e-2)


def test_noise_past_the_context_is_refused_and_jitter_is_train_only(converted, tmp_path):
    with pytest.raises(ValueError, match="--crop-context 1.5 or more"):
        ClipDataset(converted, "test", "pose_estimation", box_noise=(0.3, 0.1))
    dm = BSPDataModule(h5_path=converted, task="pose_estimation", verbose=False,
                       dataset_options={"box_jitter": (0.1, 0.05), "box_noise": (0.05, 0.02)})
    dm.setup("fit")
    dm.setup("test")
    assert (dm.datasets["train"].box_noise.scale, dm.datasets["train"].box_noise.shift) == (0.1, 0.05)
    assert (dm.datasets["val"].box_noise.scale, dm.datasets["test"].box_noise.shift) == (0.05, 0.02)


def test_bsp_eval_box_noise_scores_noisy_crops(converted, tmp_path):
    import bsp_fast
    from bsp_fast.training.evaluate import evaluate, main as eval_main

    run = bsp_fast.train("pose_estimation", "pose_cnn", data=converted, out=tmp_path / "run",
                         epochs=1, batch_size=4, limit_batches=2, crop_size=S, quiet=True,
                         hp={"width": 4, "hidden": 16})
    plain = evaluate(run.run_dir, "test")  # the whole split (the run itself read 2 batches)
    noisy = evaluate(run.run_dir, "test", box_noise=(0.1, 0.05))
    assert noisy.metrics["pck_0.05"] != plain.metrics["pck_0.05"]
    # the boxes are drawn per clip: any batch size or worker count, the same scores (PCK is
    # a ratio of counts: exactly). Not the loss: the training loss is normalised per batch
    # by its visible joints, so its clip-weighted mean over batches moves with the batch
    # size (~1e-4 relative here, with or without box noise); no table reports it.
    for batch, workers in ((1, 0), (7, 0), (64, 0), (7, 2), (64, 2)):
        again = evaluate(run.run_dir, "test", box_noise=(0.1, 0.05), batch_size=batch,
                         workers=workers)
        assert again.clips == noisy.clips
        for k, v in noisy.metrics.items():
            if k != "loss":
                assert again.metrics[k] == v, (k, batch, workers)
    zero = evaluate(run.run_dir, "test", box_noise=(0.0, 0.0))
    assert zero.metrics == plain.metrics
    with pytest.raises(SystemExit):
        eval_main([str(run.run_dir), "--box-noise", "0.1"])


def test_seeds_pose_table_scores_noisy_boxes_per_seed(converted, tmp_path, capsys):
    # bsp-reproduce --seeds: every seed's run is scored on noisy boxes too, as without
    import json
    from pathlib import Path

    from bsp_fast import reproduction as R

    argv = ["pose_estimation", "--data", str(converted), "--budget", "smoke", "--out",
            str(tmp_path), "--rows", "pose_cnn", "--seeds", "2", "--jobs", "1", "--set",
            f"crop_size={S}", "--set", "hp={width: 4, hidden: 16}"]
    assert R.main(argv) == 0
    text = capsys.readouterr().out
    saved = json.loads((tmp_path / "pose_estimation-smoke" / "results.json").read_text())
    seeds = saved["results"]["pose_cnn"]["seeds"]
    assert len(seeds) == 2
    for one in seeds.values():
        noisy = json.loads((Path(one["run"]) / "test_box_noise.json").read_text())
        assert noisy["box_noise"] == {"scale": 0.1, "shift": 0.05}
        assert one["metrics"]["pck_0.05_noisy"] == noisy["test"]["pck_0.05"]
        # the noisy sums per recording sit beside the clean ones: intervals for both
        rec = json.loads((Path(one["run"]) / "test_per_recording.json").read_text())["test"]
        for name in ("pck_0.05", "pckhn_0.1"):
            sums = rec["metrics"][f"{name}_noisy"]
            assert len(sums["num"]) == len(rec["recordings"])
            assert sum(sums["num"]) / sum(sums["den"]) == pytest.approx(noisy["test"][name])
    from bsp_fast.reproduction.evidence import _Sums

    per_seed, _ = _Sums(saved).seeds("pose_cnn", "pck_0.05_noisy", False)
    assert len(per_seed) == 2  # what the two-level intervals resample, seed by seed
    assert "PCK@0.05 noisy boxes" in text
