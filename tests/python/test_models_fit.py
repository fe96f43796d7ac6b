"""Short seeded fits on a small generated sample: each model's training loss goes down and
ends below its trivial baseline's on the training data.

The sample is ``write_clip_file`` (real kinematics through a CARLA camera). Two changes
make every task learnable in a few seconds: the crossing labels (random with respect to
the poses in that file) are replaced by the walker's facing side (toes left or right of
the hips in the image), and the crops get a coloured blob per joint
(``bsp_fast.models.testing.paint_joint_crops``). Large models are trained at reduced
widths (same code paths); their default sizes are covered by test_models.py.
"""
import h5py
import numpy as np
import pytest
import torch

from bsp_fast import models
from bsp_fast.data import ClipDataset
from bsp_fast.data.testing import write_clip_file
from bsp_fast.models.testing import paint_joint_crops

torch.set_num_threads(1)
L = 16


@pytest.fixture(scope="module")
def h5(tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "clips.h5"
    write_clip_file(path, clips=(48, 4, 4), clip_length=L, clip_offset=8, media=True,
                    crop_size=32, seed=3)
    paint_joint_crops(path, ("train",), seed=3)
    with h5py.File(path, "r+") as f:  # label = the walker faces right in the image
        g = f["train"]
        uv = g["projection_2d"][()]
        toes = uv[:, :, [19, 24], 0].mean(axis=(1, 2)) - uv[:, :, 1, 0].mean(axis=1)
        labels = (toes > 0).astype(np.uint8)
        g["labels"][...] = labels
        g.attrs["class_counts"] = np.bincount(labels, minlength=2).astype(np.int64)
    return path


def batches(h5, task, size=16, **kw):
    ds = ClipDataset(h5, "train", task, augment=False, seed=0, **kw)
    return [ds[i:i + size] for i in range(0, len(ds), size)]


def mean_loss(model, data) -> float:
    model.eval()
    with torch.no_grad():
        total = sum(model.loss(model.forward_batch(b), b).item() * len(b["inputs"]) for b in data)
    return total / sum(len(b["inputs"]) for b in data)


def fit(model, data, steps, lr):
    opt = model.configure_optimizers(lr=lr)["optimizer"]
    model.train()
    for step in range(steps):
        b = data[step % len(data)]
        loss = model.loss(model.forward_batch(b), b)
        opt.zero_grad()
        loss.backward()
        opt.step()
    return model


# 3D in camera axes: in the walker's own frame ("absolute") this sample's poses hardly vary
CAMERA = dict(lifting_target="camera")
CASES = {
    ("classification", "lstm"): ({}, 150, 3e-3, {}),
    ("classification", "pedestrian_graph"): ({}, 150, 1e-2, {}),
    ("autoencoder", "simple_transformer"): (dict(dim_feedforward=256), 120, 1e-3,
                                            dict(noise=2.0, mjp=0.2)),
    ("autoencoder", "simple_transformer_pe"): (dict(dim_feedforward=256), 120, 1e-3,
                                               dict(noise=2.0, mjp=0.2)),
    ("lifting", "baseline_3d"): (dict(linear_size=128), 120, 1e-2, CAMERA),
    ("lifting", "lstm"): ({}, 150, 3e-3, CAMERA),
    ("lifting", "lstm_relative_rot"): ({}, 150, 3e-3, CAMERA),
    ("lifting", "poseformer"): (dict(embed_dim_ratio=8, depth=1, num_heads=4), 60, 1e-3, CAMERA),
    ("pose_estimation", "pose_cnn"): (dict(width=8, hidden=64), 120, 3e-3, {}),
}


@pytest.mark.parametrize("task,name", sorted(CASES))
def test_short_fit_beats_the_trivial_baseline(h5, task, name):
    hp, steps, lr, data_kw = CASES[(task, name)]
    data = batches(h5, task, **data_kw)
    trivial = models.trivial_baseline(task).fit(data)
    torch.manual_seed(22742)
    model = models.create(task, name, **hp)
    before = mean_loss(model, data)
    fit(model, data, steps, lr)
    after = mean_loss(model, data)
    base = mean_loss(trivial, data)
    assert after < 0.7 * before, (before, after)
    assert after < base, (after, base)
    if task == "classification":
        model.eval()
        with torch.no_grad():
            out = torch.cat([model.forward_batch(b) for b in data])
        pred = out.argmax(1) if out.ndim == 2 else (out > 0).long()
        labels = torch.cat([b["targets"] for b in data])
        majority = max(labels.float().mean().item(), 1 - labels.float().mean().item())
        assert (pred == labels).float().mean().item() > majority + 0.1
