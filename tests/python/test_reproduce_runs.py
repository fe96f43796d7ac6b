"""Evidence, not anecdotes: the bootstrap over test recordings and the paired marks on
cases with known answers, root-relative N-MPJPE in every lifting target space, PoseFormer
scored on every frame, bf16 against fp32, --seeds smoke runs, and every table's `full`
rows run for two batches on the CPU (so a GPU user's first run does not fail on a config
error)."""
from __future__ import annotations

import json
from pathlib import Path
import re

import h5py
import numpy as np
import pytest
import torch

from bsp_fast import metrics as M
from bsp_fast import models
from bsp_fast.data import ClipDataset
from bsp_fast.data.testing import write_clip_file
from bsp_fast.metrics import hierarchical as H
from bsp_fast.metrics import uncertainty as U
from bsp_fast.skeleton import HIPS
from bsp_fast.reproduction import evidence as E
from bsp_fast import reproduction as R
from bsp_fast.reporting.reproduced import format_table
from bsp_fast.reproduction import runner as S
from bsp_fast.training.scoring import TaskMetrics
from bsp_fast.training.precision import resolve_precision

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("evidence")
    files = {"lifting": root / "l16.h5", "classification": root / "bench.h5",
             "autoencoder": root / "l30.h5", "pose_estimation": root / "media.h5"}
    write_clip_file(files["lifting"], clips=(24, 12, 12), clip_length=16, seed=1)
    write_clip_file(files["autoencoder"], clips=(24, 12, 12), clip_length=30, seed=2)
    write_clip_file(files["pose_estimation"], clips=(16, 8, 8), clip_length=4, seed=4,
                    media=True)
    write_clip_file(files["classification"], clips=(24, 12, 12), clip_length=16, seed=3)
    with h5py.File(files["classification"], "a") as f:
        f.attrs["benchmark"] = 1
    return files


# ---------------------------------------------------------------------- statistics
def _recordings(n=30, seed=0):
    rng = np.random.default_rng(seed)
    den = rng.integers(10, 60, n).astype(float)  # joints per recording
    return rng.uniform(40, 160, n) * den, den   # error sums: 40-160 mm per joint


def test_identical_runs_are_inconclusive():
    a = _recordings()
    iv = U.paired_interval([a, a], lambda v: v[0] - v[1])
    assert (iv.value, iv.low, iv.high, iv.n) == (0.0, 0.0, 0.0, 30)
    assert U.mark(iv, 1) == U.mark(iv, -1) == "inconclusive"


def test_a_constant_shift_is_reproduced_and_the_opposite_claim_is_not():
    num, den = _recordings()
    worse = (num + 5.0 * den, den)  # 5 mm more on every joint of every recording
    iv = U.paired_interval([worse, (num, den)], lambda v: v[0] - v[1])
    assert iv.value == pytest.approx(5.0) and iv.low == pytest.approx(5.0)
    assert iv.high == pytest.approx(5.0)
    assert U.mark(iv, 1) == "reproduced" and U.mark(iv, -1) == "not reproduced"
    # unpaired, the recordings' own spread (40-160 mm) would swamp the 5 mm
    a, b = U.ratio_interval(*worse), U.ratio_interval(num, den)
    assert a.low < b.high


def test_ratio_interval_matches_the_normal_approximation():
    # 400 recordings of one joint each, errors N(3, 2): 95 % interval about 3 +- 1.96 * 2 / 20
    x = np.random.default_rng(1).normal(3.0, 2.0, 400)
    iv = U.ratio_interval(x, np.ones(400))
    assert iv.value == pytest.approx(x.mean())
    assert (iv.high - iv.low) / 2 == pytest.approx(1.96 * x.std() / 20, rel=0.15)
    assert iv.low < iv.value < iv.high


def test_pool_sums_the_seeds_of_a_recording_and_align_keeps_common_recordings():
    s1 = {"recordings": ["a", "b"], "metrics": {"m": {"num": [1.0, 2.0], "den": [1, 1]}}}
    s2 = {"recordings": ["b", "c"], "metrics": {"m": {"num": [4.0, 8.0], "den": [2, 2]}}}
    recs, num, den = U.pool([s1, s2], "m")
    assert recs == ["a", "b", "c"] and num.tolist() == [1, 6, 8] and den.tolist() == [1, 3, 2]
    common, rows = U.align([(recs, num, den), (["c", "b"], np.array([1.0, 2]), np.ones(2))])
    assert common == ["b", "c"] and rows[1][0].tolist() == [2, 1] and rows[0][0].tolist() == [6, 8]
    with pytest.raises(ValueError, match="allowed: m"):
        U.pool([s1], "f1")


