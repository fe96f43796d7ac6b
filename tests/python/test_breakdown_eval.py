"""bsp-eval --breakdown on tiny trained runs: 26 per-joint rows, each table's counts add
up to the split, per-joint and per-bin values weigh back to the run's overall metrics,
bins agree with values computed here from the clip file, and AUROC / AP / per-joint
errors agree with values computed by hand from the run's own predictions (bsp-predict)."""
import json
import math

import h5py
import numpy as np
import pytest
import torch

import bsp_fast
from bsp_fast.data.testing import write_clip_file
from bsp_fast.skeleton import HIPS, JOINT_NAMES
from bsp_fast.reporting.breakdown import format_breakdown
from bsp_fast.training.tasks import metric_formats
from bsp_fast.training.eval_breakdown import (DISTANCE_EDGES_M, FILE, HEIGHT_EDGES_PX,
                                              bin_index)
from bsp_fast.training.evaluate import breakdown
from bsp_fast.training.evaluate import main as eval_main

pytestmark = [pytest.mark.usefixtures("one_torch_thread"),
              pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]

TINY = {"classification": ("lstm", {"hidden_size": 8, "num_layers": 1}),
        "autoencoder": ("simple_transformer", {"num_layers": 1, "dim_feedforward": 16}),
        "lifting": ("baseline_3d", {"linear_size": 32, "num_blocks": 1}),
        "pose_estimation": ("pose_cnn", {"width": 4, "hidden": 16})}
L, TEST_CLIPS = 8, 16


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("breakdown")
    info = write_clip_file(root / "clips.h5", clips=(48, TEST_CLIPS, TEST_CLIPS),
                           clip_length=L, seed=3)
    write_clip_file(root / "media.h5", clips=(24, 8, 8), clip_length=4, media=True,
                    crop_size=16, seed=4)
    return {"root": root, "clips": info["clips"]}


def _h5(data, task):
    return data["root"] / ("media.h5" if task == "pose_estimation" else "clips.h5")


@pytest.fixture(scope="module")
def runs(data):
    out = {}
    for task, (model, hp) in TINY.items():
        opts = {} if task == "pose_estimation" else {"mjp": 0.3}  # missing joints realised
        out[task] = bsp_fast.train(task, model, data=_h5(data, task),
                                   out=data["root"] / "runs" / task, epochs=2, batch_size=8,
                                   hp=hp, quiet=True, **opts).run_dir
    return out


@pytest.fixture(scope="module")
def docs(runs):
    return {task: breakdown(run, quiet=True) for task, run in runs.items()}


def _test_split(path, key):
    with h5py.File(path, "r") as f:
        g = f["test"]
        return g[key].asstr()[()] if g[key].dtype.kind == "O" else g[key][()]


@pytest.mark.parametrize("task", list(TINY))
def test_counts_of_every_table_add_up_to_the_split(data, docs, task):
    doc = docs[task]
    clips = data["clips"]["test"] if task != "pose_estimation" else \
        len(_test_split(_h5(data, task), "labels"))
    frames_per_clip = 4 if task == "pose_estimation" else L  # these models score every frame
    assert doc["totals"]["clips"] == clips
    assert doc["totals"]["frames"] == clips * frames_per_clip
    if task in ("lifting", "autoencoder"):  # every joint of every frame counts
        assert doc["totals"]["joints"] == clips * frames_per_clip * 26
    assert len(doc["tables"]) >= 3
    for t in doc["tables"]:
        assert t["total"] == doc["totals"][t["count"]], t["title"]
        assert sum(r["count"] for r in t["rows"]) == t["total"], t["title"]
        if "joints" in t["columns"]:  # per-bin joint counts add up to the counted joints
            assert sum(r["joints"] for r in t["rows"]) == doc["totals"]["joints"]
    if task != "classification":
        joints = doc["tables"][0]
        assert joints["title"] == "per joint" and joints["count"] == "joints"
        assert [r["bin"] for r in joints["rows"]] == list(JOINT_NAMES)
    titles = [t["title"] for t in doc["tables"]]
    assert ("per realised missing-joint count" in titles) == (task != "pose_estimation")
    assert "per age/gender profile" in titles
    assert doc["cost"]["parameters"] > 0


