"""Converted files made of HDF5 virtual datasets (bsp-convert --scheduler dask): the loaders
read them like one file, and refuse them, naming the shard, when a shard is missing or
unreadable (HDF5 itself would read zeros)."""
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from bsp_fast.data import MissingShardError, check_virtual_sources, open_clip_file
from bsp_fast.data import cache as _cache
from bsp_fast.conversion import vds as _vds
_write_virtual = _vds.write_virtual
from bsp_fast.data.testing import write_clip_file

torch = pytest.importorskip("torch")
torch.set_num_threads(1)


@pytest.fixture
def pair(tmp_path):
    """tmp/clips.h5 over tmp/clips.h5.shards/part-0000{0,1}.h5 (relative names)."""
    shards = tmp_path / "clips.h5.shards"
    shards.mkdir()
    parts = [shards / f"part-{k:05d}.h5" for k in range(2)]
    for k, p in enumerate(parts):
        write_clip_file(p, clips=(6, 5, 4), clip_length=8, seed=k + 1)
    out = tmp_path / "clips.h5"
    _write_virtual(out, shards, shards.name, len(parts))  # what bsp-convert --scheduler dask writes
    _vds._checked.clear()
    return out, parts


def _items(path, split="val"):
    from bsp_fast.data import ClipDataset

    ds = ClipDataset(path, split, "classification")
    batch = ds[list(range(len(ds)))]
    return len(ds), batch


def test_virtual_file_reads_as_the_concatenated_shards(pair):
    out, parts = pair
    n, b = _items(out)
    (n0, b0), (n1, b1) = _items(parts[0]), _items(parts[1])
    assert n == n0 + n1 and n0 > 0 and n1 > 0
    np.testing.assert_array_equal(b["label"].numpy(), np.r_[b0["label"].numpy(),
                                                             b1["label"].numpy()])
    x = b["inputs"].numpy()
    np.testing.assert_array_equal(x[:n0], b0["inputs"].numpy())
    np.testing.assert_array_equal(x[n0:], b1["inputs"].numpy())
    assert np.abs(x[n0:]).max() > 0.1  # shard 1's rows are data, not fill values
    # through the contiguous loader too
    from bsp_fast.data import ClipDataset

    got = torch.cat([bb["label"] for bb in ClipDataset(out, "val", "classification")
                     .loader(batch_size=3)])
    np.testing.assert_array_equal(got.numpy(), b["label"].numpy())


def test_pair_moved_together_and_read_from_another_cwd(pair, tmp_path, monkeypatch):
    out, _ = pair
    dest = tmp_path / "elsewhere"
    dest.mkdir()
    shutil.copy(out, dest / out.name)
    shutil.copytree(out.parent / "clips.h5.shards", dest / "clips.h5.shards")
    monkeypatch.chdir(dest.parent.parent)  # neither folder: names resolve next to the file
    n, b = _items(dest / "clips.h5")
    m, c = _items(out)
    assert n == m
    np.testing.assert_array_equal(b["inputs"].numpy(), c["inputs"].numpy())


def test_missing_shard_is_named(pair):
    out, parts = pair
    from bsp_fast.data import ClipDataset

    parts[1].unlink()
    with h5py.File(out, "r") as f:  # what the check prevents: HDF5 reads zeros silently
        assert not f["val/projection_2d"][-1].any()
    with pytest.raises(MissingShardError) as info:
        ClipDataset(out, "val", "classification")
    msg = str(info.value)
    assert str(out) in msg and str(parts[1]) in msg and "does not exist" in msg
    assert "clips.h5.shards" in msg and "must travel with clips.h5" in msg
    assert str(parts[0]) not in msg
    assert isinstance(info.value, FileNotFoundError) and isinstance(info.value, ValueError)


def test_missing_shards_folder(pair):
    out, parts = pair
    shutil.rmtree(parts[0].parent)
    with pytest.raises(MissingShardError, match="part-00000.h5, which does not exist"):
        open_clip_file(out)


def test_shard_deleted_after_the_dataset_was_made(pair):
    """The check runs on every open (workers, after close()), revalidating the cache."""
    out, parts = pair
    from bsp_fast.data import ClipDataset

    ds = ClipDataset(out, "val", "classification")
    first = ds[0]["inputs"].clone()
    ds.close()
    np.testing.assert_array_equal(ds[0]["inputs"].numpy(), first.numpy())  # reopens: fine
    ds.close()
    parts[0].unlink()
    with pytest.raises(MissingShardError, match="part-00000.h5"):
        ds[0]


def test_unreadable_shard_and_shard_without_the_dataset(pair):
    out, parts = pair
    data = parts[1].read_bytes()
    parts[1].write_bytes(b"not an HDF5 file" * 64)
    with pytest.raises(MissingShardError, match=r"part-00001\.h5, which cannot be opened"):
        open_clip_file(out)
    parts[1].write_bytes(data)
    assert open_clip_file(out).close() is None
    with h5py.File(parts[1], "a") as f:
        del f["val/labels"]
    with pytest.raises(MissingShardError, match="holds no dataset /?val/labels"):
        open_clip_file(out)


def test_check_is_cached_per_file_and_sources(pair, monkeypatch):
    out, parts = pair
    calls = []
    real = _vds._sources
    monkeypatch.setattr(_vds, "_sources", lambda f: calls.append(1) or real(f))
    for _ in range(3):
        open_clip_file(out).close()
    assert len(calls) == 1
    os.utime(parts[1], ns=(1, 1))  # a source changed: checked again
    open_clip_file(out).close()
    assert len(calls) == 2


def test_self_reference_and_plain_files(tmp_path):
    plain = tmp_path / "plain.h5"
    write_clip_file(plain, clips=(4, 4, 4), clip_length=8)
    with h5py.File(plain, "r") as f:
        check_virtual_sources(f)  # no virtual datasets: nothing to check
    with h5py.File(plain, "a") as f:
        n = f["val/labels"].shape[0]
        layout = h5py.VirtualLayout((2 * n,), f["val/labels"].dtype)
        src = h5py.VirtualSource(".", "val/labels", shape=(n,))
        layout[:n], layout[n:] = src, src
        f.create_virtual_dataset("val_twice", layout)
    with h5py.File(plain, "r") as f:
        assert [m.file_name for m in f["val_twice"].virtual_sources()] == [".", "."]
        check_virtual_sources(f)
        np.testing.assert_array_equal(f["val_twice"][n:], f["val/labels"][()])


def test_cache_reuse_check_reports_missing_shards(pair):
    out, parts = pair
    shutil.rmtree(parts[0].parent)
    why = _cache.stale_reason(out, {}, Path(__file__))
    assert why.startswith("its shard files are missing") and "part-00000.h5" in why