def test_bad_arguments_and_degenerate_cases():
    one = U.ratio_interval([3.0], [1.0])  # one recording: nothing to resample
    assert one.value == 3.0 and np.isnan(one.low) and U.mark(one) == "inconclusive"
    assert U.ratio([0.0, 0.0], [0.0, 0.0], empty=0.0) == 0.0
    with pytest.raises(ValueError, match=r"side must be one of \[1, -1\]"):
        U.mark(one, 0)
    with pytest.raises(ValueError, match="confidence must lie in"):
        U.ratio_interval([1.0, 2.0], [1.0, 1.0], confidence=95)
    with pytest.raises(ValueError, match="same length"):
        U.paired_interval([([1.0, 2.0], [1.0])], lambda v: v[0])
    assert U.combine_marks(["reproduced", "inconclusive"]) == "inconclusive"
    assert U.combine_marks(["reproduced", "not reproduced"]) == "not reproduced"
    assert U.combine_marks(["reproduced"] * 3) == "reproduced"


def _fake_results(tmp_path, table: dict, per_row: dict) -> dict:
    """Results of five seeds per row (the fewest a mark accepts) whose per-recording error
    sums are ``per_row[row]`` (the same for every seed) with 40 recordings."""
    rng = np.random.default_rng(5)
    den = rng.integers(10, 60, 40).astype(float)
    recs = [f"rec{i}/0_0" for i in range(40)]
    out = {"table": table["table"], "budget": "smoke", "seeds": [1, 2, 3, 4, 5], "results": {}}
    for row, per_joint in per_row.items():
        seeds = {}
        for seed in ("1", "2", "3", "4", "5"):
            path = tmp_path / f"{row}-{seed}.json"
            sec = {"recordings": recs, "metrics": {m: {"num": (per_joint * den).tolist(),
                                                       "den": den.tolist()}
                                                   for m in table["metrics"]}}
            path.write_text(json.dumps({"test": sec, "initial": sec, "empty": {}}))
            value = float((per_joint * den).sum() / den.sum())
            seeds[seed] = {"metrics": {m: value for m in table["metrics"]},
                           "initial": {m: value for m in table["metrics"]},
                           "per_recording": str(path), "epochs": 1, "best_epoch": 1}
        out["results"][row] = {"seeds": seeds, "source": "test"}
    return E.summarise(table, out)


def test_findings_marks_on_known_cases(tmp_path):
    tab = R.load_table("lifting")
    base = np.random.default_rng(2).uniform(40, 160, 40)
    rows = ["poseformer", "lstm", "baseline_3d", "lstm_relative_rot"]
    # each 10 mm worse, give or take a recording's 1 mm (every seed the same: the
    # differences vary by recording only)
    jit = {r: np.random.default_rng(10 + i).normal(0, 1.0, 40) for i, r in enumerate(rows)}
    ordered = {r: base + 10.0 * i + jit[r] for i, r in enumerate(rows)}
    found = E.evaluate_findings(tab, _fake_results(tmp_path, tab, ordered))
    assert [f["status"] for f in found[:2]] == ["reproduced", "reproduced"]
    d = found[0]["difference"]  # first pair, lower is better
    assert d == pytest.approx(-10.0, abs=0.5) and -11 < found[0]["interval"][0] < d
    assert found[0]["interval_seeds"] == pytest.approx([d, d])  # the seeds agree
    # identical rows: a difference of 0 with no variance, inconclusive by the stated rule
    same = E.evaluate_findings(tab, _fake_results(tmp_path, tab, {r: base for r in rows}))
    assert [f["status"] for f in same] == ["inconclusive"] * 3
    assert same[0]["rule"] == H.ZERO_SE
    swapped = dict(ordered, poseformer=base + 15.0)  # PoseFormer now worse than the LSTM
    assert E.evaluate_findings(tab, _fake_results(tmp_path, tab, swapped))[0]["status"] == \
        "not reproduced"
    # a drop with the report's size: its interval inside report ± equivalence margin
    ae = R.load_table("autoencoder")
    clean = np.random.default_rng(3).uniform(0.8, 1.0, 40)
    wobble = np.random.default_rng(4).normal(0, 0.005, 40)
    res = _fake_results(tmp_path, ae, {"clean": clean, "noisy": clean - 0.1 + wobble})
    drop = E.evaluate_findings(ae, res)[1]
    assert drop["status"] == "reproduced" and "size agrees with the report's 10.0" in drop["ours"]
    res = _fake_results(tmp_path, ae, {"clean": clean, "noisy": clean - 0.3 + wobble})
    assert "size differs from the report's 10.0 p.p. ± 5.0" in \
        E.evaluate_findings(ae, res)[1]["ours"]
    table = format_table(ae, res, E.evaluate_findings(ae, res))
    assert re.search(r"\| clean \| .* \| \d+\.\d ± 0\.0 \[\d+\.\d, \d+\.\d\] \|", table)