def test_lifting_per_joint_and_per_bin_weigh_back_to_the_overall_mpjpe(docs):
    doc = docs["lifting"]
    overall = doc["metrics"]["mpjpe_mm"]  # scored by the run's TaskMetrics
    assert math.isclose(doc["summary"]["mpjpe_mm"], overall, rel_tol=1e-6)
    for t in doc["tables"]:
        rows = [r for r in t["rows"] if r["count"]]
        weight = "count" if t["title"] == "per joint" else "joints"
        mean = sum(r["mpjpe_mm"] * r[weight] for r in rows) / sum(r[weight] for r in rows)
        assert math.isclose(mean, overall, rel_tol=1e-6), t["title"]
    by_joint = {r["bin"]: r["mpjpe_mm"] for r in doc["tables"][0]["rows"]}
    assert by_joint[JOINT_NAMES[HIPS]] == 0.0  # root-aligned on the hips


def test_lifting_per_joint_errors_equal_those_of_the_predictions(runs, docs, tmp_path):
    res = bsp_fast.predict(runs["lifting"], tmp_path / "lift.h5")
    with h5py.File(res.path, "r") as f:
        pred, gt = f["metres_aligned"][()].astype(np.float64), f["target_metres"][()]
    err = np.linalg.norm(pred * 1000 - gt.astype(np.float64) * 1000, axis=-1)  # (N, L, 26)
    want = err.reshape(-1, 26).mean(0)
    got = np.array([r["mpjpe_mm"] for r in docs["lifting"]["tables"][0]["rows"]])
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-3)


def test_lifting_distance_bins_are_the_hips_depth(data, docs):
    # the test file's camera sits at (0, 0, 1.7) looking along +x: depth = hips x
    depth = _test_split(_h5(data, "lifting"), "targets/world_pose_loc")[:, :, HIPS, 0]
    want = np.bincount(bin_index(depth.reshape(-1), DISTANCE_EDGES_M),
                       minlength=len(DISTANCE_EDGES_M) - 1)
    t = next(t for t in docs["lifting"]["tables"] if t["title"] == "per camera distance")
    assert [r["count"] for r in t["rows"]] == want.tolist()
    assert want[0] > 0 and want[1] > 0  # walkers start 9-14 m away: two bins in use


@pytest.mark.parametrize("task", ["autoencoder", "pose_estimation"])
def test_2d_pck_and_height_bins(data, docs, task):
    doc = docs[task]
    m = doc["metrics"]
    assert math.isclose(doc["summary"]["pck_0.05"], m["pck_0.05"], rel_tol=1e-9)
    joints = doc["tables"][0]["rows"]
    correct = sum(r["pck_0.05"] * r["count"] for r in joints)
    assert math.isclose(correct / doc["totals"]["joints"], m["pck_0.05"], rel_tol=1e-9)
    if task == "pose_estimation":  # the task's own per-joint PCK
        for r in joints:
            assert math.isclose(r["pck_0.05"], m[f"pck_0.05/{r['bin']}"], rel_tol=1e-9)
    assert 0.0 <= doc["summary"]["pck_auc"] <= 1.0
    box = _test_split(_h5(data, task), "targets/bboxes")
    height = (box[:, :, 1, 1] - box[:, :, 0, 1]).reshape(-1)
    want = np.bincount(bin_index(height, HEIGHT_EDGES_PX), minlength=len(HEIGHT_EDGES_PX) - 1)
    t = next(t for t in doc["tables"] if t["title"] == "per pedestrian pixel height")
    assert [r["count"] for r in t["rows"]] == want.tolist()


