"""bsp-reproduce's runs: a --seeds smoke run's per-seed values, intervals and marks (and
its --breakdown over seeds), the options checked, every table's `full` rows run for two
batches on the CPU (so a GPU user's first run does not fail on a config error),
--split-seeds, the budget rule, and a seeds table's cells and breakdown bins by hand."""
from __future__ import annotations

import json
from pathlib import Path
import re

import numpy as np
import pytest
from bsp_testdata import table_clip_files

from bsp_fast.reproduction import evidence as E
from bsp_fast import reproduction as R
from bsp_fast.reproduction import runner as S
from bsp_fast.defaults import SEED

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return table_clip_files(tmp_path_factory.mktemp("evidence"))


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
    for name, r in res["results"].items():  # a table of one seed: the default seed's run
        first = next(iter(tab["metrics"]))
        assert r["seeds"][str(SEED)]["metrics"].get(first) is not None, name


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