def test_budget_rule_is_checked():
    tab = R.load_table("lifting")
    S.check_budget_rule(tab)
    bad = dict(tab, rows=[dict(tab["rows"][1], budgets={"quick": {"epochs": 3}})])
    with pytest.raises(ValueError, match="row 'lstm' sets 'epochs' for budget 'quick'"):
        S.check_budget_rule(bad)
    bad = dict(tab, rows=[dict(tab["rows"][1], budgets={"quick": {"batch_size": 8}})])
    with pytest.raises(ValueError, match="own_batch_size"):
        S.check_budget_rule(bad)
    with pytest.raises(ValueError, match="missing key 'budget_rule'"):
        S.check_budget_rule({k: v for k, v in tab.items() if k != "budget_rule"})
    for name in R.TABLES:  # every table: one rule, with a patience and a cap of updates
        t = R.load_table(name)
        for budget in ("quick", "full"):
            assert t["budgets"][budget]["early_stop"] > 0 and t["budgets"][budget]["max_steps"] > 0


# ---------------------------------------------------------------------- metrics
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


# ---------------------------------------------------------------------- precision
def test_precision_auto_follows_the_per_model_decision(monkeypatch):
    import bsp_fast.models.lstm as lstm_module

    cls = {n: models.model_class(t, n) for t, n in (("lifting", "baseline_3d"),
                                                    ("autoencoder", "simple_transformer"),
                                                    ("lifting", "lstm"),
                                                    ("lifting", "poseformer"))}
    native = bool(re.search(r"avx512_bf16|amx_bf16", open("/proc/cpuinfo").read()))
    if not native:  # this machine: bf16 is emulated, auto is fp32 for every model
        assert {resolve_precision("auto", "cpu", c) for c in cls.values()} == {"32"}
    monkeypatch.setattr(lstm_module, "cpu_bf16", lambda: True)
    got = {n: resolve_precision("auto", "cpu", c) for n, c in cls.items()}
    assert got == {"baseline_3d": "bf16-mixed", "simple_transformer": "bf16-mixed",
                   "lstm": "32", "poseformer": "32"}
    assert resolve_precision("32", "cpu", cls["baseline_3d"]) == "32"
    monkeypatch.setattr(lstm_module, "cpu_bf16", lambda: False)
    assert resolve_precision("auto", "cpu", cls["baseline_3d"]) == "32"


#: bf16 autocast against float32 on the same weights and clips: relative tolerance of an
#: error in mm; a PCK is a share of joints, and bf16 rounding moves a few joints across the
#: threshold (on a CPU with native bf16, 0.0075 vs 0.0074 here): an absolute tolerance of
#: 0.5 percentage points of the joints
BF16_TOLERANCE = {"mpjpe_mm": dict(rel=0.02), "pck_0.05": dict(abs=0.005)}


@pytest.mark.parametrize("task,name,metric", [("lifting", "baseline_3d", "mpjpe_mm"),
                                              ("autoencoder", "simple_transformer",
                                               "pck_0.05")])
def test_bf16_metrics_stay_within_tolerance_of_fp32(data, task, name, metric):
    assert models.model_class(task, name).cpu_bf16_faster
    ds = ClipDataset(data[task], "test", task, noise=5.0)
    b = ds[:8]
    torch.manual_seed(0)
    m = models.create(task, name).eval()
    values = {}
    for bf16 in (False, True):
        with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = m.forward_batch(b)
        tm = TaskMetrics(task)
        tm.update(out, b, m)
        values[bf16] = tm.compute()[metric]
    assert values[True] == pytest.approx(values[False], **BF16_TOLERANCE[metric])


