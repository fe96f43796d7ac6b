"""ClipDataset and ContiguousBatchSampler on small files in the documented HDF5 schema.

The files come from ``bsp_fast.data.testing.write_clip_file`` (h5py, exact schema,
kinematically consistent poses); media (``frames/rgb`` ...) follow the future layout that
bsp-convert does not write yet.
"""
import h5py
import numpy as np
import pytest
import torch

from bsp_fast.data import (
    ClipDataset,
    ContiguousBatchSampler,
    IndexBatch,
    flip_horizontal,
    normalize_hips_neck,
)
from bsp_fast.data.testing import write_clip_file

TASKS = ("classification", "autoencoder", "lifting", "pose_estimation")
L, S = 8, 32


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("loaders") / "clips.h5"
    write_clip_file(path, clips=(96, 24, 24), clip_length=L, clip_offset=4, media=True,
                    crop_size=S, chunk=16)
    return path


def stored(path, split, name, rows=slice(None)):
    with h5py.File(path, "r") as f:
        return f[split][name][()][rows]


EXPECTED = {
    "classification": {"inputs": ((L, 26, 2), torch.float32), "targets": ((), torch.int64)},
    "autoencoder": {"inputs": ((L, 26, 2), torch.float32), "targets": ((L, 26, 2), torch.float32),
                    "target_shift": ((L, 2), torch.float32), "target_scale": ((L,), torch.float32)},
    "lifting": {"inputs": ((L, 26, 2), torch.float32), "targets": ((L, 26, 3), torch.float32),
                "targets_m": ((L, 26, 3), torch.float32)},
    "pose_estimation": {"inputs": ((L, 3, S, S), torch.uint8),
                        "targets": ((L, 26, 2), torch.float32),
                        "visible": ((L, 26), torch.bool), "crop_box": ((L, 4), torch.float32)},
}


@pytest.mark.parametrize("task", TASKS)
def test_shapes_and_dtypes_per_task(h5file, task):
    ds = ClipDataset(h5file, "val", task)
    assert len(ds) == stored(h5file, "val", "labels").shape[0]
    batch = ds[[0, 1, 2]]
    for key, (shape, dtype) in EXPECTED[task].items():
        assert tuple(batch[key].shape) == (3,) + shape, key
        assert batch[key].dtype == dtype, key
    assert batch["label"].dtype == torch.int64 and batch["label"].shape == (3,)
    meta = batch["meta"]
    assert len(meta["video_id"]) == 3 and isinstance(meta["video_id"][0], str)
    assert meta["frames"].shape == (3, L) and meta["frames"].dtype == torch.int64
    for key in ("age", "gender", "pedestrian_id"):
        assert len(meta[key]) == 3
    one = ds[1]
    for key, (shape, dtype) in EXPECTED[task].items():
        assert tuple(one[key].shape) == shape and one[key].dtype == dtype
    assert isinstance(one["meta"]["video_id"], str)


def test_classification_values_match_the_file(h5file):
    ds = ClipDataset(h5file, "val", "classification", with_pixels=True)
    rows = [5, 0, 7, 7]
    b = ds[rows]
    px = stored(h5file, "val", "projection_2d", rows)
    n = normalize_hips_neck(px)
    np.testing.assert_allclose(b["inputs"].numpy(), n.points, rtol=1e-6)
    np.testing.assert_allclose(b["pixels"].numpy(), px)
    np.testing.assert_array_equal(b["targets"].numpy(), stored(h5file, "val", "labels", rows))
    np.testing.assert_array_equal(b["meta"]["frames"].numpy(),
                                  stored(h5file, "val", "targets/frame_idx", rows))
    with h5py.File(h5file) as f:
        vid = f["val/meta/video_id"].asstr()[()][rows].tolist()
        clip_id = f["val/meta/clip_id"][()][rows]
    assert b["meta"]["video_id"] == vid
    np.testing.assert_array_equal(b["meta"]["clip_id"].numpy(), clip_id)
    # hips at the origin and unit hips-neck distance in every frame
    np.testing.assert_allclose(b["inputs"][:, :, 1].numpy(), 0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(b["inputs"][:, :, 8].numpy(), axis=-1), 1, rtol=1e-5)


