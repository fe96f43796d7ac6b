"""bsp-convert's media: crops, masks and visibility against independent decoders.

A bsp-synth dataset (3 recordings x 90 frames, 480x180, one APNG with dropped duplicate
frames) is generated once. Crops are checked against PyAV-decoded video frames and
Pillow-decoded APNG frames cut and resized in the test with opencv-python (cv2).
"""
import os
import shutil
import subprocess
import sys

import av
import cv2
import h5py
import numpy as np
import pytest
from PIL import Image

import bsp_fast as bf
from bsp_fast import conversion as cv
from bsp_testdata import corrupt_apng_frame, recording, write_dataset

S = 40
OPTS = dict(clip_length=8, clip_offset=4, crop_size=S, val_frac=0.3, test_frac=0.3)
SPLITS = ("train", "val", "test")


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("media") / "ds"
    generate(out, "sample", clips=3, frames=90, size="480x180", seed=2, workers=1,
             progress=False, apng_drop_duplicates=True)
    return out


@pytest.fixture(scope="module")
def converted(ds, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "clips.h5"
    return cv.convert(ds, out, threads=2, **OPTS)


def read_all(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o.asstr()[...] if o.dtype.kind == "O" else o[...])
                     if isinstance(o, h5py.Dataset) else None)
        out["attrs"] = dict(f.attrs)
    return out


def video_frames(path):
    with av.open(str(path)) as c:
        return np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])


def apng_for_video(path, n_video, fps=30.0):
    """Tags of the APNG frame on screen at each video frame time (Pillow decoder)."""
    im = Image.open(path)
    frames, starts, t = [], [], 0.0
    for i in range(im.n_frames):
        im.seek(i)
        assert im.mode == "P"
        frames.append(np.array(im))
        starts.append(t)
        t += im.info["duration"]
    idx = [max(j for j, s in enumerate(starts) if s <= 1000.0 * k / fps + 1e-6) for k in range(n_video)]
    return [frames[j] for j in idx]


def cut(img, box, size, interp):
    """Zero-padded square cut of `box` = [u0, v0, u1, v1] (integer edges), resized."""
    u0, v0, u1, v1 = (int(x) for x in box)
    canvas = np.zeros((v1 - v0, u1 - u0) + img.shape[2:], np.uint8)
    H, W = img.shape[:2]
    a, b, c, d = max(u0, 0), max(v0, 0), min(u1, W), min(v1, H)
    if c > a and d > b:
        canvas[b - v0:d - v0, a - u0:c - u0] = img[b:d, a:c]
    return cv2.resize(canvas, (size, size), interpolation=interp)


def expected_box(tags, uv, policy="mask"):
    """The crop box of docs/hdf5-schema.md: around the mask box (``mask``, the default; no
    pedestrian pixel: no crop, all NaN), the union with the joint box, or the joint box."""
    ys, xs = np.nonzero(tags == 4)
    if policy == "mask" and not len(xs):
        return np.full(4, np.nan)
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    if policy != "mask":
        lo, hi = uv.min(0).astype(np.float64), uv.max(0).astype(np.float64)
    if len(xs) and policy != "joints":
        lo = np.minimum(lo, [xs.min(), ys.min()])
        hi = np.maximum(hi, [xs.max() + 1, ys.max() + 1])
    side = max(32.0, np.ceil(1.2 * (hi - lo).max() - 1e-9))
    corner = np.floor((lo + hi) / 2 - side / 2 + 0.5)
    return np.concatenate([corner, corner + side])


def expected_visible(tags, uv, r=2):
    H, W = tags.shape
    out = np.zeros(26, np.uint8)
    for j, (u, v) in enumerate(uv):
        cu, cv_ = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                x, y = cu + dx, cv_ + dy
                if dx * dx + dy * dy <= r * r and 0 <= x < W and 0 <= y < H and tags[y, x] == 4:
                    out[j] = 1
    return out


def test_frame_table_layout_and_clip_frames(converted):
    d = read_all(converted["output"])
    assert d["attrs"]["media"] == 1 and d["attrs"]["crop_size"] == S
    with h5py.File(converted["output"]) as f:  # measured defaults: deflated masks, plain RGB
        assert f["train/frames/mask"].compression == "gzip" and f["train/frames/rgb"].compression is None
        assert f["train/frames/rgb"].chunks[0] == 16
    total = 0
    for s in SPLITS:
        cf, fidx = d[f"{s}/clip_frames"], d[f"{s}/frames/frame_idx"]
        F = len(fidx)
        assert converted["media"]["frames"][s] == F
        total += F
        assert d[f"{s}/frames/rgb"].shape == (F, S, S, 3) and d[f"{s}/frames/mask"].shape == (F, S, S)
        assert d[f"{s}/frames/joint_visible"].shape == (F, 26)
        # clip_frames point at the right frames, and each frame is stored once
        np.testing.assert_array_equal(fidx[cf], d[f"{s}/targets/frame_idx"])
        assert sorted(set(cf.ravel().tolist())) == list(range(F))
        vids = d[f"{s}/meta/video_id"]
        owner = np.empty(F, object)
        for i in range(len(cf)):
            owner[cf[i]] = vids[i]
        # one contiguous block per recording, frame.idx ascending inside it
        changes = [0] + [i for i in range(1, F) if owner[i] != owner[i - 1]]
        assert len(changes) == len(set(owner))
        for a, b in zip(changes, changes[1:] + [F]):
            assert np.all(np.diff(fidx[a:b]) > 0)
    # overlapping clips (offset 4 < L 8) share frames: fewer table rows than clip frames
    assert total < sum(d[f"{s}/clip_frames"].size for s in SPLITS)
    assert converted["media"]["crops_per_second"] > 0 and converted["media"]["bad"] == []


