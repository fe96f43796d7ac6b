"""The pose-estimation protocol (#27): PCK over every joint of every frame with a crop,
visible vs occluded joints with one normaliser, the hips-aligned protocol, per-joint PCK
and fully occluded frames, against numbers computed by hand."""
import numpy as np
import pytest
import torch

from bsp_fast import metrics as M
from bsp_fast.skeleton import JOINT_NAMES


def line_pose():
    """Joint j at (j + 1, 0) (none at (0, 0), the missing-joint marker): the bbox diagonal is 25 px (PCK@0.05: 1.25 px); hips (joint 1)
    to neck (joint 8) is 7 px (PCKhn@0.1: 0.7 px)."""
    return np.stack([np.arange(26.0) + 1, np.zeros(26)], -1)


def test_pck_select_align_and_per_joint_by_hand():
    gt = np.stack([line_pose(), line_pose()])      # two frames
    pred = gt + [1.0, 0.0]                          # frame 0: shifted 1 px ...
    pred[0, 5] += [0.0, 2.0]                        # ... joint 5 by (1, 2): sqrt(5) px
    pred[1] = gt[1]                                 # frame 1 exact
    # bbox: 1 px <= 1.25 except joint 5 of frame 0
    assert M.pck(pred, gt) == pytest.approx(51 / 52)
    # hips-neck: 1 px > 0.7 px for every joint of frame 0
    assert M.pck(pred, gt, alpha=0.1, norm="hips_neck") == pytest.approx(26 / 52)
    # aligned: frame 0's 1 px shift is gone, joint 5 is still (0, 2) off; hips not counted
    assert M.pck(pred, gt, align="hips") == pytest.approx(49 / 50)
    assert M.pck(pred, gt, alpha=0.1, norm="hips_neck", align="hips") == pytest.approx(49 / 50)
    # visible = joints 0..12: counted 26, joint 5 wrong; the normaliser stays the bbox of
    # all 26 joints (with the visible joints' own bbox, 12 px, 1 px would be wrong)
    vis = np.zeros((2, 26), bool)
    vis[:, :13] = True
    assert M.pck(pred, gt, select=vis) == pytest.approx(25 / 26)
    assert M.pck(pred, gt, select=~vis) == pytest.approx(1.0)
    assert M.pck(pred, gt, visible=vis) == pytest.approx(13 / 26)  # the old rule differs
    per = M.pck_per_joint(pred, gt)
    assert per[5] == 0.5 and np.all(np.delete(per, 5) == 1.0)
    none = M.pck_per_joint(pred, gt, select=np.zeros((2, 26), bool))
    assert np.isnan(none).all()
    # torch gives the same
    t = M.pck(torch.tensor(pred), torch.tensor(gt), select=torch.tensor(vis))
    assert float(t) == pytest.approx(25 / 26)
    with pytest.raises(ValueError, match="align"):
        M.pck(pred, gt, align="neck")


class _Model:
    def frame_slice(self, L):
        return slice(None)


def test_task_metrics_count_fully_occluded_frames_and_score_the_rest():
    from bsp_fast.training.scoring import TaskMetrics

    L = 3
    gt = np.stack([line_pose()] * L)[None].astype(np.float32)   # (1, 3, 26, 2)
    box = np.tile(np.array([0, 0, 32, 32], np.float32), (1, L, 1))
    gt[0, 2], box[0, 2] = np.nan, np.nan                         # frame 2: no crop
    out = torch.tensor(np.nan_to_num(gt) + [1.0, 0.0])
    out[0, 0, 5] += torch.tensor([0.0, 2.0])
    vis = np.zeros((1, L, 26), bool)
    vis[..., :13] = True
    batch = {"targets": torch.tensor(gt), "visible": torch.tensor(vis),
             "crop_box": torch.tensor(box)}
    tm = TaskMetrics("pose_estimation")
    tm.update(out, batch, _Model())
    r = tm.compute()
    assert r["fully_occluded_frames"] == 1
    assert r["pck_0.05"] == pytest.approx(51 / 52)              # frames 0 and 1 only
    assert r["pckhn_0.1"] == 0.0
    assert r["pck_0.05_visible"] == pytest.approx(25 / 26)
    assert r["pck_0.05_occluded"] == 1.0
    assert r["pck_0.05_aligned"] == pytest.approx(49 / 50)
    assert r["pckhn_0.1_aligned"] == pytest.approx(49 / 50)
    assert r[f"pck_0.05/{JOINT_NAMES[5]}"] == 0.5 and r[f"pck_0.05/{JOINT_NAMES[0]}"] == 1.0


def test_task_metrics_score_hands_and_feet_apart():
    from bsp_fast.skeleton import JOINT_NAMES
    from bsp_fast.training.scoring import TaskMetrics
    from bsp_fast.training.tasks.pose_estimation import FEET, HANDS

    L = 2
    gt = np.stack([line_pose()] * L)[None].astype(np.float32)   # (1, 2, 26, 2)
    box = np.tile(np.array([0, 0, 32, 32], np.float32), (1, L, 1))
    out = torch.tensor(gt.copy())
    left_hand, right_toe = JOINT_NAMES.index("crl_hand__L"), JOINT_NAMES.index("crl_toe__R")
    out[0, 0, left_hand] += torch.tensor([0.0, 10.0])        # 1 of 4 hand entries wrong
    out[0, :, right_toe] += torch.tensor([10.0, 0.0])        # 2 of 12 foot entries wrong
    out[0, 1, JOINT_NAMES.index("crl_Head__C")] += 10.0      # neither a hand nor a foot
    batch = {"targets": torch.tensor(gt), "visible": torch.ones(1, L, 26, dtype=torch.bool),
             "crop_box": torch.tensor(box)}
    tm = TaskMetrics("pose_estimation")
    tm.update(out, batch, _Model())
    r = tm.compute()
    assert len(HANDS) == 2 and len(FEET) == 6
    assert r["pck_0.05_hands"] == pytest.approx(3 / 4)
    assert r["pck_0.05_feet"] == pytest.approx(10 / 12)
    assert r["pck_0.05"] == pytest.approx(48 / 52)
