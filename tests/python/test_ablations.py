"""The ablation tables of issue #26 (experiments/ablation_*.yaml): they load, their rows are
the grid the docs describe, they run with --budget smoke --seeds 2 on tiny data and write
their figures; the table-format pieces they use (own_updates, data_suffix, figures); the
normaliser-fallback share on hand-built frames; experiments/poseformer_updates.py."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from bsp_fast.data import ClipDataset
from bsp_fast.data import functional as F
from bsp_fast.data.testing import write_clip_file
from bsp_fast import reproduction as R
from bsp_fast.training.logs import read_logs
from bsp_fast.reporting.figures import figure_series
from bsp_fast.reproduction.table_files import check_figures
from bsp_fast.training.scoring import TaskMetrics
from bsp_fast.reproduction.table_files import check_budget_rule, load_table, row_data, table_names

ROOT = Path(__file__).resolve().parents[2]
ABLATIONS = ("ablation_classifier", "ablation_relative_rot", "ablation_poseformer")
PNG = b"\x89PNG\r\n\x1a\n"

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("ablations")
    bench = root / "bench.h5"
    write_clip_file(bench, clips=(24, 12, 12), clip_length=16, seed=3)
    with h5py.File(bench, "a") as f:
        f.attrs["benchmark"] = 1
    for name, seed in (("l16.h5", 1), ("l16-bones5.h5", 5), ("l16-motion.h5", 7)):
        write_clip_file(root / name, clips=(24, 12, 12), clip_length=16, seed=seed)
    return {"bench": bench, "lifting": root / "l16.h5"}


# ---------------------------------------------------------------------- the table files
def test_ablation_tables_load_by_name_with_the_documented_rows():
    assert set(ABLATIONS) <= set(table_names())
    cls = load_table("ablation_classifier")
    rows = {r["name"]: r for r in cls["rows"]}
    grid = [(m, s, j) for m in ("lstm", "pedestrian_graph") for s in (0, 5)
            for j in (0, 0.3, 0.7187, 0.9328)]
    plain = [r for r in cls["rows"] if not r.get("own_updates") and not r.get("own_batch_size")
             and "use_visible" not in (r["options"].get("hp") or {})]
    assert sorted((r["options"]["model"], r["options"]["noise"], r["options"]["mjp"])
                  for r in plain) == sorted(grid)
    vis = [r for r in cls["rows"] if (r["options"].get("hp") or {}).get("use_visible")]
    assert len(vis) == 6 and all(r["options"]["noise"] == 5 for r in vis)
    upd = [r for r in cls["rows"] if r["name"].endswith("-upd")]
    assert len(upd) == 8
    for r in upd:  # the original's batch-1 updates: 40 epochs x 804 windows, 13 per epoch
        q = r["budgets"]["quick"]
        assert q["max_steps"] == 40 * 804 == 32160 and q["epochs"] * 13 >= q["max_steps"]
        assert q["early_stop"] == 619 and (q["epochs"] - 1) * 13 < q["max_steps"]
        assert "batch_size" not in q and "batch_size" not in r["options"]
    assert rows["graph-s5-m0.3-upd"]["options"] == rows["graph-s5-m0.3"]["options"]
    b8 = [r for r in cls["rows"] if r["name"].endswith("-b8")]
    assert len(b8) == 4 and all(r["options"]["model"] == "pedestrian_graph" for r in b8)
    for r in b8:  # batch 8 over the quick budget's 40 epochs: ceil(804 / 8) = 101 per epoch
        q = r["budgets"]["quick"]
        assert q == {"batch_size": 8, "max_steps": 40 * 101, "epochs": 40, "early_stop": 10}
        assert r["options"] == rows[r["name"][:-3]]["options"]
    b1 = [r for r in cls["rows"] if r["name"].endswith("-b1")]
    assert [r["budgets"]["quick"] for r in b1] == [
        {"batch_size": 1, "max_steps": 40 * 804, "epochs": 40, "early_stop": 10}] * 4
    assert "normaliser_fallback" in cls["metrics"]
    rel = load_table("ablation_relative_rot")
    assert {r.get("data_suffix") for r in rel["rows"]} == {None, "-bones5", "-motion"}
    assert set(rel["data_variants"]) == {"-bones5", "-motion"}
    direct = [r for r in rel["rows"] if (r["options"].get("hp") or {}).get("parameterisation")]
    assert len(direct) == 3
    pf = load_table("ablation_poseformer")
    assert [r["name"] for r in pf["rows"]] == ["poseformer", "lstm"]
    assert pf["budgets"]["quick"]["early_stop"] == 0


def test_own_updates_is_the_only_way_for_a_row_to_change_its_update_cap():
    tab = {"table": "t", "budget_rule": "one rule", "rows": [
        {"name": "a", "budgets": {"quick": {"max_steps": 10}}}]}
    with pytest.raises(ValueError, match="own_updates"):
        check_budget_rule(tab)
    tab["rows"][0]["own_updates"] = "the original's batch-1 updates"
    check_budget_rule(tab)
    tab["rows"][0]["budgets"]["quick"]["limit_batches"] = 2  # never a row's
    with pytest.raises(ValueError, match="limit_batches"):
        check_budget_rule(tab)


def test_data_suffix_names_a_sibling_dataset():
    assert row_data("d/medium-poses/", {"data_suffix": "-bones5"}) == "d/medium-poses-bones5"
    assert row_data("d/clips.h5", {"data_suffix": "-motion"}) == "d/clips-motion.h5"
    assert row_data("d/clips.h5", {}) == "d/clips.h5"


def test_bad_figures_are_refused_naming_the_figure():
    tab = load_table("ablation_classifier")
    bad = dict(tab, figures=[dict(tab["figures"][0], x="speed")])
    with pytest.raises(ValueError, match="figure 1: x 'speed'"):
        check_figures(bad)
    line = {"label": "x", "rows": ["no-such-row"]}
    bad = dict(tab, figures=[dict(tab["figures"][0], lines=[line])])
    with pytest.raises(ValueError, match="unknown row"):
        check_figures(bad)
    bad = dict(tab, figures=[dict(tab["figures"][0], file="../f.png")])
    with pytest.raises(ValueError, match="plain name"):
        check_figures(bad)


def test_figure_series_are_means_and_sample_stds_over_seeds():
    fig = {"metric": "f1", "x": "mjp", "lines": [{"label": "a", "rows": ["r1", "r0"]}]}
    res = {"results": {
        "r0": {"mjp": 0.0, "seeds": {"1": {"metrics": {"f1": 0.5}}, "2": {"metrics": {"f1": 0.7}}}},
        "r1": {"mjp": 0.3, "seeds": {"1": {"metrics": {"f1": 0.2}}, "2": {"metrics": {"f1": 0.2}}}}}}
    (label, pts), = figure_series(fig, res)
    assert label == "a" and [p[0] for p in pts] == [0.0, 0.3]  # sorted by MJP
    assert pts[0][1] == pytest.approx(0.6) and pts[0][2] == pytest.approx(0.1414213562)
    assert pts[1][1:3] == (pytest.approx(0.2), 0.0)
    # one run per row (no --seeds): the run's value, no band
    single = {"results": {"r0": {"mjp": None, "metrics": {"f1": 0.4}}}}
    (_, pts), = figure_series(fig, single)
    assert pts == [(0.0, 0.4, 0.0, [0.4])]


# ---------------------------------------------------------------------- normaliser fallback
def _frames(rng, B=2, L=4):
    pts = rng.uniform(20, 200, (B, L, 26, 2)).astype(np.float32)
    pts[0, 0, F.HIPS] = 0          # hips missing
    pts[0, 2, F.HIPS] = 0
    pts[1, 1, F.NECK] = 0          # neck missing
    pts[1, 3, F.NECK] = pts[1, 3, F.HIPS]  # hips and neck coincide
    return pts


def test_fallback_share_of_a_hand_built_batch():
    pts = _frames(np.random.default_rng(0))
    n = F.normalize_hips_neck(pts)
    want = np.zeros((2, 4), bool)
    want[0, 0] = want[0, 2] = want[1, 1] = want[1, 3] = True
    np.testing.assert_array_equal(n.fallback, want)
    tm = TaskMetrics("classification")
    batch = {"label": torch.tensor([0, 1]), "normaliser_fallback": torch.from_numpy(n.fallback)}
    tm.update(torch.tensor([[2.0, 0.0], [0.0, 2.0]]), batch, model=None)
    # a second batch of 3 frames, one of them a fallback: (4 + 1) / (8 + 3)
    batch = {"label": torch.tensor([1]), "normaliser_fallback": torch.tensor([[False, True, False]])}
    tm.update(torch.tensor([[0.0, 1.0]]), batch, model=None)
    out = tm.compute()
    assert out["normaliser_fallback"] == pytest.approx(5 / 11) and out["f1"] == 1.0
    tm.reset()
    assert "normaliser_fallback" not in TaskMetrics("pose_estimation").compute()


def test_dataset_marks_exactly_the_frames_without_hips_or_neck(data):
    ds = ClipDataset(data["lifting"], "val", "lifting", noise=0.0, mjp=0.5)
    batch = ds[list(range(len(ds)))]
    vis = batch["visible"]
    want = ~vis[..., F.HIPS] | ~vis[..., F.NECK]
    assert batch["normaliser_fallback"].dtype == torch.bool
    assert torch.equal(batch["normaliser_fallback"], want)
    share = want.float().mean().item()
    assert 0.5 < share < 0.95  # MJP 0.5 on two joints: about 1 - 0.25 of the frames


# ---------------------------------------------------------------------- smoke runs
def _smoke(table, data_path, out, rows=None, *more):
    argv = [table, "--data", str(data_path), "--budget", "smoke", "--out", str(out),
            "--seeds", "2", "--jobs", "1", *more]
    return R.main(argv + (["--rows", rows] if rows else []))


def test_classifier_ablation_smoke_writes_the_figures_and_fallback(data, tmp_path, capsys):
    rows = "lstm-s0-m0,lstm-s0-m0.9328,graph-s5-m0,graph-s5-m0.3-vis,graph-s5-m0.9328-upd"
    assert _smoke("ablation_classifier", data["bench"], tmp_path, rows) == 0
    text = capsys.readouterr().out
    base = tmp_path / "ablation_classifier-smoke"
    saved = json.loads((base / "results.json").read_text())
    for name in ("f1_vs_mjp.png", "f1_vs_mjp_updates_visible.png"):
        assert (base / name).read_bytes()[:8] == PNG and str(base / name) in saved["figures"]
    assert "normaliser fallback (%)" in text
    for name in rows.split(","):
        for seed in saved["results"][name]["seeds"].values():
            share = seed["metrics"]["normaliser_fallback"]
            assert 0.0 <= share <= 1.0
            logs = read_logs(seed["run"])
            assert "train/normaliser_fallback" in logs and "cost/cpu_s" in logs
    fb = {n: saved["results"][n]["seeds"]["22742"]["metrics"]["normaliser_fallback"]
          for n in rows.split(",")}
    assert fb["lstm-s0-m0.9328"] > 0.5 > fb["lstm-s0-m0"]  # MJP 0.93 removes hips or neck
    marks = {f["text"]: f["status"] for f in saved["findings"]}
    assert marks["LSTM loses less F1 than PedestrianGraph at MJP 0.7187"] == "n/a"


def test_classification_at_batch_1_is_the_classification_table_at_batch_1(data, tmp_path):
    import yaml

    b1, cls = load_table("classification_batch1"), load_table("classification")
    for key in ("findings", "metrics", "common"):
        assert b1[key] == cls[key]
    # the same rows; only their registered seed caps differ (batch 1 costs more per seed)
    caps = ("max_seeds", "max_seeds_why")
    assert [{k: v for k, v in r.items() if k not in caps} for r in b1["rows"]] == \
        [{k: v for k, v in r.items() if k not in caps} for r in cls["rows"]]
    # the original's batch 1 over the same 40 epochs and patience: 804 updates per epoch
    assert b1["budgets"]["quick"] == dict(cls["budgets"]["quick"], batch_size=1,
                                          max_steps=40 * 804)
    assert R.main(["classification_batch1", "--data", str(data["bench"]), "--budget",
                   "smoke", "--seeds", "1", "--rows", "lstm-perfect,graph-perfect",
                   "--out", str(tmp_path)]) == 0
    base = tmp_path / "classification_batch1-smoke"
    for cfg in (base / "configs").glob("*.yaml"):
        assert yaml.safe_load(cfg.read_text())["batch_size"] == 1
    saved = json.loads((base / "results.json").read_text())
    assert sorted(saved["results"]) == ["graph-perfect", "lstm-perfect"]


def test_relative_rot_ablation_reads_each_rows_dataset(data, tmp_path, capsys):
    rows = "relrot,relrot-direct-bones5,lstm-motion"
    assert _smoke("ablation_relative_rot", data["lifting"], tmp_path, rows) == 0
    base = tmp_path / "ablation_relative_rot-smoke"
    want = {"relrot": "l16.h5", "relrot-direct-bones5": "l16-bones5.h5",
            "lstm-motion": "l16-motion.h5"}
    import yaml

    for name, file in want.items():
        cfg = yaml.safe_load((base / "configs" / f"{name}-seed-22742.yaml").read_text())
        assert Path(cfg["data"]).name == file
    cfg = yaml.safe_load((base / "configs" / "relrot-direct-bones5-seed-22743.yaml").read_text())
    assert cfg["hp"] == {"parameterisation": "direct"}
    capsys.readouterr()
    # a variant that was not made: exit 2, naming the row and the bsp-synth command
    lone = tmp_path / "lone" / "x.h5"
    lone.parent.mkdir()
    lone.write_bytes(data["lifting"].read_bytes())
    assert _smoke("ablation_relative_rot", lone, tmp_path / "o2", "relrot-bones5") == 2
    err = capsys.readouterr().err
    assert "relrot-bones5" in err and "x-bones5.h5" in err and "--bone-length-variation" in err


def _script():
    spec = importlib.util.spec_from_file_location(
        "poseformer_updates", ROOT / "experiments" / "poseformer_updates.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_first_pass_on_hand_made_curves():
    pu = _script()
    # LSTM 100 -> 80 -> 60 at 10, 20, 30 updates; PoseFormer 120, 90, 55 at 10, 20, 30
    assert pu.first_pass([10, 20, 30], [120, 90, 55], [10, 20, 30], [100, 80, 60]) == 30
    # interpolated: LSTM 90 at 15; PoseFormer 85 there passes
    assert pu.first_pass([15], [85], [10, 20], [100, 80]) == 15
    # past the LSTM's last point its last value holds (70); before its first: not compared
    assert pu.first_pass([5, 40], [1, 69], [10, 20], [100, 70]) == 40
    assert pu.first_pass([10, 20], [101, 81], [10, 20], [100, 80]) is None


def test_poseformer_ablation_smoke_and_the_updates_script(data, tmp_path, capsys):
    # the full-size PoseFormer: batches of 4 (still 2 per epoch) rather than the smoke
    # budget's 16 make its runs half as long; every row at the same batch size
    assert _smoke("ablation_poseformer", data["lifting"], tmp_path, None,
                  "--set", "batch_size=4") == 0
    base = tmp_path / "ablation_poseformer-smoke"
    capsys.readouterr()
    pu = _script()
    assert pu.main([str(base)]) == 0
    res = json.loads((base / "poseformer_updates.json").read_text())
    assert (base / "poseformer_updates.png").read_bytes()[:8] == PNG
    for row in ("poseformer", "lstm"):  # 2 epochs of 2 batches: 2 and 4 updates
        assert res["rows"][row]["updates"] == [2.0, 4.0] and res["rows"][row]["seeds"] == 2
    runs = [pu.run_series(base / "poseformer" / f"seed-{s}") for s in (22742, 22743)]
    mean = np.mean([r["value"] for r in runs], 0)
    np.testing.assert_allclose(res["rows"]["poseformer"]["mean"], mean)
    assert "PoseFormer's mean val MPJPE" in capsys.readouterr().out
