"""bsp-preview on a generated sample: sizes, skeleton pixels on the projected joints,
segmentation colours, MP4 frame counts, the 3D and predictions views, exit codes."""
from __future__ import annotations

import re

import h5py
import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast.media import ApngReader, VideoReader
from bsp_fast.preview import (preview_clips, preview_frames, preview_pose3d,
                              preview_predictions)
from bsp_fast.preview.cli import main

# The documented colours (RGB): left blue, right orange, centre green; truth / prediction.
LEFT, RIGHT, CENTRE = (0, 170, 255), (255, 140, 0), (60, 230, 60)
TRUTH, PREDICTION = (60, 230, 60), (255, 0, 255)
CAPTION = 14  # caption bar height per text line
W, H = 640, 240


def side_colour(j: int):
    name = bf.skeleton.JOINT_NAMES[j]
    return LEFT if name.endswith("__L") else RIGHT if name.endswith("__R") else CENTRE


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    from bsp_fast.synth import generate

    root = tmp_path_factory.mktemp("preview")
    generate(root / "ds", "sample", workers=2, progress=False)
    bf.convert(root / "ds", root / "clips.h5", clip_length=10)
    return root


def _read(png):
    import cv2

    img = cv2.imread(str(png), cv2.IMREAD_COLOR)
    return img[..., ::-1]


def _separated(uv, far=5.0):
    """Joints at least `far` px from every other joint (their disc is theirs alone)."""
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1)
    d[np.arange(len(uv)), np.arange(len(uv))] = np.inf
    return [j for j in range(len(uv)) if d[j].min() >= far]


def _disc(img, x, y, colour) -> bool:
    """The joint's disc (radius 2) is centred on pixel (x, y): its centre and its four
    extreme pixels have the colour (a disc 1 px off leaves one extreme pixel out)."""
    return all(tuple(img[y + dy, x + dx]) == colour
               for dx, dy in ((0, 0), (-2, 0), (2, 0), (0, -2), (0, 2)))


def _best_frame(ds):
    """Row of recording 0 with the largest skeleton fully inside the image."""
    t = bf.read_csv(ds / "data.csv")
    rid = t["id"][0]
    rows = np.flatnonzero(t["id"] == rid)
    uv = t["frame.pedestrian.pose.camera"][rows]
    inside = ((uv >= 0) & (uv < [W, H])).all((1, 2))
    height = np.where(inside, np.ptp(uv[..., 1], axis=1), -1)
    return t, rows[int(np.argmax(height))]


def test_frames_png_skeleton_on_projected_joints(sample, tmp_path):
    t, row = _best_frame(sample / "ds")
    f = int(t["frame.idx"][row])
    out = tmp_path / "f.png"
    res = preview_frames(sample / "ds", 0, out, frames=f"{f},{f + 1}")
    img = _read(out)
    assert img.shape == (2 * (CAPTION + H) + 2, 2 * W, 3) and res["size"] == (2 * W, img.shape[0])
    # Independent projection of the world pose through the CSV's camera (fov 90).
    uv = bf.project(t["frame.pedestrian.pose.world"][row][:, :3], t["camera.transform"][row],
                    W, H, fov=90.0)
    assert np.abs(uv - t["frame.pedestrian.pose.camera"][row]).max() < 1e-2
    good = _separated(uv)
    sides = {side_colour(j) for j in good}
    assert len(good) >= 4 and LEFT in sides and RIGHT in sides, good
    for j in good:
        x, y = int(np.floor(uv[j, 0])), int(np.floor(uv[j, 1]))
        assert _disc(img[CAPTION:], x, y, side_colour(j)), bf.skeleton.JOINT_NAMES[j]
        assert _disc(img[CAPTION:, W:], x, y, side_colour(j))  # segmentation panel too
    # Away from the drawing: the RGB panel is the video frame, the other the Cityscapes
    # colours of the segmentation's tags.
    frame = VideoReader(sample / "ds" / t["camera.recording"][row]).read([f])[0]
    tags = ApngReader(sample / "ds" / t["camera.semantic_segmentation"][row])[f]
    assert np.array_equal(img[CAPTION, :W], frame[0])
    assert np.array_equal(img[CAPTION, W:], bf.media.CITYSCAPES_PALETTE[tags[0]])
    assert (tags[0] == 13).any() and tuple(img[CAPTION, W + np.argmax(tags[0] == 13)]) == \
        (70, 130, 180)  # sky


