"""PyTorch habits on the datasets: plain DataLoader and Subset, transform hooks, seeds."""
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, Subset

from bsp_fast.data import ClipDataset, ContiguousBatchSampler
from bsp_fast.data.testing import write_clip_file

L, S = 6, 16


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("torch") / "clips.h5"
    write_clip_file(path, clips=(60, 12, 12), clip_length=L, media=True, crop_size=S)
    return path


def test_plain_dataloader_with_shuffle_and_default_collate(h5file):
    ds = ClipDataset(h5file, "train", "lifting")
    torch.manual_seed(0)
    seen = []
    for batch in DataLoader(ds, batch_size=32, shuffle=True):
        idx = batch["meta"]["index"].tolist()
        seen += idx
        assert batch["inputs"].shape == (len(idx), L, 26, 2)
        assert isinstance(batch["meta"]["video_id"], list)
        ref = ds[idx]  # the fast path gives the same values
        for key in ("inputs", "targets", "targets_m", "visible", "label"):
            assert torch.equal(batch[key], ref[key]), key
        assert batch["meta"]["video_id"] == ref["meta"]["video_id"]
    assert sorted(seen) == list(range(len(ds))) and seen != sorted(seen)


def test_subset_and_workers_with_plain_dataloader(h5file):
    ds = ClipDataset(h5file, "val", "classification", noise=3.0)
    sub = Subset(ds, [7, 2, 9, 4, 0])
    batches = list(DataLoader(sub, batch_size=2, num_workers=2))
    assert [b["meta"]["index"].tolist() for b in batches] == [[7, 2], [9, 4], [0]]
    assert [b["targets"].tolist() for b in batches][0] == ds.labels[[7, 2]].tolist()
    one = DataLoader(ds, batch_size=None)  # no batching: one sample at a time
    first = next(iter(one))
    assert first["inputs"].shape == (L, 26, 2) and first["meta"]["index"].item() == 0


def test_transform_hooks_run_per_sample_on_every_path(h5file):
    shapes = []

    def transform(x):
        shapes.append(tuple(x.shape))
        return x * 2

    ds = ClipDataset(h5file, "val", "autoencoder", transform=transform,
                     target_transform=lambda t: t[..., :1])
    plain = ClipDataset(h5file, "val", "autoencoder")
    b, ref = ds[[3, 1, 4]], plain[[3, 1, 4]]
    assert shapes == [(L, 26, 2)] * 3
    assert torch.equal(b["inputs"], ref["inputs"] * 2)
    assert torch.equal(b["targets"], ref["targets"][..., :1])
    loaded = next(iter(ds.loader(4, num_workers=1)))
    assert torch.equal(loaded["inputs"], plain[[0, 1, 2, 3]]["inputs"] * 2)
    item = ds[5]
    assert torch.equal(item["targets"], plain[5]["targets"][..., :1])
    pose = ClipDataset(h5file, "val", "pose_estimation",
                       transform=lambda x: x.float().mean(dim=(-1, -2)))
    p = next(iter(DataLoader(pose, batch_size=3)))
    stored = ClipDataset(h5file, "val", "pose_estimation")[[0, 1, 2]]["inputs"]
    assert p["inputs"].shape == (3, L, 3)  # the transform saw (L, 3, S, S) crops
    assert torch.allclose(p["inputs"], stored.float().mean(dim=(-1, -2)))
    with pytest.raises(ValueError, match="transform must be a callable"):
        ClipDataset(h5file, "val", transform="flip")


def _two_epochs(h5file, seed=None, sampler_seed=None):
    ds = ClipDataset(h5file, "train", "classification", noise=5.0, mjp=0.2, seed=seed)
    loader = ds.loader(8, sampler_seed=sampler_seed)
    out = []
    for _ in range(2):
        for b in loader:
            out.append((b["meta"]["index"].tolist(), b["inputs"].clone()))
    return out


def _same(a, b) -> bool:
    return all(i == j and torch.equal(x, y) for (i, x), (j, y) in zip(a, b))


def test_seed_everything_makes_order_and_noise_reproducible(h5file):
    seed_everything = pytest.importorskip("lightning").seed_everything
    seed_everything(11)
    a = _two_epochs(h5file)
    seed_everything(11)
    b = _two_epochs(h5file)
    seed_everything(12)
    c = _two_epochs(h5file)
    assert _same(a, b)
    assert [i for i, _ in a] != [i for i, _ in c]  # another seed: another order ...
    assert not torch.equal(a[0][1], c[0][1])  # ... and other noise
    assert [i for i, _ in a[:len(a) // 2]] != [i for i, _ in a[len(a) // 2:]]  # per epoch
    # explicit seeds win over the global seed
    torch.manual_seed(1)
    d = _two_epochs(h5file, seed=5, sampler_seed=6)
    torch.manual_seed(2)
    e = _two_epochs(h5file, seed=5, sampler_seed=6)
    assert _same(d, e)


def test_sampler_shares_every_epoch_between_ranks():
    n, B = 101, 8
    for drop_last in (False, True):
        ranks = [ContiguousBatchSampler(n, B, shuffle=True, block_size=4, seed=3,
                                        drop_last=drop_last, num_replicas=3, rank=r)
                 for r in range(3)]
        for epoch in (0, 1):
            shares = [[list(b) for b in ranks[r].batches(epoch)] for r in range(3)]
            assert len({len(s) for s in shares}) == 1 and len(shares[0]) == len(ranks[0])
            flat = [i for s in shares for b in s for i in b]
            if drop_last:  # whole super-batches only: no repeats, full batches
                assert len(flat) == len(set(flat)) == (n // (3 * B)) * 3 * B
                assert all(len(b) == B for s in shares for b in s)
            else:  # padded by wrapping: everything, at most 2 clips twice
                assert set(flat) == set(range(n)) and len(flat) == 102
            for s in shares:  # each batch is a slice of the block order: few runs
                assert all(1 + np.count_nonzero(np.diff(b) != 1) <= B // 4 + 2 for b in s)
    assert [list(b) for b in ContiguousBatchSampler(5, 2, num_replicas=2, rank=1)] == [[2, 3], [0]]
    with pytest.raises(ValueError, match="without a process group"):
        list(ContiguousBatchSampler(10, 2, shuffle=True, num_replicas=2, rank=0))
    with pytest.raises(ValueError, match="rank must lie in"):
        ContiguousBatchSampler(10, 2, num_replicas=2, rank=2)


def test_missing_torch_is_an_import_error_naming_the_extra():
    import os
    import subprocess
    import sys

    code = ("import sys; sys.modules['torch'] = None\n"
            "import bsp_fast.data as d\n"
            "d.normalize_hips_neck  # NumPy transforms work without torch\n"
            "d.ClipDataset\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 1
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: bsp_fast.data needs torch")
    assert "pip install 'bsp_fast[torch]'" in last