def test_lifting_targets_and_camera_frame_agree_with_the_projection(h5file):
    ds = ClipDataset(h5file, "test", "lifting", lifting_target="camera", with_pixels=True)
    b = ds[list(range(len(ds)))]
    cam = b["targets_m"].numpy().astype(np.float64)  # x forward, y right, z up
    u = 1600 / 2 + 800 * cam[..., 1] / cam[..., 0]  # f = W / (2 tan 45deg) = 800
    v = 600 / 2 - 800 * cam[..., 2] / cam[..., 0]
    np.testing.assert_allclose(np.stack([u, v], -1), b["pixels"].numpy(), atol=1e-2)
    t = b["targets"].numpy()
    np.testing.assert_allclose(t[:, :, 1], 0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(t[:, :, 8], axis=-1), 1, rtol=1e-5)
    ref = stored(h5file, "test", "targets/absolute_pose_loc")
    absolute = ClipDataset(h5file, "test", "lifting")[list(range(len(ds)))]
    np.testing.assert_array_equal(absolute["targets_m"].numpy(), ref)
    # hips-neck scale is a length: the same in every frame of reference
    np.testing.assert_allclose(absolute["target_scale"].numpy(), b["target_scale"].numpy(),
                               rtol=1e-4)


def test_pose_estimation_reads_the_right_frames_and_crop_coordinates(h5file):
    ds = ClipDataset(h5file, "train", "pose_estimation", with_mask=True)
    rows = [3, 1, 2, 40]  # overlapping clips share frames: read once, gathered twice
    b = ds[rows]
    frames = stored(h5file, "train", "clip_frames", rows)
    np.testing.assert_array_equal(b["inputs"][:, :, 0, 0, 0].numpy(), frames % 256)
    np.testing.assert_array_equal(b["inputs"][0, 0, 1, 0].numpy(), np.arange(S))  # G = column
    box = stored(h5file, "train", "frames/crop_box")[frames]
    px = stored(h5file, "train", "projection_2d", rows)
    want = (px - box[..., None, :2]) / (box[..., None, 2:] - box[..., None, :2]) * S
    np.testing.assert_allclose(b["targets"].numpy(), want, rtol=1e-5, atol=1e-4)
    vis = stored(h5file, "train", "frames/joint_visible")[frames] != 0
    np.testing.assert_array_equal(b["visible"].numpy(), vis)
    assert b["mask"].shape == (4, L, S, S) and set(np.unique(b["mask"].numpy())) == {0, 4}


def test_autoencoder_targets_stay_clean_and_inputs_are_deformed(h5file):
    ds = ClipDataset(h5file, "val", "autoencoder", noise=5.0, mjp=0.3)
    b = ds[list(range(len(ds)))]
    clean = normalize_hips_neck(stored(h5file, "val", "projection_2d"))
    np.testing.assert_allclose(b["targets"].numpy(), clean.points, rtol=1e-6)
    missing = ~b["visible"].numpy()
    assert abs(missing.mean() - 0.3) < 0.03
    np.testing.assert_array_equal(b["inputs"].numpy()[missing], 0)
    assert not np.allclose(b["inputs"].numpy(), b["targets"].numpy(), atol=1e-3)


def test_missing_joint_ratio_of_dataset_inputs(h5file):
    for p in (0.2944, 0.7187):
        ds = ClipDataset(h5file, "train", "classification", mjp=p, augment=False)
        vis = ds[list(range(len(ds)))]["visible"].numpy()
        assert abs((~vis).mean() - p) < 0.02, p  # 96*8*26 = 19968 draws


def collect_inputs(loader):
    out = {}
    for batch in loader:
        for i, x in zip(batch["meta"]["index"].tolist(), batch["inputs"]):
            out[i] = x.clone()
    return out


def test_val_inputs_identical_across_epochs_train_inputs_differ(h5file):
    val = ClipDataset(h5file, "val", "classification", noise=5.0, mjp=0.2944)
    loader = val.loader(batch_size=10)
    e1, e2 = collect_inputs(loader), collect_inputs(loader)
    assert all(torch.equal(e1[i], e2[i]) for i in e1)
    again = ClipDataset(h5file, "val", "classification", noise=5.0, mjp=0.2944).loader(10)
    e3 = collect_inputs(again)  # a new dataset object: same fixed-seed inputs
    assert all(torch.equal(e1[i], e3[i]) for i in e1)
    train = ClipDataset(h5file, "train", "classification", noise=5.0, mjp=0.2944, augment=False)
    tl = train.loader(batch_size=10)
    t1, t2 = collect_inputs(tl), collect_inputs(tl)
    assert sum(torch.equal(t1[i], t2[i]) for i in t1) == 0
    seeded = ClipDataset(h5file, "train", "classification", noise=5.0, seed=7, augment=False)
    s1 = collect_inputs(seeded.loader(10, shuffle=False))
    s2 = collect_inputs(seeded.loader(10, shuffle=False))  # a new sampler starts at epoch 0
    assert all(torch.equal(s1[i], s2[i]) for i in s1)
    sl = seeded.loader(10, shuffle=False)
    s3, s4 = collect_inputs(sl), collect_inputs(sl)  # epochs 0 and 1 of one sampler differ
    assert all(torch.equal(s1[i], s3[i]) for i in s1)
    assert sum(torch.equal(s3[i], s4[i]) for i in s3) == 0


