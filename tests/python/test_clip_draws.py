"""Every random draw applied to a clip is a function of (seed, split, epoch, the clip's row)
alone (#34): batch size, batch composition, shuffle order and worker count change nothing,
down to the scores of a checkpoint."""
import numpy as np
import pytest

import bsp_fast
from bsp_fast.data import ClipDataset
from bsp_fast.data.clip_random import ClipRandom, clip_keys
from bsp_fast.data.testing import write_clip_file

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- the generator itself
def test_a_clip_draws_the_same_numbers_alone_or_in_any_batch():
    rows = np.array([11, 3, 500, 7, 42])
    whole = ClipRandom.for_rows(5, 2, 0, rows)
    draws = [whole.standard_normal((5, 30, 26, 2)), whole.random((5, 30, 26), np.float32),
             whole.uniform(-10, 10, (5,)), whole.random(5)]
    for i, r in enumerate(rows):
        alone = ClipRandom.for_rows(5, 2, 0, [r])
        got = [alone.standard_normal((1, 30, 26, 2)), alone.random((1, 30, 26), np.float32),
               alone.uniform(-10, 10, (1,)), alone.random(1)]
        for a, b in zip(draws, got):
            np.testing.assert_array_equal(a[i], b[0])
    # reversed order of the batch: the same numbers per clip
    back = ClipRandom.for_rows(5, 2, 0, rows[::-1])
    np.testing.assert_array_equal(back.standard_normal((5, 30, 26, 2))[::-1], draws[0])


def test_the_key_separates_seed_split_epoch_and_row():
    base = clip_keys(1, 0, 0, np.arange(1000))
    assert len(np.unique(base)) == 1000
    for other in (clip_keys(2, 0, 0, np.arange(1000)), clip_keys(1, 1, 0, np.arange(1000)),
                  clip_keys(1, 0, 1, np.arange(1000))):
        assert not np.intersect1d(base, other).size


def test_uniforms_and_normals_have_the_stated_distribution():
    from scipy import stats

    g = ClipRandom.for_rows(0, 0, 0, np.arange(64))
    u64 = g.random((64, 4000))
    u32 = g.random((64, 4000), np.float32)
    n = g.standard_normal((64, 4001))  # odd: the last pair is cut
    assert u64.dtype == np.float64 and u32.dtype == np.float32 and n.dtype == np.float32
    assert u64.min() >= 0 and u64.max() < 1 and u32.min() >= 0 and u32.max() < 1
    assert np.all(u32 * 2**24 == np.floor(u32 * 2**24))  # on the stated grid
    # Kolmogorov-Smirnov on 256k draws each; a fixed key, so no flakiness: the p-values
    # are what this generator gives, and a broken transform gives p ~ 0
    assert stats.kstest(u64.ravel(), "uniform").pvalue > 1e-3
    assert stats.kstest(u32.ravel(), "uniform").pvalue > 1e-3
    assert stats.kstest(n.ravel(), "norm").pvalue > 1e-3
    assert abs(n.mean()) < 0.01 and abs(n.std() - 1) < 0.01
    assert np.abs(n).max() < 5.9  # the stated cut-off
    # neighbouring clips and neighbouring draws are uncorrelated
    assert abs(np.corrcoef(n[:-1].ravel(), n[1:].ravel())[0, 1]) < 0.01
    assert abs(np.corrcoef(n[:, :-1].ravel(), n[:, 1:].ravel())[0, 1]) < 0.01


def test_the_first_axis_must_be_the_batch():
    g = ClipRandom.for_rows(0, 0, 0, [1, 2, 3])
    with pytest.raises(ValueError, match="batch's 3 clips"):
        g.random((4, 2))
    with pytest.raises(ValueError, match="batch's 3 clips"):
        g.standard_normal(())


# ---------------------------------------------------------------- datasets and loaders
@pytest.fixture(scope="module")
def h5(tmp_path_factory):
    path = tmp_path_factory.mktemp("draws") / "clips.h5"
    write_clip_file(path, clips=(150, 40, 150), clip_length=8, seed=11)
    return path


def _by_row(batches, key="inputs") -> dict:
    out = {}
    for b in batches:
        for r, x in zip(b["meta"]["row"].tolist(), b[key].numpy()):
            out[r] = x
    return out


