"""Lifting scores: root-relative N-MPJPE is 0 for a pose scaled about the hips in every
lifting target space, and PoseFormer is scored on every frame like the other models."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from bsp_fast import metrics as M
from bsp_fast import models
from bsp_fast.data import ClipDataset
from bsp_fast.data.testing import write_clip_file
from bsp_fast.skeleton import HIPS
from bsp_fast.training.scoring import TaskMetrics

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("clips")
    files = {"lifting": root / "l16.h5"}
    write_clip_file(files["lifting"], clips=(24, 12, 12), clip_length=16, seed=1)
    return files


@pytest.mark.parametrize("space", ["absolute", "world", "camera"])
def test_scaled_about_the_hips_has_zero_n_mpjpe_in_every_lifting_target_space(data, space):
    ds = ClipDataset(data["lifting"], "test", "lifting", lifting_target=space)
    b = ds[:6]
    gt = b["targets_m"].double() * 1000
    hips = gt[..., HIPS:HIPS + 1, :]
    pred = hips + 1.1 * (gt - hips)
    assert float(M.n_mpjpe(pred, gt)) == pytest.approx(0.0, abs=1e-9)
    assert float(M.mpjpe(pred, gt)) > 1.0
    # the scoring path: any multiple of the normalised target is a pose scaled about the
    # hips once de-normalised, so N-MPJPE is 0 and never above MPJPE
    tm = TaskMetrics("lifting")
    tm.update(1.1 * b["targets"], b, models.create("lifting", "lstm"))
    out = tm.compute()
    assert out["n_mpjpe_mm"] == pytest.approx(0.0, abs=1e-3)
    assert out["n_mpjpe_mm_centre"] == pytest.approx(0.0, abs=1e-3)
    assert out["mpjpe_mm"] > 1.0
    if space == "world":  # scaled about the origin instead, the world offset shows
        p, g = pred.numpy(), gt.numpy()
        s = (p * g).sum((-1, -2)) / (p * p).sum((-1, -2))
        assert np.linalg.norm(s[..., None, None] * p - g, axis=-1).mean() > 1.0


def test_poseformer_is_scored_on_every_frame_like_the_other_models(data):
    b = ClipDataset(data["lifting"], "test", "lifting")[:4]
    counts = {}
    for name, hp in (("poseformer", dict(embed_dim_ratio=8, depth=1)), ("lstm", {})):
        torch.manual_seed(0)
        m = models.create("lifting", name, **hp).eval()
        with torch.no_grad():
            out = m.forward_batch(b)
        assert out.shape == (4, 16, 26, 3)
        tm = TaskMetrics("lifting")
        tm.update(out, b, m)
        counts[name] = (int(tm.scores["mpjpe_mm"].count),
                        int(tm.scores["mpjpe_mm_centre"].count))
    assert counts["poseformer"] == counts["lstm"] == (4 * 16 * 26, 4 * 8 * 26)
    pf = models.create("lifting", "poseformer", embed_dim_ratio=8, depth=1)
    assert pf.centre_slice(16) == slice(4, 12) and pf.frame_slice(16) == slice(0, 16)
