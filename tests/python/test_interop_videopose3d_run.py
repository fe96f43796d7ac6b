"""The VideoPose3D commands of docs/interop.md, run as written in a checkout of VideoPose3D
(github.com/facebookresearch/VideoPose3D) named by BSP_VIDEOPOSE3D_ROOT (opt-in: its code
is not part of bsp_fast): the viewer export and run.py's render over a video in which the
subject starts at frame 35; the 3D export, the docs' dataset class and run.py patch, one
epoch of training, and the render with the ground truth in its viewer's box. The model's
weights are random, made by VideoPose3D's own TemporalModel under the pretrained file's
name (that file is a download). Needs PyTorch, matplotlib and ffmpeg."""
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from bsp_fast.data.testing import write_clip_file
from bsp_fast.interop.cli import main

VP3D = os.environ.get("BSP_VIDEOPOSE3D_ROOT")
pytestmark = pytest.mark.skipif(not VP3D, reason="opt-in: BSP_VIDEOPOSE3D_ROOT (a checkout)")
DOCS = (Path(__file__).resolve().parents[2] / "docs" / "interop.md").read_text()
START = 35


def _block(containing: str) -> str:
    """The docs' code block holding ``containing``, continuation lines joined."""
    for block in re.findall(r"```[a-z]*\n(.*?)```", DOCS, re.S):
        if containing in block:
            return block.replace("\\\n", " ")
    raise AssertionError(f"docs/interop.md: no code block with {containing!r}")


@pytest.fixture
def site(tmp_path):
    """A VideoPose3D copy, a clip file whose subjects start at frame 35, their video,
    and the checkpoint file the docs name (random weights)."""
    shutil.copytree(VP3D, tmp_path / "VideoPose3D",
                    ignore=shutil.ignore_patterns(".git", "images"))
    clips = tmp_path / "clips.h5"
    write_clip_file(clips, clips=(8, 4, 4), clip_length=8)
    with h5py.File(clips, "r+") as f:
        for s in ("train", "val", "test"):
            for name in ("targets/frame_idx", "meta/start_frame", "meta/end_frame"):
                f[s][name][...] = f[s][name][()] + START
        w, h = int(f["train/meta/clip_width"][0]), int(f["train/meta/clip_height"][0])
        frames = int(max(f[s]["meta/end_frame"][()].max() for s in ("train", "val", "test")))
    subprocess.run(["ffmpeg", "-loglevel", "error", "-f", "lavfi", "-i",
                    f"color=c=gray:s={w}x{h}:r=25:d={frames / 25 + 0.2:.2f}",
                    str(tmp_path / "VIDEO.mp4")], check=True)
    code = ("import torch; from common.model import TemporalModel; "
            "m = TemporalModel(17, 2, 17, filter_widths=[3, 3, 3, 3, 3], channels=1024); "
            "torch.save({'epoch': 0, 'model_pos': m.state_dict()}, "
            "'checkpoint/pretrained_h36m_detectron_coco.bin')")
    (tmp_path / "VideoPose3D" / "checkpoint").mkdir()
    subprocess.run([sys.executable, "-c", code], cwd=tmp_path / "VideoPose3D", check=True)
    return tmp_path


def _meta(site, name="data_2d_custom_bsp.npz"):
    return np.load(site / "VideoPose3D" / "data" / name, allow_pickle=True)["metadata"].item()


def _run_block(site, block: str, monkeypatch, subject=None) -> None:
    """Each line of a docs block: bsp-interop through its main(), cd, python run.py."""
    monkeypatch.chdir(site)
    for line in block.strip().splitlines():
        argv = shlex.split(line)
        if argv[0] == "bsp-interop":
            assert main(argv[1:] + ["--force", "--quiet"]) == 0, line
        elif argv[0] == "cd":
            monkeypatch.chdir(Path.cwd() / argv[1])
        else:
            subject = subject or _meta(site)["subjects"]["train"][0]
            src = _meta(site)["source"][subject]
            argv = [a.replace("VIDEO/TRACK", subject).replace("VIDEO.mp4", str(site / "VIDEO.mp4"))
                    .replace("START_FRAME", str(src["start_frame"]))
                    .replace("END_FRAME", str(src["end_frame"])) for a in argv]
            p = subprocess.run([sys.executable] + argv[1:], capture_output=True, text=True,
                               timeout=900)
            assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]