def test_train_augmentation_flips_and_rotates_2d_tasks_only(h5file):
    ds = ClipDataset(h5file, "train", "classification", rotation=0.0, flip_p=1.0, with_pixels=True)
    b = ds[[0, 1]]
    px = stored(h5file, "train", "projection_2d", [0, 1])
    np.testing.assert_allclose(b["pixels"].numpy(), flip_horizontal(px, 1600), atol=1e-4)
    assert ClipDataset(h5file, "val", "classification").augment is False
    assert ClipDataset(h5file, "train", "lifting").augment is False
    with pytest.raises(ValueError, match="2D tasks"):
        ClipDataset(h5file, "train", "lifting", augment=True)


def test_two_worker_loader_yields_every_clip_exactly_once_per_epoch(h5file):
    ds = ClipDataset(h5file, "train", "autoencoder", noise=5.0, mjp=0.1)
    loader = ds.loader(batch_size=7, num_workers=2, block_size=4)
    ds[0]  # the parent opened the file: it must be closed before the workers fork
    orders = []
    for _ in range(2):
        seen = [i for b in loader for i in b["meta"]["index"].tolist()]
        assert sorted(seen) == list(range(len(ds)))
        orders.append(seen)
    assert orders[0] != orders[1]  # reshuffled per epoch


def test_sampler_blocks_are_contiguous_and_cover_everything():
    s = ContiguousBatchSampler(100, 20, shuffle=True, block_size=5, seed=3)
    batches = list(s)
    assert all(isinstance(b, IndexBatch) and b.epoch == 0 for b in batches)
    flat = [i for b in batches for i in b]
    assert sorted(flat) == list(range(100))
    runs = sum(1 + int(np.count_nonzero(np.diff(b) != 1)) for b in batches)
    assert runs <= len(batches) * 5  # at most batch/block (+1 for the offset) runs each
    assert [b.epoch for b in s][0] == 1
    s.set_epoch(0)
    assert [list(b) for b in s] == [list(b) for b in batches]
    assert len(ContiguousBatchSampler(10, 3, drop_last=True)) == 3
    assert [list(b) for b in ContiguousBatchSampler(5, 2)] == [[0, 1], [2, 3], [4]]


def test_balance_and_indices(h5file):
    ds = ClipDataset(h5file, "train", "classification", balance=True)
    n0, n1 = ds.class_counts
    labels = stored(h5file, "train", "labels")
    assert n0 == n1 == np.bincount(labels).min()
    first = np.flatnonzero(labels == 1)[:n1]
    np.testing.assert_array_equal(np.sort(ds._rows[ds.labels == 1]), first)
    sub = ClipDataset(h5file, "train", "classification", indices=[4, 9])
    assert len(sub) == 2 and sub[1]["meta"]["row"].item() == 9


def test_bad_options_and_files(h5file, tmp_path):
    with pytest.raises(ValueError, match="task must be one of"):
        ClipDataset(h5file, "train", "detection")
    with pytest.raises(ValueError, match="split must be one of"):
        ClipDataset(h5file, "dev")
    with pytest.raises(ValueError, match="pose_estimation inputs are images"):
        ClipDataset(h5file, "train", "pose_estimation", noise=5.0)
    plain = tmp_path / "plain.h5"
    write_clip_file(plain, clips=(8, 4, 4), clip_length=4)
    with pytest.raises(ValueError, match="frames/rgb.*convert with media=True"):
        ClipDataset(plain, "train", "pose_estimation")
    with h5py.File(plain, "a") as f:
        f.attrs["schema_version"] = 2
    with pytest.raises(ValueError, match="schema_version 2"):
        ClipDataset(plain, "train")
    ds = ClipDataset(h5file, "val")
    with pytest.raises(IndexError):
        ds[[len(ds)]]
    assert ds[-1]["meta"]["index"].item() == len(ds) - 1


@pytest.mark.parametrize("task", ["lifting", "pose_estimation"])
def test_worker_batches_equal_in_process_batches(h5file, task):
    """Batches leave the workers packed in one shared buffer: same keys, dtypes, values."""
    kw = dict(noise=5.0, mjp=0.2) if task == "lifting" else dict(with_mask=True)
    ds = ClipDataset(h5file, "val", task, **kw)
    for batch in ds.loader(batch_size=5, num_workers=2):
        ref = ds[batch["meta"]["index"].tolist()]
        assert type(batch) is dict and set(batch) == set(ref)
        for key in ref:
            if key == "meta":
                assert set(batch["meta"]) == set(ref["meta"])
                for k, v in ref["meta"].items():
                    got = batch["meta"][k]
                    assert got == v if isinstance(v, list) else torch.equal(got, v), k
            else:
                assert batch[key].dtype == ref[key].dtype, key
                assert torch.equal(batch[key], ref[key]), key


