"""Pose estimation: single-frame dataset, float/mean/std crops, augmentation that keeps the
joints on the pixels they belong to."""
import h5py
import numpy as np
import pytest
import torch

from bsp_fast.data import ClipDataset, FrameDataset, ImageAugment
from bsp_fast.data.testing import write_clip_file
from bsp_fast.skeleton import FLIP_PERMUTATION

L, S = 6, 32
FLIP = list(FLIP_PERMUTATION)
CLEAN = dict(image_scale=0.0, image_shift=0.0, color_jitter=0.0)


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("pose") / "clips.h5"
    write_clip_file(path, clips=(24, 8, 8), clip_length=L, clip_offset=3, media=True,
                    crop_size=S)
    return path


def _stored(path, split):
    with h5py.File(path) as f:
        g = f[split]
        return {k: g[k][()] for k in ("clip_frames", "projection_2d", "frames/rgb",
                                      "frames/crop_box", "frames/joint_visible", "frames/mask")}


def test_frame_dataset_items_are_the_used_frames_with_their_joints(h5file):
    st = _stored(h5file, "val")
    ds = FrameDataset(h5file, "val", with_mask=True)
    used = np.unique(st["clip_frames"])
    assert len(ds) == len(used) and not ds.augment
    b = ds[list(range(len(ds)))]
    f = b["meta"]["frame"].numpy()
    np.testing.assert_array_equal(f, used)
    assert b["inputs"].shape == (len(ds), 3, S, S) and b["inputs"].dtype == torch.uint8
    np.testing.assert_array_equal(b["inputs"].numpy(), st["frames/rgb"][f].transpose(0, 3, 1, 2))
    clip, at = b["meta"]["clip_row"].numpy(), b["meta"]["clip_frame"].numpy()
    assert (st["clip_frames"][clip, at] == f).all()
    uv, box = st["projection_2d"][clip, at], st["frames/crop_box"][f]
    want = (uv - box[:, None, :2]) * S / (box[:, None, 2:] - box[:, None, :2])
    np.testing.assert_allclose(b["targets"].numpy(), want, rtol=1e-5, atol=1e-4)
    np.testing.assert_array_equal(b["visible"].numpy(), st["frames/joint_visible"][f] != 0)
    np.testing.assert_array_equal(b["mask"].numpy(), st["frames/mask"][f])
    one = ds[3]
    assert one["inputs"].shape == (3, S, S) and one["targets"].shape == (26, 2)
    assert FrameDataset(h5file, "train").augment  # train augments by default
    loader = FrameDataset(h5file, "train").loader(5, num_workers=1)
    assert sum(len(x["meta"]["frame"]) for x in loader) == len(FrameDataset(h5file, "train"))


def test_float_images_with_mean_and_std(h5file):
    st = _stored(h5file, "val")
    mean, std = (0.5, 0.4, 0.3), (0.2, 0.25, 0.5)
    clips = ClipDataset(h5file, "val", "pose_estimation", image_dtype="float32", mean=mean,
                        std=std)[[0, 2]]
    rgb = st["frames/rgb"][st["clip_frames"][[0, 2]]].transpose(0, 1, 4, 2, 3) / 255.0
    want = (rgb - np.array(mean)[:, None, None]) / np.array(std)[:, None, None]
    assert clips["inputs"].dtype == torch.float32
    np.testing.assert_allclose(clips["inputs"].numpy(), want, atol=1e-5)
    frames = FrameDataset(h5file, "val", image_dtype="float32")[[0]]
    assert frames["inputs"].dtype == torch.float32 and frames["inputs"].max() <= 1.0
    with pytest.raises(ValueError, match="image_dtype must be one of"):
        FrameDataset(h5file, "val", image_dtype="float16")
    with pytest.raises(ValueError, match="mean and std go together"):
        ClipDataset(h5file, "val", "pose_estimation", mean=(0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="pose_estimation crops only"):
        ClipDataset(h5file, "val", "lifting", image_dtype="float32")


def test_flip_mirrors_pixels_joints_visibility_and_masks_per_clip(h5file):
    st = _stored(h5file, "train")
    ds = ClipDataset(h5file, "train", "pose_estimation", augment=True, flip_p=1.0,
                     with_mask=True, **CLEAN)
    plain = ClipDataset(h5file, "train", "pose_estimation", with_mask=True)
    b, ref = ds[[1, 4]], plain[[1, 4]]
    np.testing.assert_array_equal(b["inputs"].numpy(), ref["inputs"].numpy()[..., ::-1])
    np.testing.assert_array_equal(b["mask"].numpy(), ref["mask"].numpy()[..., ::-1])
    t = ref["targets"].numpy()[:, :, FLIP]
    t[..., 0] = S - t[..., 0]
    np.testing.assert_allclose(b["targets"].numpy(), t, atol=1e-4)
    inside = np.all((t >= 0) & (t <= S), -1)
    np.testing.assert_array_equal(b["visible"].numpy(), ref["visible"].numpy()[:, :, FLIP] & inside)
    assert st["frames/rgb"].shape[1] == S
    with pytest.raises(ValueError, match="2D tasks"):
        ClipDataset(h5file, "train", "lifting", augment=True)


def test_zoom_shift_and_flip_keep_joints_on_their_pixels():
    rng = np.random.default_rng(0)
    N, K, J, size = 8, 2, 26, 64
    marked = (4, 5, 12, 13)  # left and right arm joints: a flip swaps their slots
    joints = rng.uniform(16, 48, (N, K, J, 2)).astype(np.float32)
    img = np.zeros((N, K, size, size, 3), np.uint8)
    for n, k in np.ndindex(N, K):  # each marked joint: a bright 5x5 square in one channel
        for c, j in enumerate(marked):
            u, v = joints[n, k, j].astype(int)
            img[n, k, v - 2:v + 3, u - 2:u + 3, c % 3] = 255
            joints[n, k, j] = (u + 0.5, v + 0.5)  # the square's centre
    aug = ImageAugment(flip_p=0.5, scale=0.2, shift=0.1, color_jitter=0.0)
    out, j2, vis, _ = aug(img, joints, np.ones((N, K, J), bool), rng=np.random.default_rng(1))
    flipped = np.random.default_rng(1).random(N) < 0.5  # the first draw: one flip per clip
    assert out.shape == (N, K, 3, size, size) and 0 < flipped.sum() < N
    checked = 0
    for n, k in np.ndindex(N, K):
        for c, j in enumerate(marked):
            slot = FLIP.index(j) if flipped[n] else j  # output joint i takes input FLIP[i]
            u, v = np.floor(j2[n, k, slot]).astype(int)
            if vis[n, k, slot]:
                assert out[n, k, c % 3, v, u] > 200, (n, k, j)
                checked += 1
    assert checked > 0.8 * N * K * len(marked)


def test_color_jitter_changes_pixels_not_joints():
    rng = np.random.default_rng(2)
    img = rng.integers(0, 256, (3, 1, 16, 16, 3), dtype=np.uint8)
    joints = rng.uniform(0, 16, (3, 1, 26, 2)).astype(np.float32)
    aug = ImageAugment(flip_p=0.0, scale=0.0, shift=0.0, color_jitter=0.5)
    out, j2, _, _ = aug(img, joints, np.ones((3, 1, 26), bool), rng=rng)
    np.testing.assert_allclose(j2, joints, atol=1e-5)
    assert out.min() >= 0 and out.max() <= 255
    assert np.abs(out - img.transpose(0, 1, 4, 2, 3)).mean() > 5
