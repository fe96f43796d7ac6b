"""The crop-box policy of bsp-convert (#27): mask boxes by default, the union with the joint
box only when asked for, no crop for frames without a pedestrian pixel, the policy in the
file and in the cache check."""
import json
import shutil

import h5py
import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast import conversion as cv
from bsp_fast.data import cache

SPLITS = ("train", "val", "test")


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    """``bsp-synth --preset sample --seed 5`` (docs/synth.md): 20 clips, 640x240."""
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("crop") / "ds"
    generate(out, "sample", seed=5, workers=1, progress=False)
    return out


@pytest.fixture(scope="module")
def default_file(sample, tmp_path_factory):
    out = tmp_path_factory.mktemp("conv") / "mask.h5"
    with pytest.warns(UserWarning):  # the sample's test split has one class
        return cv.convert(sample, out, threads=2)


def test_frame_media_mask_box_only_or_the_union_by_hand():
    """Mask [50, 90) x [10, 80) (40 x 70 px), every joint at (40, 40): left of the mask."""
    tags = np.full((100, 200), 7, np.uint8)
    tags[10:80, 50:90] = 4
    uv = np.full((26, 2), 40.0, np.float32)
    # mask: side ceil(1.2 * 70) = 84 around the mask's centre (70, 45): corner (28, 3)
    assert cv.frame_media(tags, uv)["crop_box"].tolist() == [28, 3, 112, 87]
    assert cv.frame_media(tags, uv, "mask")["crop_box"].tolist() == [28, 3, 112, 87]
    # union u 40..90, v 10..80 (50 x 70): side 84 around (65, 45): corner (23, 3)
    assert cv.frame_media(tags, uv, "mask+joints")["crop_box"].tolist() == [23, 3, 107, 87]
    # the joint box alone is a point: the 32 px minimum around (40, 40)
    assert cv.frame_media(tags, uv, "joints")["crop_box"].tolist() == [24, 24, 56, 56]
    none = cv.frame_media(np.zeros((100, 200), np.uint8), uv)
    assert np.isnan(none["crop_box"]).all() and none["visible_pixels"] == 0
    with pytest.raises(ValueError, match="mask, mask\\+joints, joints"):
        cv.frame_media(tags, uv, "union")
    # the context box: 84 * 1.25 = 105 px, corner moved by floor(21 / 2) = 10
    assert cv.context_box([28, 3, 112, 87], 1.25).tolist() == [18, -7, 123, 98]


def test_default_crops_are_centred_on_the_mask_box_and_cover_it(default_file):
    """With the default conversion every crop of a frame with pedestrian pixels is centred
    on the mask box (to the half pixel of the integer corner) and covers it; frames
    without one have no crop, are stored as zeros and counted as fully occluded."""
    path = default_file["output"]
    occluded = default_file["media"]["fully_occluded"]
    with h5py.File(path, "r") as f:
        assert f.attrs["crop_box"] == "mask"
        assert json.loads(f.attrs["settings_json"])["crop_box"] == "mask"
        total = 0
        for s in SPLITS:
            g = f[s]
            box, bbox = g["frames/crop_box"][()], g["frames/mask_bbox"][()]
            pixels = g["frames/visible_pixels"][()]
            seen = pixels > 0
            assert occluded[s] == g.attrs["fully_occluded_frames"] == int((~seen).sum())
            assert np.isnan(box[~seen]).all() and np.isfinite(box[seen]).all()
            assert not g["frames/rgb"][()][~seen].any()
            centre = (box[seen, :2] + box[seen, 2:]) / 2
            mask_centre = (bbox[seen, :2] + bbox[seen, 2:]) / 2
            assert np.abs(centre - mask_centre).max() <= 0.5
            assert (box[seen, :2] <= bbox[seen, :2]).all() and (box[seen, 2:] >= bbox[seen, 2:]).all()
            total += int((~seen).sum())
    assert total > 0  # the sample has fully occluded frames: this test sees them
    text = cv.format_report(default_file)
    assert f"{total} frames without a pedestrian pixel" in text and "no crop" in text


def test_moving_the_poses_in_data_csv_moves_no_mask_crop(sample, default_file, tmp_path):
    """The crops come from the segmentation alone: shifting every pose column (2D by
    25 px, 3D by 0.3 m) leaves each crop box and crop as it was; under mask+joints the
    same change moves crops (the test can tell)."""
    moved = tmp_path / "moved"
    shutil.copytree(sample, moved)
    t = bf.read_csv(moved / "data.csv")
    t["frame.pedestrian.pose.camera"][...] += 25.0
    for k in ("frame.pedestrian.pose.world", "frame.pedestrian.pose.component"):
        t[k][..., :3] += 0.3
    bf.write_csv(moved / "data.csv", t)
    kw = dict(threads=2, strict=False)
    with pytest.warns(UserWarning):
        a = cv.convert(moved, tmp_path / "a.h5", **kw)["output"]
        union = cv.convert(sample, tmp_path / "u.h5", crop_box="mask+joints", **kw)["output"]
        union_moved = cv.convert(moved, tmp_path / "um.h5", crop_box="mask+joints", **kw)["output"]
    base, after = frames_by_key(default_file["output"]), frames_by_key(a)
    common = sorted(set(base) & set(after))
    assert len(common) > 500  # the in-image filter sees the moved 2D poses: most frames stay
    for k in common:
        np.testing.assert_array_equal(base[k][0], after[k][0])
        np.testing.assert_array_equal(base[k][1], after[k][1])
    u, um = frames_by_key(union), frames_by_key(union_moved)
    assert any(not np.array_equal(u[k][0], um[k][0]) for k in set(u) & set(um))