def test_profile_counts_are_those_of_the_clip_file(data, docs):
    h5 = _h5(data, "autoencoder")
    ages, genders = _test_split(h5, "meta/age"), _test_split(h5, "meta/gender")
    want = {}
    for a, g in zip(ages, genders):
        want[f"{a}/{g}"] = want.get(f"{a}/{g}", 0) + L
    t = next(t for t in docs["autoencoder"]["tables"] if t["title"] == "per age/gender profile")
    assert {r["bin"]: r["count"] for r in t["rows"]} == want


def _auroc_by_hand(s, y):
    pos, neg = s[y == 1], s[y == 0]
    wins = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    return wins / (len(pos) * len(neg))


def _ap_by_hand(s, y):
    total, ap, prev_recall = y.sum(), 0.0, 0.0
    for t in np.unique(s)[::-1]:  # each distinct threshold, highest first
        chosen = s >= t
        recall = y[chosen].sum() / total
        ap += (recall - prev_recall) * y[chosen].sum() / chosen.sum()
        prev_recall = recall
    return ap


def test_classification_auroc_ap_f1_from_the_runs_predictions(runs, docs, tmp_path):
    doc = docs["classification"]
    res = bsp_fast.predict(runs["classification"], tmp_path / "cls.h5")
    with h5py.File(res.path, "r") as f:
        logits, label = f["logits"][()].astype(np.float64), f["label"][()]
    s = logits[:, 1] - logits[:, 0] if logits.ndim == 2 else logits
    assert 0 < label.sum() < len(label)
    assert math.isclose(doc["summary"]["auroc"], _auroc_by_hand(s, label), rel_tol=1e-9)
    assert math.isclose(doc["summary"]["ap"], _ap_by_hand(s, label), rel_tol=1e-9)
    for k in ("f1", "precision", "recall", "accuracy", "auroc", "ap"):
        assert math.isclose(doc["summary"][k], doc["metrics"][k], rel_tol=1e-9, abs_tol=1e-12)
    assert doc["summary"]["crossing"] == label.sum()
    # not benchmark windows: no event, no time-to-event table (tests/python/test_tte_breakdown.py)
    assert any(n.startswith("no time-to-event table:") and "no benchmark windows" in n
               for n in doc["notes"])


def test_without_missing_joints_every_frame_is_in_the_first_bin(runs):
    doc = breakdown(runs["autoencoder"], quiet=True, mjp="0")
    t = next(t for t in doc["tables"] if t["title"] == "per realised missing-joint count")
    assert t["rows"][0]["bin"] == "0" and t["rows"][0]["count"] == doc["totals"]["frames"]


def test_cli_formats_and_save(runs, capsys):
    run = runs["lifting"]
    assert eval_main([str(run), "--breakdown", "--quiet", "--save"]) == 0
    md = capsys.readouterr().out
    assert "### per joint (count: joints)" in md and "| crl_hips__C | " in md
    saved = json.loads((run / FILE).read_text())
    assert saved["task"] == "lifting" and saved["totals"]["frames"] == TEST_CLIPS * L
    assert None in [r["mpjpe_mm"] for t in saved["tables"] for r in t["rows"]]  # empty: null
    assert eval_main([str(run), "--breakdown", "--quiet", "--format", "csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "table,row,count_unit,count,metric,value"
    assert sum(1 for x in lines if x.startswith("per joint,")) == 26
    assert eval_main([str(run), "--breakdown", "--quiet", "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["totals"] == saved["totals"]


@pytest.mark.parametrize("argv", [["--save"], ["--format", "json"],
                                  ["--breakdown", "--split", "val"]])
def test_cli_refuses_bad_combinations(runs, capsys, argv):
    assert eval_main([str(runs["lifting"]), "--quiet"] + argv) == 2
    assert "bsp-eval:" in capsys.readouterr().err


def test_format_refuses_an_unknown_format(docs):
    with pytest.raises(ValueError, match="format must be one of"):
        format_breakdown(docs["lifting"], metric_formats(), "xml")