def test_balancing_a_split_without_one_class_leaves_it_empty(h5file):
    rows = np.flatnonzero(stored(h5file, "train", "labels") == 0)[:5]
    with pytest.warns(UserWarning, match="balancing leaves no clip"):
        ds = ClipDataset(h5file, "train", "classification", indices=rows, balance=True)
    assert len(ds) == 0 and list(ds.loader(4)) == []


def test_worker_batches_travel_in_the_pre_fork_arena(h5file, monkeypatch):
    from bsp_fast.data import transport

    monkeypatch.setattr(transport, "_mapped", {})
    ds = ClipDataset(h5file, "val", "autoencoder", noise=5.0, mjp=0.2)
    loader = ds.loader(batch_size=1, num_workers=2)  # 12 batches per worker > slots
    for _ in range(2):
        for batch in loader:
            ref = ds[batch["meta"]["index"].tolist()]
            assert all(torch.equal(batch[k], ref[k]) for k in ref if k != "meta")
            assert len(transport._arenas) >= 1
    assert transport._mapped == {}  # no ring buffer, no file descriptor was passed
    arena = next(iter(transport._arenas.values()))
    assert arena.workers == 2 and arena.slots == 4
    assert all(arena.slot(k)[0] == 0 for k in range(8))  # every slot handed back
    del loader, batch
    import gc

    gc.collect()
    assert not transport._arenas  # freed with the loader's iterator
    # a slot too small for a batch: the per-worker ring takes over
    monkeypatch.setattr(ClipDataset, "_packed_bytes", lambda self, b: 64)
    seen = [i for b in ds.loader(batch_size=3, num_workers=1) for i in b["meta"]["index"].tolist()]
    assert seen == list(range(len(ds))) and len(transport._mapped) > 0


def test_packing_in_process_ring_and_one_off_buffers(monkeypatch):
    import pickle
    from multiprocessing.reduction import ForkingPickler

    from bsp_fast.data import transport

    monkeypatch.setattr(transport, "_ring", [])
    monkeypatch.setattr(transport, "_mapped", {})
    arrays = {"x": np.arange(12, dtype=np.float32).reshape(3, 4), "m": np.array([True, False])}
    packed = [transport.pack_batch(arrays, {"i": np.arange(3)}, {"s": ["a", "b", "c"]})
              for _ in range(transport.RING_SLOTS + 2)]
    keys = [p.slot[2] for p in packed]
    assert all(k is not None for k in keys[:transport.RING_SLOTS])
    assert keys[transport.RING_SLOTS:] == [None, None]  # every ring slot in flight
    batches = [pickle.loads(ForkingPickler.dumps(p)) for p in packed]
    for b in batches:
        np.testing.assert_array_equal(b["x"].numpy(), arrays["x"])
        assert b["m"].dtype == torch.bool and b["m"].tolist() == [True, False]
        assert b["meta"]["i"].tolist() == [0, 1, 2] and b["meta"]["s"] == ["a", "b", "c"]
    again = transport.pack_batch(arrays, {}, {})  # received batches freed their slots
    assert again.slot[2] == keys[0] and again.slot[3]  # reused; sent as a key only
    b = pickle.loads(ForkingPickler.dumps(again))
    np.testing.assert_array_equal(b["x"].numpy(), arrays["x"])


def test_one_public_name_for_datasets():
    import importlib

    import bsp_fast.data as data

    assert data.ClipDataset.__module__ == "bsp_fast.data.datasets"
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("bsp_fast.loaders")


def test_package_data_lives_in_resources():
    from importlib import resources

    from bsp_fast import skeleton

    folder = resources.files("bsp_fast").joinpath("resources", "carla_skeleton")
    assert folder.joinpath("structure.yaml").is_file()
    assert skeleton.reference_pose(skeleton.model_name("adult", "female")).shape[0] == 26


def test_zero_copy_crops_stay_valid_while_held_and_free_their_slot(h5file):
    import gc

    from bsp_fast.data import transport

    ds = ClipDataset(h5file, "train", "pose_estimation")  # 16 x 8 x 32 x 32 x 3 > 256 KB
    loader = ds.loader(batch_size=16, num_workers=1, shuffle=False)
    kept = list(loader)  # every batch held at once
    assert len(kept) > 4  # more batches than the worker's arena slots
    for b in kept:  # nothing was overwritten while held
        assert torch.equal(b["inputs"], ds[b["meta"]["index"].tolist()]["inputs"])
    arena = max(transport._arenas.values(), key=lambda a: a.id[1])
    busy = sum(arena.slot(k)[0] for k in range(arena.slots))
    assert busy > 0  # slots still lent out to the held batches
    del kept, b
    gc.collect()
    assert all(arena.slot(k)[0] == 0 for k in range(arena.slots))