def _frames(path) -> int:
    out = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0",
                          "-show_entries", "stream=nb_read_frames", "-of", "csv=p=0",
                          str(path)], capture_output=True, text=True, check=True).stdout
    return int(out.strip())


def test_render_command_runs_as_written(site, monkeypatch):
    _run_block(site, _block("--viz-video VIDEO.mp4"), monkeypatch)
    meta = _meta(site)
    subject = meta["subjects"]["train"][0]
    src = meta["source"][subject]
    assert src["start_frame"] == START and src["padded_frames"] == START
    T = len(np.load(site / "VideoPose3D" / "data" / "data_2d_custom_bsp.npz",
                    allow_pickle=True)["positions_2d"].item()[subject]["custom"][0])
    # every row is its video frame; the render starts at the subject's first frame
    assert T == src["end_frame"] and _frames(site / "VideoPose3D" / "out.mp4") == T - START


def test_3d_training_and_render_with_ground_truth(site, monkeypatch):
    vp = site / "VideoPose3D"
    monkeypatch.chdir(site)
    export = _block("--out-3d VideoPose3D/data/data_3d_custom_bsp.npz\n").strip()
    assert main(shlex.split(export)[1:]) == 0  # the worked example: the camera frame
    (vp / "common" / "bsp_dataset.py").write_text(_block("class BSPDataset"))
    patch = _block("from common.bsp_dataset import BSPDataset")
    run_py = (vp / "run.py").read_text()
    stock = ("    from common.custom_dataset import CustomDataset\n    dataset = CustomDataset("
             "'data/data_2d_' + args.dataset + '_' + args.keypoints + '.npz')\n")
    assert stock in run_py
    (vp / "run.py").write_text(run_py.replace(stock, patch))
    train = _block("subjects() {").replace("-e 80", "-e 1").replace("python ",
                                                                      f"{sys.executable} ")
    p = subprocess.run(["bash", "-c", train], cwd=vp, capture_output=True, text=True,
                       timeout=900)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    camera = np.load(vp / "data" / "data_3d_custom_bsp.npz", allow_pickle=True)[
        "positions_3d"].item()
    # the viewer export with its 3D; VideoPose3D's camera functions on it
    assert main(["export", "videopose3d", "clips.h5", "VideoPose3D/data/data_2d_custom_bsp.npz",
                 "--viewer", "--out-3d", "VideoPose3D/data/data_3d_custom_bsp.npz",
                 "--force", "--quiet"]) == 0
    np.save(vp / "camera_frame.npy", camera, allow_pickle=True)
    # VideoPose3D's own camera functions, in its checkout (test_interop_videopose3d.py
    # leaves a stand-in package named common in this process)
    check = f"""
import numpy as np
from common.camera import camera_to_world, world_to_camera
doc = np.load('data/data_3d_custom_bsp.npz', allow_pickle=True)
ground, cams = doc['positions_3d'].item(), doc['metadata'].item()['cameras']
camera = np.load('camera_frame.npy', allow_pickle=True).item()
for subject, pose in cams.items():
    g = ground[subject]['custom'][{START}:]
    R = np.array(pose['orientation'], np.float32)
    t = np.array(pose['translation'], np.float32)
    back = world_to_camera(g, R=R, t=t)  # what run.py trains on: the camera frame
    assert np.abs(back - camera[subject]['custom']).max() < 2e-3, subject
    shown = camera_to_world(back, R=R, t=t)  # what its render draws
    assert shown[..., 2].min() > -0.01 and shown[..., 2].max() < 2.0, subject  # z box 0..1.7
    assert np.abs(shown[..., :2] - shown[:, :1, :2]).max() < 0.85, subject  # around the root
print(len(cams))
"""
    p = subprocess.run([sys.executable, "-c", check], cwd=vp, capture_output=True, text=True)
    assert p.returncode == 0 and int(p.stdout.split()[-1]) > 0, p.stderr[-3000:]
    subject = _meta(site)["subjects"]["train"][0]
    _run_block(site, "\n".join(line for line in _block("--viz-video VIDEO.mp4").splitlines()
                               if not line.startswith("bsp-interop")), monkeypatch, subject)
    assert (vp / "out.mp4").is_file()
