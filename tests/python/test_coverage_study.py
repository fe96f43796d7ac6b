"""The coverage study of the tables' interval (#56, experiments/coverage_study.py), small:
a few cells where the tables live must cover 91-99 % of 400 simulated tables (target
93-97 %, Monte Carlo sd 1.1 p.p.), and the study must be able to fail: the interval that
holds the recordings fixed, fed the same tables, under-covers when recordings vary."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _study():
    spec = importlib.util.spec_from_file_location(
        "coverage_study", ROOT / "experiments" / "coverage_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


CELLS = [("mean", "cell", "balanced", 5, 20, ""),
         ("mean", "difference", "seed-dominant", 5, 43, "unequal seeds"),
         ("f1", "cell", "recording-dominant", 5, 43, ""),
         ("f1", "difference", "balanced", 3, 20, "")]


@pytest.mark.parametrize("metric,target,regime,S,R,variant", CELLS)
def test_the_interval_covers_where_the_tables_live(metric, target, regime, S, R, variant):
    C = _study()
    cell = {"metric": metric, "target": target, "regime": regime, "seeds": S,
            "recordings": R, "variant": variant}
    r = C.run_cell(cell, 400, seed=1)
    assert r["inconclusive"] == 0.0 and 0.91 <= r["coverage"] <= 0.99, r


def test_the_bounded_df_covers_where_satterthwaite_alone_did_not(monkeypatch):
    """3 seeds on 43 recordings, seed and recording variance balanced: the seed mean square
    (2 df) carries most of the variance, and Satterthwaite's df alone rose where it came
    out small (91.4 % of 1,000 tables); bounded by that mean square's df, in target."""
    from bsp_fast.metrics import hierarchical as H

    C = _study()
    cell = {"metric": "mean", "target": "cell", "regime": "balanced", "seeds": 3,
            "recordings": 43, "variant": ""}
    ours = C.run_cell(cell, 400, seed=1)
    monkeypatch.setattr(H, "bounded_df", H.satterthwaite)
    plain = C.run_cell(cell, 400, seed=1)  # the same 400 tables
    assert 0.93 <= ours["coverage"] <= 0.97 and ours["df"] < plain["df"], (ours, plain)
    assert ours["coverage"] >= plain["coverage"] + 0.01, (ours, plain)


def test_the_study_can_fail():
    C = _study()
    cell = {"metric": "mean", "target": "cell", "regime": "recording-dominant", "seeds": 5,
            "recordings": 20, "variant": ""}
    r = C.run_cell(cell, 300, seed=1, levels="seeds")  # the recordings held fixed
    assert r["coverage"] < 0.9 and C.verdict(r) == "under"  # measured 82 %


def test_collapsed_seeds_are_inconclusive_by_rule():
    C = _study()
    assert C.split_modes([np.array([0.45, 0.0, 0.5])])  # one seed says one class only
    assert not C.split_modes([np.array([0.0, 0.0, 0.0])])  # all alike: one mode
    assert not C.split_modes([np.array([0.45, 0.4, 0.5])])
    cell = {"metric": "f1", "target": "cell", "regime": "balanced", "seeds": 5,
            "recordings": 20, "variant": "collapse"}
    r = C.run_cell(cell, 200, seed=1)
    # a collapse seen in 1 - 0.8^5 = 67 % of tables: those are inconclusive by the rule;
    # the rest saw none and cover the main mode (what a table without collapse can say)
    assert 0.55 < r["inconclusive"] < 0.8 and r["coverage_main_mode"] > 0.9


def test_f1_truth_by_quadrature_matches_a_large_simulation():
    C = _study()
    means = []
    for seed in range(3):  # 100 seeds on 20,000 recordings: sd about 0.001 each
        (num, den), = C.f1_rows(np.random.default_rng(seed), 100, 20000, "balanced", 1)[0]
        means.append(np.mean(num.sum(1) / den.sum(1)))
    truth = C.f1_truth(C.LOGIT[0], "balanced", C.REGIMES["balanced"][0])
    assert np.mean(means) == pytest.approx(truth, abs=0.0015)


def test_coverage_study_smoke(tmp_path):
    C = _study()
    assert C.main(["--out", str(tmp_path), "--sims", "5", "--only", "mean/cell"]) == 0
    rows = json.loads((tmp_path / "coverage_study.json").read_text())["rows"]
    assert len(rows) == 3 * 3 * 4 and {r["metric"] for r in rows} == {"mean"}
    assert "| mean | cell | seed-dominant | – | 3 | 10 | 95 % |" in \
        (tmp_path / "coverage_study.md").read_text()
    assert C.main(["--out", str(tmp_path), "--sims", "5", "--only", "mean/cell",
                   "--resume"]) == 0
    assert len(json.loads((tmp_path / "coverage_study.json").read_text())["rows"]) == 36