def test_crops_match_pyav_and_pillow(ds, converted):
    d = read_all(converted["output"])
    checked = 0
    for s in SPLITS:
        cf, fidx = d[f"{s}/clip_frames"], d[f"{s}/frames/frame_idx"]
        by_video = {}
        for i, vid in enumerate(d[f"{s}/meta/video_id"]):
            for t, row in enumerate(cf[i]):
                by_video.setdefault(vid, {})[int(row)] = d[f"{s}/projection_2d"][i, t]
        for vid, rows in by_video.items():
            rgb = video_frames(ds / f"{vid}.mp4")
            tags = apng_for_video(ds / (vid[:-2] + "-1.apng"), len(rgb))
            for row, uv in rows.items():
                k = fidx[row]
                box = d[f"{s}/frames/crop_box"][row]
                np.testing.assert_array_equal(box, expected_box(tags[k], uv))
                np.testing.assert_array_equal(d[f"{s}/frames/joint_visible"][row],
                                              expected_visible(tags[k], uv))
                ys, xs = np.nonzero(tags[k] == 4)
                assert d[f"{s}/frames/visible_pixels"][row] == len(xs)
                bbox = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1] if len(xs) else [-1] * 4
                np.testing.assert_array_equal(d[f"{s}/frames/mask_bbox"][row], bbox)
                checked += 1
                if not len(xs):  # fully occluded: no crop, zeros stored
                    assert not d[f"{s}/frames/rgb"][row].any() and not d[f"{s}/frames/mask"][row].any()
                    continue
                np.testing.assert_array_equal(d[f"{s}/frames/mask"][row],
                                              cut(tags[k], box, S, cv2.INTER_NEAREST))
                want = cut(rgb[k], box, S, cv2.INTER_AREA).astype(int)
                assert np.abs(d[f"{s}/frames/rgb"][row].astype(int) - want).max() <= 2, (vid, k)
    assert checked == sum(converted["media"]["frames"].values()) > 100


def test_identical_output_for_one_and_two_threads(ds, converted, tmp_path):
    a = read_all(converted["output"])
    b = read_all(cv.convert(ds, tmp_path / "one.h5", threads=1, **OPTS)["output"])
    assert a.keys() == b.keys()
    for k in a:
        if k != "attrs":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_no_media_writes_no_frame_table(ds, tmp_path):
    d = read_all(cv.convert(ds, tmp_path / "o.h5", media=False, **OPTS)["output"])
    assert d["attrs"]["media"] == 0
    assert not any(k.startswith(f"{s}/frames") or k == f"{s}/clip_frames" for k in d for s in SPLITS)


def copy_dataset(ds, tmp_path):
    return shutil.copytree(ds, tmp_path / "copy")


def first_video(converted):
    with h5py.File(converted["output"]) as f:
        for s in SPLITS:
            if f[f"{s}/clip_frames"].shape[0]:
                vid = f[f"{s}/meta/video_id"].asstr()[0]
                frames = f[f"{s}/targets/frame_idx"][...][f[f"{s}/meta/video_id"].asstr()[...] == vid]
                return vid, int(frames.max())
    raise AssertionError("no clips")


def test_missing_mp4_fails_with_its_path_or_is_skipped(ds, converted, tmp_path):
    copy = copy_dataset(ds, tmp_path)
    vid, _ = first_video(converted)
    mp4 = copy / f"{vid}.mp4"
    mp4.unlink()
    out = tmp_path / "o.h5"
    with pytest.raises(bf.Error, match=str(mp4)):
        cv.convert(copy, out, **OPTS)
    assert not out.exists() and not list(tmp_path.glob(".o.h5.tmp-*"))
    assert cv.main([str(copy), str(out), "--quiet", "--crop-size", str(S)]) == 1

    rep = cv.convert(copy, out, skip_bad_media=True, **OPTS)
    ((path, why),) = rep["media"]["bad"]
    assert path == str(mp4) and "No such file" in why and rep["media"]["passes"] == 1
    d = read_all(out)
    assert d["attrs"]["media_recordings_left_out"] == 1
    kept = set(np.concatenate([d[f"{s}/meta/video_id"] for s in SPLITS]))
    assert vid not in kept and len(kept) == 2  # re-planned without it
    for s in SPLITS:
        np.testing.assert_array_equal(d[f"{s}/frames/frame_idx"][d[f"{s}/clip_frames"]],
                                      d[f"{s}/targets/frame_idx"])
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "convert", str(copy), str(tmp_path / "c.h5"),
                        "--skip-bad-media", "--crop-size", "16", "--clip-length", "8"],
                       capture_output=True, text=True, env={**os.environ})
    assert p.returncode == 0, p.stderr
    assert "1 bad media files left out" in p.stdout and str(mp4) in p.stdout