# ---------------------------------------------------------------------- runs
def test_seeds_smoke_run_gives_per_seed_values_intervals_and_marks(data, tmp_path, capsys):
    argv = ["classification", "--data", str(data["classification"]), "--budget", "smoke",
            "--out", str(tmp_path), "--rows", "lstm-perfect,graph-perfect", "--seeds", "2",
            "--jobs", "1"]  # in this process (the worker processes: test_reproduce_worker.py)
    assert R.main(argv) == 0
    text = capsys.readouterr().out
    base = tmp_path / "classification-smoke"
    saved = json.loads((base / "results.json").read_text())
    assert saved["seeds"] == [22742, 22743] and (base / "curves.png").is_file()
    for row in ("lstm-perfect", "graph-perfect"):
        r = saved["results"][row]
        assert sorted(r["seeds"]) == ["22742", "22743"]
        for seed, one in r["seeds"].items():  # per-seed runs, with their own config
            assert one["run"].endswith(f"{row}/seed-{seed}")
            assert (base / "configs" / f"{row}-seed-{seed}.yaml").is_file()
            rec = json.loads(open(one["per_recording"]).read())
            f1 = rec["test"]["metrics"]["f1"]
            assert sum(f1["num"]) / max(sum(f1["den"]), 1) == pytest.approx(one["metrics"]["f1"])
        vals = [s["metrics"]["accuracy"] for s in r["seeds"].values()]
        assert r["metrics"]["accuracy"] == pytest.approx(np.mean(vals))
        assert r["std"]["accuracy"] == pytest.approx(np.std(vals, ddof=1))
        low, high = r["interval"]["accuracy"]
        assert low <= high
        line = next(ln for ln in text.splitlines() if ln.startswith(f"| {row} |"))
        # two seeds: a t interval with one degree of freedom, which may pass 0 or 1
        assert re.search(r"\d\.\d{3} ± \d\.\d{3} \[-?\d+\.\d{3}, -?\d+\.\d{3}\]", line)
    # LSTM >= graph on perfect data: an interval and a p-value, but two seeds (and a
    # 12-clip test split) make it inconclusive by rule whatever they say
    first = saved["findings"][0]
    lo, hi = first["interval"]
    assert lo <= first["difference"] <= hi and len(first["p_holm"]) == 1
    assert first["status"] == "inconclusive" and "fewer than 5 seeds" in first["rule"]
    assert re.search(r"\| perfect data: LSTM >= PedestrianGraph \| lstm-perfect − "
                     r"graph-perfect [+-]\d\.\d{3} \[", text)
    assert R.main(argv + ["--breakdown"]) == 0  # finished runs are reused
    assert "reusing" in capsys.readouterr().out
    # --breakdown: every run's test breakdown, then mean ± std over seeds per bin
    agg = json.loads((base / "breakdown.json").read_text())["tables"]
    assert [t["title"] for t in agg][0] == "per pedestrian pixel height"
    for t in agg:
        for row in ("lstm-perfect", "graph-perfect"):
            docs = [json.loads((base / row / f"seed-{s}" / "test_breakdown.json").read_text())
                    for s in (22742, 22743)]
            counts = sum(c["count"] for c in t["rows"][row].values())
            assert counts == docs[0]["totals"]["clips"] == 12  # the test split's windows
            mine = next(x for x in docs[0]["tables"] if x["title"] == t["title"])
            for r in mine["rows"]:
                vals = [next(y for y in next(x for x in d["tables"] if x["title"] == t["title"])
                             ["rows"] if y["bin"] == r["bin"])["f1"] for d in docs]
                vals = [v for v in vals if v is not None]
                if vals:
                    assert t["rows"][row][r["bin"]]["mean"] == pytest.approx(np.mean(vals))
    md = (base / "breakdown.md").read_text()
    assert "### per pedestrian pixel height: F1 (count: clips)" in md
    assert (base / "breakdown-per-pedestrian-pixel-height.png").stat().st_size > 1000


def test_seeds_options_are_checked(data, tmp_path, capsys):
    argv = ["lifting", "--data", str(data["lifting"]), "--budget", "smoke", "--out",
            str(tmp_path)]
    assert R.main(argv + ["--seeds", "0"]) == 2
    assert "seeds must be an integer >= 1" in capsys.readouterr().err
    assert R.main(argv + ["--seeds", "2", "--split-seeds"]) == 2
    assert "--split-seeds needs a dataset directory" in capsys.readouterr().err


#: two batches of 4 clips (the full budgets' batches of 256 would be one batch of every
#: train clip of these files, and the full-size PoseFormer's cost grows with it)
FULL_ON_CPU = {"accelerator": "cpu", "limit_batches": 2, "epochs": 1, "max_steps": 2,
               "batch_size": 4, "precision": "32", "threads": 1, "workers": 0}