def frames_by_key(path):
    """{(split, video_id, frame.idx): (crop_box, rgb)} of a converted file."""
    out = {}
    with h5py.File(path, "r") as f:
        for s in SPLITS:
            g = f[s]
            box, rgb, fidx = g["frames/crop_box"][()], g["frames/rgb"][()], g["frames/frame_idx"][()]
            for vid, rows in zip(g["meta/video_id"].asstr()[()], g["clip_frames"][()]):
                for r in rows:
                    out[(vid, int(fidx[r]))] = (box[r], rgb[r])
    return out


def test_policy_round_trip_and_refusal_names_the_option(sample, default_file, tmp_path):
    out = tmp_path / "union.h5"
    with pytest.warns(UserWarning):
        r = cv.convert(sample, out, threads=2, crop_box="mask+joints", crop_context=1.25)
    with h5py.File(out) as f:
        assert f.attrs["crop_box"] == "mask+joints" and f.attrs["crop_context"] == 1.25
        assert cache.file_crop_box(f.attrs) == "mask+joints"
        settings = json.loads(f.attrs["settings_json"])
        assert (settings["crop_box"], settings["crop_context"]) == ("mask+joints", 1.25)
        # frames without a pedestrian pixel still get the joints' crop under mask+joints
        assert np.isfinite(f["test/frames/crop_box"][()]).all()
        side = f["test/frames/context_box"][()] @ [-1, 0, 1, 0]
        np.testing.assert_array_equal(side, np.ceil(1.25 * (f["test/frames/crop_box"][()] @ [-1, 0, 1, 0])))
        assert f["test/frames/context_rgb"].shape[1:] == (160, 160, 3)
    assert r["media"]["fully_occluded"] == default_file["media"]["fully_occluded"]
    csv = sample / "data.csv"
    why = cache.stale_reason(out, cv.conversion_settings(sample), csv)
    assert "--crop-box mask vs mask+joints in the file" in why
    assert cache.stale_reason(default_file["output"], cv.conversion_settings(sample), csv) is None
    from bsp_fast.data import BSPDataModule

    dm = BSPDataModule(h5_path=out, task="pose_estimation", verbose=False,
                       convert_options={"crop_box": "mask"})
    with pytest.raises(ValueError, match="--crop-box mask vs mask\\+joints in the file"):
        dm.setup("test")
    dm = BSPDataModule(sample, h5_path=out, task="pose_estimation", verbose=False)
    with pytest.raises(ValueError, match="--crop-box mask vs mask\\+joints in the file"):
        dm.prepare_data()
    with pytest.raises(SystemExit) as exit_:  # argparse: exit 2 listing the choices
        cv.main([str(sample), str(tmp_path / "x.h5"), "--crop-box", "union", "--quiet"])
    assert exit_.value.code == 2
    with pytest.raises(ValueError, match="crop_context"):
        cv.convert(sample, tmp_path / "y.h5", crop_context=0.5)


def test_pose_estimation_table_refuses_a_file_of_another_policy(sample, default_file, tmp_path):
    """Every row of the pose-estimation table reads mask-box crops; a mask+joints file is
    refused with a message naming both policies, except for the row that asks for it."""
    from bsp_fast.reproduction import run_table as reproduce

    union = tmp_path / "union.h5"
    with pytest.warns(UserWarning):
        cv.convert(sample, union, threads=2, crop_box="mask+joints")
    out = tmp_path / "runs"
    with pytest.raises(ValueError, match=r"converted with --crop-box mask\+joints, but table "
                       "'pose_estimation' row 'pose_cnn' needs --crop-box mask"):
        reproduce("pose_estimation", union, "smoke", out, rows=["pose_cnn"], dry_run=True,
                  log=lambda *a: None)
    reproduce("pose_estimation", union, "smoke", out, rows=["pose_cnn_mask_joints"],
              dry_run=True, log=lambda *a: None)
    reproduce("pose_estimation", default_file["output"], "smoke", out, rows=["pose_cnn"],
              dry_run=True, log=lambda *a: None)
    with pytest.raises(ValueError, match=r"needs --crop-box mask\+joints"):
        reproduce("pose_estimation", default_file["output"], "smoke", out,
                  rows=["pose_cnn_mask_joints"], dry_run=True, log=lambda *a: None)