def test_apng_damaged_mid_file_fails_or_is_left_out_after_a_second_pass(ds, converted, tmp_path):
    copy = copy_dataset(ds, tmp_path)
    vid, last = first_video(converted)
    apng = copy / (vid[:-2] + "-1.apng")
    assert Image.open(apng).n_frames == 90  # one APNG frame per video frame
    corrupt_apng_frame(apng, last)
    with pytest.raises(bf.ApngError, match=str(apng)):
        cv.convert(copy, tmp_path / "o.h5", **OPTS)
    rep = cv.convert(copy, tmp_path / "o.h5", skip_bad_media=True, **OPTS)
    ((path, why),) = rep["media"]["bad"]
    assert path == str(apng) and rep["media"]["passes"] == 2  # found while decoding
    d = read_all(rep["output"])
    assert vid not in set(np.concatenate([d[f"{s}/meta/video_id"] for s in SPLITS]))
    assert sum(rep["media"]["frames"].values()) == sum(len(d[f"{s}/frames/frame_idx"]) for s in SPLITS) > 0


U1 = "094b9fe1-babe-48d5-bd17-3ba3185690c5-0"


@pytest.mark.parametrize("column,path,reason", [
    ("camera.recording", "/etc/passwd", "absolute"),
    ("camera.recording", "clips/../../x.mp4", "'..'"),
    ("camera.semantic_segmentation", "../y.apng", "'..'"),
])
def test_unsafe_media_paths_are_refused(tmp_path, column, path, reason):
    rows = recording(U1, range(20))
    for r in rows:
        r[column] = path
    root = write_dataset(tmp_path / "ds", rows)
    with pytest.raises(bf.Error, match=f"data.csv:2: column {column}: media path .*{reason}.*refused"):
        cv.convert(root, tmp_path / "o.h5", clip_length=10)


def test_escaping_path_is_never_opened(tmp_path):
    # A FIFO blocks whoever opens it for reading: a converter that opened it would hang.
    os.mkfifo(tmp_path / "x.mp4")
    rows = recording(U1, range(20))
    for r in rows:
        r["camera.recording"] = "../x.mp4"
    root = write_dataset(tmp_path / "ds", rows)
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "convert", str(root), str(tmp_path / "o.h5"),
                        "--clip-length", "10", "--quiet"],
                       capture_output=True, text=True, env={**os.environ}, timeout=120)
    assert p.returncode == 1 and "../x.mp4" in p.stderr and "refused" in p.stderr


def test_frame_media_and_crop_resize_wrappers(ds, tmp_path):
    tags = np.full((16, 20), 7, np.uint8)
    tags[4:12, 5:9] = 4
    uv = np.full((26, 2), 6.0, np.float32)
    uv[1] = (10.4, 8)  # 2 px from the mask after rounding: visible
    uv[2] = (11, 8)    # 3 px: hidden
    m = cv.frame_media(tags, uv)
    assert m["mask_bbox"].tolist() == [5, 4, 9, 12] and m["visible_pixels"] == 32
    assert m["joint_visible"][:3].tolist() == [1, 1, 0]
    np.testing.assert_array_equal(m["crop_box"], expected_box(tags, uv))
    for policy in ("mask+joints", "joints"):
        np.testing.assert_array_equal(cv.frame_media(tags, uv, policy)["crop_box"],
                                      expected_box(tags, uv, policy))
    np.testing.assert_array_equal(m["joint_visible"], expected_visible(tags, uv))
    img = np.random.default_rng(0).integers(0, 255, (16, 20, 3), np.uint8)
    for interp, nearest in ((cv2.INTER_AREA, False), (cv2.INTER_NEAREST, True)):
        np.testing.assert_array_equal(cv.crop_resize(img, m["crop_box"], 24, nearest),
                                      cut(img, m["crop_box"], 24, interp))
    with pytest.raises(ValueError, match="crop_size"):
        cv.convert(ds, tmp_path / "x.h5", crop_size=4)
    assert cv.main([str(ds), str(tmp_path / "x.h5"), "--crop-size", "0", "--quiet"]) == 2