@pytest.mark.parametrize("table", R.TABLES)
def test_full_budget_rows_run_two_batches_on_the_cpu(table, data, tmp_path):
    # pose: small crops; no train-time box jitter, which re-cuts crops from the converter's
    # context crops that these synthetic files lack (test_box_noise.py covers jitter)
    pose = {"crop_size": 32, "box_jitter_scale": 0.0, "box_jitter_shift": 0.0}
    over = dict(FULL_ON_CPU, **(pose if table == "pose_estimation" else {}))
    tab = R.load_table(table)
    # a row asking for mask+joints crops needs a file (or conversion) of its own: these
    # files are mask-box files (tests/python/test_crop_policy.py checks the refusal)
    rows = [r["name"] for r in tab["rows"] if r.get("crop_box", "mask") == "mask"]
    res = R.run_table(tab, data[table], "full", tmp_path, overrides=over, rows=rows,
                      log=lambda s: 0)
    assert sorted(res["results"]) == sorted(rows)
    for name, r in res["results"].items():
        first = next(iter(tab["metrics"]))
        assert r["metrics"].get(first) is not None, name


def test_split_seeds_set_the_converters_split_seed(tmp_path, capsys):
    from bsp_testdata import recording, write_dataset

    rows = [r for i in range(10) for r in recording(f"rec{i:02d}", range(48), seed=i)]
    ds = write_dataset(tmp_path / "ds", rows)
    argv = ["lifting", "--data", str(ds), "--budget", "smoke", "--out", str(tmp_path / "o"),
            "--rows", "lstm", "--seeds", "2", "--split-seeds", "--jobs", "1"]
    assert R.main(argv) == 0
    saved = json.loads((tmp_path / "o" / "lifting-smoke" / "results.json").read_text())
    assert saved["split_seeds"] is True
    tests = {}
    for seed, one in saved["results"]["lstm"]["seeds"].items():
        cfg = (tmp_path / "o" / "lifting-smoke" / "configs" / f"lstm-seed-{seed}.yaml").read_text()
        assert f"split_seed: {seed}" in cfg and f"seed: {seed}" in cfg
        tests[seed] = json.loads(open(one["per_recording"]).read())["test"]["recordings"]
    # the converter assigns recordings to splits by their clip counts (deterministic);
    # split_seed shuffles the clips inside each split: the same test recordings
    assert tests["22742"] == tests["22743"]
    capsys.readouterr()


def test_cell_interval_is_that_of_the_mean_over_seeds(tmp_path):
    # two seeds on the same 40 recordings: one right on 90 % of its joints, one on 10 %,
    # with different denominators, so the pooled ratio (sum num / sum den over seeds) is
    # not the mean of the seeds' values; the cell is the mean and its interval must hold it
    tab = R.load_table("autoencoder")
    m = next(iter(tab["metrics"]))
    rng = np.random.default_rng(7)
    recs = [f"rec{i}/0_0" for i in range(40)]
    seeds, values = {}, []
    for seed, share, scale in (("1", 0.9, 1.0), ("2", 0.1, 5.0)):
        den = rng.integers(10, 60, 40).astype(float) * scale
        num = den * np.clip(share + rng.normal(0, 0.05, 40), 0, 1)
        path = tmp_path / f"s{seed}.json"
        sec = {"recordings": recs, "metrics": {k: {"num": num.tolist(), "den": den.tolist()}
                                               for k in tab["metrics"]}}
        path.write_text(json.dumps({"test": sec, "initial": sec, "empty": {}}))
        values.append(num.sum() / den.sum())
        seeds[seed] = {"metrics": {k: values[-1] for k in tab["metrics"]},
                       "initial": {k: values[-1] for k in tab["metrics"]},
                       "per_recording": str(path), "epochs": 1, "best_epoch": 1}
    res = E.summarise(tab, {"table": tab["table"], "budget": "smoke", "seeds": [1, 2],
                            "results": {"r": {"seeds": seeds, "source": "test"}}})
    r = res["results"]["r"]
    mean = float(np.mean(values))
    low, high = r["interval"][m]
    pooled = sum(float(np.sum(json.loads(Path(s["per_recording"]).read_text())["test"]
                              ["metrics"][m]["num"])) for s in seeds.values()) / sum(
        float(np.sum(json.loads(Path(s["per_recording"]).read_text())["test"]["metrics"][m]
                     ["den"])) for s in seeds.values())
    assert r["metrics"][m] == pytest.approx(mean)
    # the interval is of its statistic: the mean (0.5), not the pooled ratio (near 0.23);
    # two seeds this far apart (t with about 1 degree of freedom) leave it nearly all of
    # [0, 1], inside it without cutting (Clopper-Pearson at the effective sample size);
    # the seed-only one too
    assert abs(pooled - mean) > 0.2
    for lo, hi in ([low, high], r["interval_seeds"][m]):
        assert 0.0 <= lo < 0.01 and 0.99 < hi <= 1.0