def test_frames_mp4_and_layouts(sample, tmp_path):
    out = tmp_path / "f.mp4"
    res = preview_frames(sample / "ds", 1, out, frames="0:30:3")
    r = VideoReader(out)
    assert len(r) == 10 == res["frames"] and r.size == (2 * W, CAPTION + H)
    blend = preview_frames(sample / "ds", 1, None, frames="5", layout="blend", scale=0.5)
    assert blend["images"][0].shape == (CAPTION + H // 2, W // 2, 3)
    rgb = preview_frames(sample / "ds", 1, tmp_path / "r.png", frames="5,6,7,8", layout="rgb",
                         cols=2)
    assert rgb["size"] == (2 * W + 2, 2 * (CAPTION + H) + 2)
    with pytest.raises(ValueError, match="layout must be one of side, blend, rgb"):
        preview_frames(sample / "ds", 1, None, layout="mosaic")


def test_clips_sheet_crops_with_skeleton(sample, tmp_path):
    out = tmp_path / "c.png"
    res = preview_clips(sample / "clips.h5", out, n=5, size=96, cols=3, frame="first")
    img = _read(out)
    assert img.shape == (2 * (3 * CAPTION + 96) + 2, 3 * 96 + 2 * 2, 3) and res["media"]
    with h5py.File(sample / "clips.h5", "r") as f:
        g = f["train"]
        ok = 0
        for i in range(5):
            row = g["clip_frames"][i, 0]
            u0, v0, u1, v1 = g["frames/crop_box"][row]
            vis = g["frames/joint_visible"][row]
            p = (g["projection_2d"][i, 0] - [u0, v0]) * (96 / (u1 - u0))
            c, r = i % 3, i // 3
            for j in _separated(p):
                if not vis[j]:
                    continue
                x, y = int(np.floor(p[j, 0])), int(np.floor(p[j, 1]))
                panel = img[r * (3 * CAPTION + 96 + 2) + 3 * CAPTION:, c * 98:]
                assert _disc(panel, x, y, side_colour(j))
                ok += 1
    assert ok >= 10
    sheet = preview_clips(sample / "clips.h5", tmp_path / "c.mp4", split="val", n=4, size=64)
    assert len(VideoReader(tmp_path / "c.mp4")) == 10 == sheet["frames"]


def test_pose3d_png_and_mp4(sample, tmp_path):
    res = preview_pose3d(sample / "clips.h5", 0, tmp_path / "p.png", size="600x300")
    img = _read(tmp_path / "p.png")
    assert img.shape == (300, 600, 3) and res["size"] == (600, 300)
    for colour in (LEFT, RIGHT, CENTRE):  # bones in the side colours (antialiased lines)
        assert (np.abs(img.astype(int) - colour).max(-1) < 40).sum() > 20
    preview_pose3d(sample / "clips.h5", 1, tmp_path / "p.mp4", split="test", space="world")
    assert len(VideoReader(tmp_path / "p.mp4")) == 10
    assert VideoReader(tmp_path / "p.mp4").size == (800, 400)


def _write_preds(path, task, pred, target, units):
    with h5py.File(path, "w") as f:
        f.attrs.update(task=task, units=units)
        names = {"autoencoder": ("pixels", "target_pixels"),
                 "lifting": ("metres_aligned", "target_metres")}.get(task, ("a", "b"))
        f[names[0]], f[names[1]] = pred, target
        f["label"] = np.arange(len(pred)) % 2
        f["clip_id"] = np.arange(len(pred))
        f["video_id"] = np.array([f"clips/{k:08d}-0-0" for k in range(len(pred))],
                                 dtype=h5py.string_dtype())


def test_predictions_2d_and_3d(sample, tmp_path):
    with h5py.File(sample / "clips.h5", "r") as f:
        gt2 = f["test/projection_2d"][:3].astype(np.float32)
        gt3 = f["test/targets/absolute_pose_loc"][:2]
    p2 = tmp_path / "ae.h5"
    _write_preds(p2, "autoencoder", gt2 + 6.0, gt2, "pixels")
    res = preview_predictions(p2, tmp_path / "ae.png", size=100, cols=3)
    img = _read(tmp_path / "ae.png")
    assert img.shape == (3 * CAPTION + 100, 3 * 100 + 2 * 2, 3)
    assert res["datasets"] == ["pixels", "target_pixels"]
    for colour in (TRUTH, PREDICTION):
        assert (img == colour).all(-1).sum() > 30
    p3 = tmp_path / "lift.h5"
    _write_preds(p3, "lifting", gt3 + 0.05, gt3, "metres")
    out = preview_predictions(p3, tmp_path / "lift.mp4", clip=1)
    assert out["frames"] == 10 and len(VideoReader(tmp_path / "lift.mp4")) == 10
    bad = tmp_path / "cls.h5"
    with h5py.File(bad, "w") as f:
        f.attrs["task"] = "classification"
    assert main(["predictions", str(bad), "--out", str(tmp_path / "x.png")]) == 2
    wrong = tmp_path / "wrong.h5"
    _write_preds(wrong, "pose_estimation", gt2, gt2, "pixels")
    with pytest.raises(ValueError, match="needs datasets crop_pixels \\+ target_crop_pixels"):
        preview_predictions(wrong)


def test_cli_exit_codes(sample, tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["frames", str(sample / "ds"), "--recording", "0", "--out", str(out),
                 "--frames", "10"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["frames", str(sample / "ds"), "--recording", "0", "--out", str(out)]) == 3
    assert "exists" in capsys.readouterr().err
    assert main(["frames", str(sample / "ds"), "--recording", "nope", "--out",
                 str(tmp_path / "y.png")]) == 2
    assert "is not an id" in capsys.readouterr().err
    assert main(["clips", str(sample / "clips.h5"), "--out", str(tmp_path / "y.gif")]) == 2
    assert main(["pose3d", str(sample / "clips.h5"), "--clip", "9999", "--out",
                 str(tmp_path / "y.png")]) == 2
    for argv, code in ((["--help"], 0), (["frames"], 2)):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == code


# ---------------------------------------------------------------- issue 28, item 11
def test_pose_estimation_predictions_are_drawn_on_their_crops(sample, tmp_path):
    """A bsp-predict-like file (rows of the test split, image pixels, source) is drawn on
    the crops of the converted file, skeletons where the crop box puts them."""
    with h5py.File(sample / "clips.h5", "r") as f:
        g = f["test"]
        n = min(3, g["labels"].shape[0])
        uv = g["projection_2d"][:n].astype(np.float64)
        cf = g["clip_frames"][:n]
        boxes = g["frames/crop_box"][()][cf]
        rgb = g["frames/rgb"][()][cf]
    preds = tmp_path / "pose.h5"
    S = 64.0  # the model's crop side
    crop_uv = (uv - boxes[..., None, :2]) * (S / (boxes[..., 2] - boxes[..., 0]))[..., None, None]
    with h5py.File(preds, "w") as f:
        f.attrs.update(task="pose_estimation", units="pixels", source=str(sample / "clips.h5"),
                       split="test", frame_start=0)
        f["crop_pixels"], f["target_crop_pixels"] = crop_uv + 2.0, crop_uv
        f["pixels"] = uv + 6.0
        f["row"] = np.arange(n)
        f["label"] = np.zeros(n, np.int64)
        f["clip_id"] = np.arange(n)
    size = 160
    res = preview_predictions(preds, tmp_path / "p.png", clips=[0], size=size, frame="first")
    assert res["background"] == "crops"
    img = _read(tmp_path / "p.png")[3 * CAPTION:]
    assert img.shape == (size, size, 3)
    u0, v0, u1, v1 = boxes[0, 0]
    s = size / (u1 - u0)
    truth = (uv[0, 0] - [u0, v0]) * s
    pred = (uv[0, 0] + 6.0 - [u0, v0]) * s
    inside = [j for j in _separated(np.concatenate([truth, pred]), 6.0)
              if j < 26 and 3 <= truth[j][0] < size - 3 and 3 <= truth[j][1] < size - 3]
    assert len(inside) >= 3
    for j in inside:
        assert _disc(img, int(np.floor(truth[j][0])), int(np.floor(truth[j][1])), TRUTH)
    # every pixel not drawn in the two skeleton colours is the crop itself (resized),
    # not a blank square
    import cv2

    crop = cv2.resize(np.ascontiguousarray(rgb[0, 0]), (size, size),
                      interpolation=cv2.INTER_LINEAR)
    drawn = (img == TRUTH).all(-1) | (img == PREDICTION).all(-1)
    assert 50 < drawn.sum() < size * size // 4
    assert np.abs(img[~drawn].astype(int) - crop[~drawn]).max() <= 1
    assert len(np.unique(img[~drawn].reshape(-1, 3), axis=0)) > 20
    # a moved or missing source says so, and --clips-h5 points at it
    with h5py.File(preds, "a") as f:
        f.attrs["source"] = str(tmp_path / "gone.h5")
    with pytest.raises(ValueError, match="gone.h5: the converted file of these predictions"):
        preview_predictions(preds)
    assert main(["predictions", str(preds), "--clips-h5", str(sample / "clips.h5"), "--out",
                 str(tmp_path / "q.png")]) == 0


def test_autoencoder_predictions_show_the_noisy_input(sample, tmp_path):
    INPUT = (150, 150, 150)
    with h5py.File(sample / "clips.h5", "r") as f:
        gt = f["test/projection_2d"][:2].astype(np.float32)
    noisy = gt + 25.0
    noisy[:, :, ::3] = 0.0  # missing joints, as bsp-predict writes them
    p = tmp_path / "ae.h5"
    _write_preds(p, "autoencoder", gt + 1.0, gt, "pixels")
    with h5py.File(p, "a") as f:
        f["input_pixels"] = noisy
    img = preview_predictions(p, None, size=160, cols=2)["images"][0]
    assert (img == INPUT).all(-1).sum() > 30
    # a missing joint is not drawn at (0, 0): the input's joints all lie in the panel's
    # scaled frame, none is pulled to the corner where (0, 0) would land
    scale_free = preview_predictions(p, None, size=160, cols=2, clips=[0])["images"][0]
    assert (scale_free[3 * CAPTION:3 * CAPTION + 8, :8] == INPUT).all(-1).sum() == 0


def test_lifting_predictions_front_and_side_without_piled_up_depth_labels(sample, tmp_path):
    from bsp_fast.preview.plot3d import VIEWS, SkeletonFigure, depth_axis, limits

    with h5py.File(sample / "clips.h5", "r") as f:
        gt3 = f["test/targets/absolute_pose_loc"][:2]
    p3 = tmp_path / "lift.h5"
    _write_preds(p3, "lifting", gt3 + 0.05, gt3, "metres")
    img = preview_predictions(p3, None, clip=0)["images"][0]
    w = img.shape[1]
    for half in (img[:, : w // 2], img[:, w // 2:]):  # both views hold both skeletons
        for colour in (TRUTH, PREDICTION):
            assert (np.abs(half.astype(int) - colour).max(-1) < 40).sum() > 20, colour
    assert depth_axis(VIEWS["front"][1]) == "x" and depth_axis(VIEWS["side"][1]) == "y"
    lo, hi = limits(gt3[0])
    fig = SkeletonFigure([(v, VIEWS[v]) for v in ("front", "side")], lo, hi)
    fig.render([[gt3[0, 0]], [gt3[0, 0]]])
    for ax, depth in zip(fig.axes, ("x", "y")):
        for name in "xyz":
            texts = [t.get_text() for t in getattr(ax, f"{name}axis").get_ticklabels()]
            if name == depth:  # seen end-on: no labels to pile up
                assert not any(texts) and getattr(ax, f"get_{name}label")() == ""
            else:
                assert sum(bool(t) for t in texts) >= 3, (name, texts)


def test_preview_frames_counts_the_frames_the_picture_shows(tmp_path, capsys):
    pytest.importorskip("cv2")
    from bsp_fast.preview.cli import main
    from bsp_fast.synth import generate

    ds = tmp_path / "ds"
    generate(ds, "sample", clips=2, frames=150, size="320x120", seed=1, workers=1,
             progress=False)
    out = tmp_path / "x.png"
    assert main(["frames", str(ds), "--recording", "0", "--frames", "60,140",
                 "--out", str(out)]) == 0
    assert re.fullmatch(rf"wrote {re.escape(str(out))} \(\d+x\d+, 2 frame\(s\)\)\n",
                        capsys.readouterr().out)
    assert main(["frames", str(ds), "--recording", "0", "--frames", "10:40:10",
                 "--out", str(tmp_path / "y.mp4")]) == 0
    assert "3 frame(s)" in capsys.readouterr().out  # MP4: one video frame each