@pytest.mark.parametrize("split", ["test", "train"])
def test_dataset_draws_ignore_batch_size_order_and_workers(h5, split):
    opts = dict(task="autoencoder", noise=5.0, mjp=0.3, seed=7, augment=split == "train")
    ds = ClipDataset(h5, split, **opts)
    n = len(ds)
    ref = _by_row([ds[list(range(n))]])
    ref_vis = _by_row([ds[list(range(n))]], "visible")
    assert len(ref) == n
    one = ds[n - 1]
    np.testing.assert_array_equal(one["inputs"].numpy(), ref[int(one["meta"]["row"])])
    for batch, workers, shuffle in ((1, 0, False), (7, 0, True), (64, 2, True), (7, 2, False)):
        ds = ClipDataset(h5, split, **opts)
        loader = ds.loader(batch, shuffle=shuffle, num_workers=workers, sampler_seed=batch,
                           persistent_workers=False)
        loader.sampler.set_epoch(0)
        batches = list(loader)
        got, vis = _by_row(batches), _by_row(batches, "visible")
        assert sorted(got) == sorted(ref)
        for r in ref:
            np.testing.assert_array_equal(got[r], ref[r], err_msg=f"row {r}, batch {batch}")
            np.testing.assert_array_equal(vis[r], ref_vis[r])
    if split == "train":  # a new epoch draws anew; val/test draws are fixed
        ds.set_epoch(1)
        other = _by_row([ds[list(range(n))]])
        assert not any(np.array_equal(other[r], ref[r]) for r in ref)
    # and the noise is really there: corrupted inputs differ from the clean ones
    clean = _by_row([ClipDataset(h5, split, task="autoencoder", seed=7,
                                 augment=False)[list(range(n))]])
    assert not any(np.array_equal(clean[r], ref[r]) for r in ref)


# ---------------------------------------------------------------- a checkpoint's scores
@pytest.fixture(scope="module")
def noisy_run(h5, tmp_path_factory):
    out = tmp_path_factory.mktemp("noisy-run") / "run"
    return h5, bsp_fast.train("classification", "lstm", data=h5, out=out, epochs=1,
                          batch_size=16, noise=5.0, mjp=0.7187, quiet=True,
                          hp={"hidden_size": 8, "num_layers": 1})


def test_a_noisy_checkpoint_scores_the_same_at_any_batch_size_and_worker_count(noisy_run):
    from bsp_fast.training.evaluate import evaluate

    h5, noisy_run = noisy_run
    results = [evaluate(noisy_run.run_dir, "test", batch_size=b, workers=w)
               for b, w in ((1, 0), (7, 0), (64, 0), (7, 2), (64, 2))]
    first = results[0]
    assert first.clips == len(ClipDataset(h5, "test"))  # the whole split
    for res in results[1:]:
        assert (res.clips, res.recordings) == (first.clips, first.recordings)
        for k, v in first.metrics.items():
            # counts (F1, precision, recall, accuracy) exactly; the loss is a float sum
            # whose order follows the batches: 1e-6 relative
            assert res.metrics[k] == pytest.approx(v, rel=1e-6, abs=1e-9), k
    # the run's own test (batch 16 during training) scored the same draws
    assert first.metrics["loss"] == pytest.approx(noisy_run.metrics["loss"], rel=1e-6)
    # and the scores saw noise: without it the same checkpoint scores differently
    clean = evaluate(noisy_run.run_dir, "test", noise=0.0, mjp=0.0)
    assert clean.metrics["loss"] != pytest.approx(first.metrics["loss"], rel=1e-6)


def test_bsp_eval_scores_every_clip_and_says_how_many(noisy_run, capsys):
    from bsp_fast.training.evaluate import evaluate, main as eval_main

    h5, noisy_run = noisy_run
    n = len(ClipDataset(h5, "test"))
    # a run trained with --limit-batches 1 still gets the whole split from bsp-eval
    limited = bsp_fast.train("classification", "lstm", data=h5,
                             out=noisy_run.run_dir.parent / "limited", epochs=1,
                             batch_size=16, limit_batches=1, quiet=True,
                             hp={"hidden_size": 8, "num_layers": 1})
    assert eval_main([str(limited.run_dir), "--batch-size", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"scored {n} clips of " in out
    res = evaluate(limited.run_dir, "test", batch_size=1)
    assert res.clips == n
    part = evaluate(limited.run_dir, "test", batch_size=1, limit_batches=5)
    assert part.clips == 5


def test_bsp_predict_covers_every_clip_with_the_same_inputs_at_any_batch(noisy_run, tmp_path,
                                                                         capsys):
    import h5py

    from bsp_fast.training.predict import main as predict_main, predict

    h5, run = noisy_run
    n = len(ClipDataset(h5, "test"))
    a = predict(run.run_dir, tmp_path / "b1.h5", batch_size=1)
    b = predict(run.run_dir, tmp_path / "b64.h5", batch_size=64, workers=2)
    assert a.clips == b.clips == n and a.recordings == b.recordings > 1
    with h5py.File(tmp_path / "b1.h5") as fa, h5py.File(tmp_path / "b64.h5") as fb:
        assert sorted(fa) == sorted(fb)
        for k in fa:
            x, y = fa[k][()], fb[k][()]
            if x.dtype.kind == "f":  # the same noisy inputs: outputs equal up to float order
                np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6, err_msg=k)
            else:
                np.testing.assert_array_equal(x, y, err_msg=k)
    assert predict_main([str(run.run_dir), "--out", str(tmp_path / "c.h5"), "--quiet"]) == 0
    assert predict_main([str(run.run_dir), "--out", str(tmp_path / "d.h5")]) == 0
    assert f"{n} test clips of {a.recordings} recordings" in capsys.readouterr().out