def test_table_breakdown_aggregates_bins_over_seeds_by_hand():
    from bsp_fast.reporting.breakdown import format_aggregate
    from bsp_fast.reproduction.table_breakdown import aggregate
    from bsp_fast.training.tasks import metric_formats

    def doc(a, b):
        return {"tables": [{"title": "per joint", "by": "joint", "count": "joints",
                            "columns": {"mpjpe_mm": "MPJPE (mm)"},
                            "rows": [{"bin": "hips", "count": 10, "mpjpe_mm": a},
                                     {"bin": "head", "count": 10, "mpjpe_mm": b}]}]}

    agg = aggregate({"lstm": [doc(10.0, None), doc(14.0, 30.0)], "mean": [doc(20.0, 40.0)]})
    cells = agg[0]["rows"]
    assert cells["lstm"]["hips"] == {"mean": 12.0, "std": pytest.approx(2 ** 1.5),
                                     "seeds": 2, "count": 10.0}
    assert cells["lstm"]["head"]["mean"] == 30.0 and cells["lstm"]["head"]["seeds"] == 1
    assert cells["mean"]["hips"]["std"] == 0.0
    md = format_aggregate(agg, {"lstm": "LSTM"}, 2, "## t", metric_formats())
    # mm in the task registry's format (two decimals), like every other table (#35)
    assert "| hips | 12.00 ± 2.83 (n 10) | 20.00 (n 10) |" in md


def test_rows_of_different_datasets_are_resampled_independently():
    num, den = _recordings(30, seed=3)
    other = _recordings(24, seed=4)  # another dataset: other recordings, other count
    # one group is the paired bootstrap itself
    one = U.grouped_interval([[(num, den), (num + 5 * den, den)]], lambda v: v[1] - v[0])
    assert one == U.paired_interval([(num, den), (num + 5 * den, den)], lambda v: v[1] - v[0])
    two = U.grouped_interval([[(num, den)], [other]], lambda v: v[1] - v[0])
    assert two.value == pytest.approx(other[0].sum() / other[1].sum() - num.sum() / den.sum())
    assert two.low < two.value < two.high and two.n == 24
    # a dataset against itself shifted by a constant: unpaired, so the interval is wide
    shifted = U.grouped_interval([[(num, den)], [(num + 5 * den, den)]], lambda v: v[1] - v[0])
    assert shifted.value == pytest.approx(5.0) and shifted.high - shifted.low > 1.0
    # the two-level bootstrap the marks use: the recordings of one dataset are drawn once
    # for its rows (a constant shift on it: zero width), of another independently
    from bsp_fast.metrics.hierarchical import two_level

    rows = [(np.tile(other[0], (5, 1)), np.tile(other[1], (5, 1))),
            (np.tile(num, (5, 1)), np.tile(den, (5, 1))),
            (np.tile(other[0] + 2 * other[1], (5, 1)), np.tile(other[1], (5, 1)))]
    for method in ("t", "vc"):  # no variance: no p (never 0 from a standard error of 0)
        iv = two_level(rows, lambda v: v[2] - v[0] + 0 * v[1], groups=["b", "a", "b"],
                       method=method)
        assert iv.value == pytest.approx(2.0) and iv.high - iv.low < 1e-9
        assert np.isnan(iv.p) and iv.se == pytest.approx(0.0, abs=1e-9)
        iv = two_level(rows, lambda v: v[1] - v[0], groups=["b", "a", "b"], method=method)
        assert iv.high - iv.low > 1.0
    with pytest.raises(ValueError, match="aligned on the same recordings"):
        two_level(rows, lambda v: v[1] - v[0])  # 24 and 30 recordings, one dataset
    with pytest.raises(ValueError, match="1-d arrays of one length"):
        U.grouped_interval([[(num, den[:-1])]], lambda v: v[0])
