"""Smoke versions of the scripts in experiments/ (the long runs live there, not here)."""
import importlib.util
import json
import lzma
import math
from pathlib import Path

import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "experiments" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    import warnings

    from bsp_fast import convert
    from bsp_fast.synth import generate

    root = tmp_path_factory.mktemp("ns")
    generate(root / "ds", "sample", clips=6, frames=60, size="320x120", seed=1,
             poses_only=True, workers=1, progress=False)
    with warnings.catch_warnings():  # a single-class split is fine here
        warnings.simplefilter("ignore", UserWarning)
        convert(root / "ds", root / "c.h5", clip_length=10, media=False, val_frac=0.3,
                test_frac=0.3)
    return root / "c.h5"


def test_normaliser_stats_smoke(clips, tmp_path):
    ns = _load("normaliser_stats")
    assert ns.main([str(clips), "--out", str(tmp_path), "--mjp", "0", "0.5", "0.95",
                    "--sigma", "0", "5"]) == 0
    info = json.loads((tmp_path / "normaliser_stats.json").read_text())
    rows = {(r["sigma"], r["mjp"]): r for r in info["rows"]}
    assert len(rows) == 6 and "| 5 | 0.95 |" in (tmp_path / "normaliser_stats.md").read_text()
    # no missing joint: hips and neck are always there, the normaliser never falls back
    assert rows[(0.0, 0.0)]["fallback_share"] == 0.0
    assert rows[(0.0, 0.0)]["direct_noise_over_scale_median"] == 0.0
    # hips or neck dropped: the fallback share grows with MJP, towards 1 - (1 - p)^2
    shares = [rows[(5.0, m)]["fallback_share"] for m in (0.0, 0.5, 0.95)]
    assert shares[0] == 0.0 < shares[1] < shares[2]
    assert abs(shares[1] - 0.75) < 0.1 and shares[2] > 0.95
    # the noise is the same share of the direct scale whatever the MJP (same frames' sizes)
    assert rows[(5.0, 0.0)]["direct_noise_over_scale_median"] > 0


def test_redraw_shift_smoke(clips, tmp_path):
    """The old, batch-keyed draws move a noisy checkpoint's score with the evaluation batch
    size; the per-clip draws give one score at every batch size."""
    import bsp_fast

    run = bsp_fast.train("classification", "lstm", data=clips, out=tmp_path / "run", epochs=1,
                         batch_size=4, noise=5.0, mjp=0.7187, quiet=True,
                         hp={"hidden_size": 8, "num_layers": 1})
    rs = _load("redraw_shift")
    assert rs.main([str(run.run_dir), "--out", str(tmp_path / "o"), "--batches", "1", "3",
                    "4", "--metrics", "loss"]) == 0
    doc = json.loads((tmp_path / "o" / "redraw_shift.json").read_text())
    (row,) = doc["rows"]
    m = row["metrics"]["loss"]
    assert row["own_batch_size"] == 4 and m["old_at_own_batch"] is not None
    assert m["new_spread"] < 1e-5  # per clip: the batch size changes nothing
    assert m["old_max"] - m["old_min"] > 1e-4  # batch-keyed: it did
    assert "| run (batch 4) | loss |" in (tmp_path / "o" / "redraw_shift.md").read_text()
    # --resume keeps the rows written
    assert rs.main([str(run.run_dir), "--out", str(tmp_path / "o"), "--resume"]) == 0
    assert len(json.loads((tmp_path / "o" / "redraw_shift.json").read_text())["rows"]) == 1


def _fake_results(folder: Path, precision: str, per_seed: dict) -> Path:
    """A table's results.json with one row, lifting/lstm, and per-recording mpjpe sums."""
    folder.mkdir(parents=True)
    seeds, values = {}, []
    for seed, num in per_seed.items():
        pr = folder / f"seed-{seed}.json"
        pr.write_text(json.dumps({"test": {"recordings": ["r1", "r2", "r3"], "metrics": {
            "mpjpe_mm": {"num": num, "den": [1.0, 2.0, 1.0]}}}}))
        seeds[str(seed)] = {"precision": precision, "per_recording": str(pr),
                            "seconds": {"fit_cpu": 30.0}}
        values.append(sum(num) / 4.0)
    mean = sum(values) / len(values)
    (folder / "results.json").write_text(json.dumps({"table": "lifting", "budget": "quick",
        "results": {"lstm": {"seeds": seeds, "metrics": {"mpjpe_mm": mean},
                             "std": {"mpjpe_mm": 0.0}}}}))
    return folder


def test_precision_retrain_difference_by_hand_and_verdicts(tmp_path):
    pr = _load("precision_retrain")
    auto = _fake_results(tmp_path / "auto", "bf16-mixed",
                         {1: [10.0, 40.0, 30.0], 2: [12.0, 36.0, 33.0]})
    same = _fake_results(tmp_path / "same", "32", {1: [10.0, 40.0, 30.0], 2: [12.0, 36.0, 33.0]})
    noisy = _fake_results(tmp_path / "noisy", "32", {1: [11.0, 42.0, 29.0], 2: [12.0, 40.0, 31.0]})
    # the same shift on every seed and recording: no variance at either level
    shifted = _fake_results(tmp_path / "shifted", "32",
                            {1: [15.0, 50.0, 35.0], 2: [17.0, 46.0, 38.0]})
    out = tmp_path / "out"
    args = ["--auto", str(auto), "--row", "lstm", "--metric", "mpjpe_mm", "--out", str(out)]
    assert pr.main([*args, "--fp32", str(same), "--margin", "2%"]) == 0
    row = json.loads((out / "precision_retrain.json").read_text())["rows"][0]
    # auto: seed 1 (10 + 40 + 30) / 4 = 20, seed 2 81 / 4 = 20.25: 20.125
    assert row["auto"] == pytest.approx(20.125) and row["difference"] == 0.0
    assert row["margin"] == pytest.approx(0.4025) and row["verdict"] == "agrees"
    assert row["fit_cpu_min"] == {"auto": 1.0, "fp32": 1.0}
    # no machine's paths in a published file: folders outside the repository by name
    assert row["auto_runs"] == "auto" and str(tmp_path) not in row["command"]
    assert pr.main([*args, "--fp32", str(noisy), "--margin", "2%"]) == 0
    rows = json.loads((out / "precision_retrain.json").read_text())["rows"]
    assert len(rows) == 1  # the same table, row and metric: replaced
    # float32: seed 1 82 / 4 = 20.5, seed 2 83 / 4 = 20.75; minus auto: +0.5
    assert rows[0]["difference"] == pytest.approx(0.5)
    lo, hi = rows[0]["interval"]
    assert lo < 0.5 < hi and rows[0]["verdict"] == "undetermined"
    assert pr.main([*args, "--fp32", str(shifted), "--margin", "0.5"]) == 0
    rows = json.loads((out / "precision_retrain.json").read_text())["rows"]
    # +5 per unit of den on every recording: (5 + 10 + 5) / 4 = +5
    assert rows[0]["difference"] == pytest.approx(5.0) and rows[0]["verdict"] == "differs"
    assert "| lifting / lstm | mpjpe_mm | 2 |" in (out / "precision_retrain.md").read_text()
    with pytest.raises(SystemExit, match="not float32"):
        pr.main([*args, "--fp32", str(auto), "--margin", "1"])
    # another change keeps the table's precision: a row of its own beside float32's
    relaid = _fake_results(tmp_path / "relaid", "bf16-mixed",
                           {1: [10.0, 40.0, 30.0], 2: [12.0, 36.0, 33.0]})
    assert pr.main([*args, "--fp32", str(relaid), "--margin", "2%", "--change", "layout"]) == 0
    rows = json.loads((out / "precision_retrain.json").read_text())["rows"]
    assert [(r["change"], r["verdict"]) for r in rows] == [("float32", "differs"),
                                                          ("layout", "agrees")]
    assert "| layout |" in (out / "precision_retrain.md").read_text()
    with pytest.raises(SystemExit, match="must keep the precision"):
        pr.main([*args, "--fp32", str(same), "--margin", "1", "--change", "layout"])
    # float32 on another machine: a row of its own, float32 runs required
    assert pr.main([*args, "--fp32", str(same), "--margin", "2%", "--change",
                    "float32 (AVX2-only CPU)"]) == 0
    rows = json.loads((out / "precision_retrain.json").read_text())["rows"]
    assert [r["change"] for r in rows] == ["float32", "layout", "float32 (AVX2-only CPU)"]
    with pytest.raises(SystemExit, match="not float32"):
        pr.main([*args, "--fp32", str(relaid), "--margin", "1", "--change", "float32 (x)"])


def _fake_published(folder: Path, precision: str, per_seed: dict) -> Path:
    """:func:`_fake_results`' row as a published table: ``lifting-quick.json`` and its
    ``.per_recording.json.xz`` (what ``bsp-reproduce --publish`` writes), no run folder."""
    from bsp_fast.reproduction.readme import FORMAT

    res = json.loads((_fake_results(folder / "runs", precision, per_seed)
                      / "results.json").read_text())
    sums = {"lstm": {}}
    for seed, s in res["results"]["lstm"]["seeds"].items():
        sums["lstm"][seed] = json.loads(Path(s.pop("per_recording")).read_text())
        s["metrics"] = {"mpjpe_mm": sum(per_seed[int(seed)]) / 4.0}
    (folder / "lifting-quick.per_recording.json.xz").write_bytes(
        lzma.compress(json.dumps(sums).encode()))
    doc = dict(res, format=FORMAT, per_recording="lifting-quick.per_recording.json.xz")
    (folder / "lifting-quick.json").write_text(json.dumps(doc))
    return folder / "lifting-quick.json"


def test_precision_retrain_against_a_published_table_on_its_first_seeds(tmp_path):
    pr = _load("precision_retrain")
    published = _fake_published(tmp_path / "results", "bf16-mixed",
                                {1: [10.0, 40.0, 30.0], 2: [12.0, 36.0, 33.0],
                                 3: [50.0, 90.0, 70.0]})
    # a re-run of the table's first two seeds, each +4 on its second recording (den 2)
    rerun = _fake_results(tmp_path / "fp32", "32", {1: [10.0, 44.0, 30.0],
                                                   2: [12.0, 40.0, 33.0]})
    out = tmp_path / "out"
    args = ["--row", "lstm", "--metric", "mpjpe_mm", "--margin", "2", "--out", str(out)]
    assert pr.main(["--auto", str(published), "--fp32", str(rerun), *args]) == 0
    row = json.loads((out / "precision_retrain.json").read_text())["rows"][0]
    # the table's mean over seeds 1 and 2 only: (80 / 4 + 81 / 4) / 2 = 20.125 (seed 3's
    # 65 would make it 35.08); its std: |20 - 20.25| / sqrt(2)
    assert row["seeds"] == [1, 2] and row["auto"] == pytest.approx(20.125)
    assert row["auto_std"] == pytest.approx(0.25 / 2 ** 0.5)
    assert row["difference"] == pytest.approx(1.0) and row["auto_precision"] == ["bf16-mixed"]
    assert row["fit_cpu_min"] == {"auto": 1.0, "fp32": 1.0}
    # a re-run whose seeds are not the table's first: refused, not silently re-paired
    other = _fake_results(tmp_path / "other", "32", {2: [12.0, 36.0, 33.0]})
    with pytest.raises(SystemExit, match="not the first seeds"):
        pr.main(["--auto", str(published), "--fp32", str(other), *args])
    # a file that is not a published table: named in the error
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(SystemExit, match="not a published table"):
        pr.main(["--auto", str(bad), "--fp32", str(rerun), *args])


@pytest.fixture(scope="module")
def pose_table(tmp_path_factory) -> Path:
    """Two smoke seeds of the pose table's pose_temporal row (tiny network and crops) on a
    clip file of 16/8/8 clips; the table's run folder. Trained once for the module: the
    scripts below only read it (their outputs go to each test's own folder)."""
    from bsp_fast import reproduction as R
    from bsp_fast.data.testing import write_clip_file

    tmp_path = tmp_path_factory.mktemp("pose_table")
    h5 = tmp_path / "media.h5"
    write_clip_file(h5, clips=(16, 8, 8), clip_length=4, seed=4, media=True)
    assert R.main(["pose_estimation", "--data", str(h5), "--budget", "smoke", "--out",
                   str(tmp_path / "runs"), "--rows", "pose_temporal", "--seeds", "2",
                   "--jobs", "1", "--set", "crop_size=32", "--set", "hp={width: 4}",
                   # no context frames in this file: no box jitter (nor noisy-box scores)
                   "--set", "box_jitter_scale=0", "--set", "box_jitter_shift=0"]) == 0
    return tmp_path / "runs" / "pose_estimation-smoke"


def test_pose_decode_smoke_rescores_the_same_checkpoints(pose_table, tmp_path):
    pd = _load("pose_decode")
    assert pd.main([str(pose_table), "--out", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "pose_decode.json").read_text())
    assert doc["seeds"] == ["22742", "22743"] and doc["reproduced_max_abs"] == 0.0
    one = doc["summary"][0]
    assert one["metric"] == "pck_0.05"
    got = {d: [doc["per_seed"][s][d]["metrics"]["pck_0.05"] for s in doc["seeds"]]
           for d in ("soft_argmax", "dark", "flip")}
    # the summary's values are the seeds' means of the scorings, each difference against
    # the soft-argmax
    for d in ("dark", "flip"):
        assert one[d] == pytest.approx(sum(got[d]) / 2)
        assert one[f"{d}_difference"]["value"] == pytest.approx(
            (sum(got[d]) - sum(got["soft_argmax"])) / 2)
    assert got["flip"] != got["soft_argmax"]  # the flip was applied
    md = (tmp_path / "out" / "pose_decode.md").read_text()
    assert "| pck_0.05 |" in md and "soft-argmax + flip − soft-argmax" in md
    # --resume scores only what is missing: a decoding dropped from one seed comes back
    first = doc["per_seed"]["22743"].pop("flip")["metrics"]
    (tmp_path / "out" / "pose_decode.json").write_text(json.dumps(doc))
    calls = []
    real = pd.score
    pd.score = lambda run, d: calls.append((run.name, d)) or real(run, d)
    try:
        assert pd.main([str(pose_table), "--out", str(tmp_path / "out"), "--resume"]) == 0
    finally:
        pd.score = real
    assert calls == [("seed-22743", "flip")]
    again = json.loads((tmp_path / "out" / "pose_decode.json").read_text())
    assert again["per_seed"]["22743"]["flip"]["metrics"] == first  # scored alike again


def test_pose_decode_checks_each_run_against_its_own_decoding(tmp_path):
    pd = _load("pose_decode")
    for hp, want in (("{width: 16}", "soft_argmax"), ("{width: 32, flip_test: true}", "flip"),
                     ("{decode: dark}", "dark"), ("null", "soft_argmax")):
        (tmp_path / "config.yaml").write_text(f"model: pose_temporal\nhp: {hp}\n")
        assert pd._own_decode(tmp_path) == want


def test_cross_table_difference_by_hand_with_holm(tmp_path):
    ct = _load("cross_table")
    a = _fake_results(tmp_path / "a", "32", {1: [10.0, 40.0, 30.0], 2: [12.0, 36.0, 33.0]})
    b = _fake_results(tmp_path / "b", "32", {1: [15.0, 50.0, 35.0], 2: [17.0, 46.0, 38.0]})
    out = tmp_path / "out"
    assert ct.main(["--a", str(a), "--b", str(b), "--rows", "lstm", "--metric", "mpjpe_mm",
                    "--out", str(out)]) == 0
    (row,) = json.loads((out / "cross_table.json").read_text())["rows"]
    # a: (20 + 20.25) / 2; b: (25 + 25.25) / 2; b is a + 5 on every recording of both
    # seeds (paired on the shared seed numbers and on recordings): no variance at all, so
    # the interval is +5 itself and no p is made of a zero standard error
    assert row["difference"] == pytest.approx(5.0) and row["seeds"] == [2, 2]
    lo, hi = row["interval"]
    assert lo == pytest.approx(5.0) == hi
    assert math.isnan(row["p"]) and math.isnan(row["p_holm"])
    assert row["command"].startswith("python3 experiments/cross_table.py --a a --b b ")
    assert "| lstm | mpjpe_mm | 20.125 (lifting, 2 seeds) |" in (out / "cross_table.md").read_text()
    with pytest.raises(SystemExit, match="no row 'gru'"):
        ct.main(["--a", str(a), "--b", str(b), "--rows", "gru", "--metric", "mpjpe_mm",
                 "--out", str(out)])
    # A:B: two rows of one table (here the b folder's row renamed), the same numbers
    doc = json.loads((b / "results.json").read_text())
    doc["results"]["lstm-upd"] = doc["results"].pop("lstm")
    (b / "results.json").write_text(json.dumps(doc))
    assert ct.main(["--a", str(a), "--b", str(b), "--rows", "lstm:lstm-upd", "--metric",
                    "mpjpe_mm", "--out", str(out)]) == 0
    rows = json.loads((out / "cross_table.json").read_text())["rows"]
    assert [r["row"] for r in rows] == ["lstm", "lstm → lstm-upd"]
    assert rows[1]["difference"] == pytest.approx(5.0) and rows[1]["interval"] == row["interval"]
    with pytest.raises(SystemExit, match="no row 'lstm'"):
        ct.main(["--a", str(a), "--b", str(b), "--rows", "lstm", "--metric", "mpjpe_mm",
                 "--out", str(out)])


def test_pose_generalisation_smoke_scores_train_val_and_test(pose_table, tmp_path):
    from bsp_fast.training.evaluate import evaluate

    table = pose_table
    pg = _load("pose_generalisation")
    assert pg.main([str(table), "--out", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "pose_generalisation.json").read_text())
    part = doc["rows"]["pose_temporal"]
    assert part["seeds"] == ["22742", "22743"]
    for seed in part["seeds"]:
        run = table / "pose_temporal" / f"seed-{seed}"
        got = part["per_seed"][seed]
        # the linked file scores the split's own clips: the same as bsp-eval --split val,
        # every train clip, and the test entry is the run's own metrics.json
        assert got["val"]["metrics"] == evaluate(run, "val").metrics
        assert got["train"]["clips"] == 16 and got["val"]["clips"] == 8
        assert got["test"]["metrics"] == json.loads((run / "metrics.json").read_text())["test"]
        assert got["train"]["metrics"] != got["val"]["metrics"]
    one = part["summary"][0]
    assert one["metric"] == "pck_0.05" and one["train_recordings"] >= 1
    want = [part["per_seed"][s][sp]["metrics"]["pck_0.05"] for s in part["seeds"]
            for sp in ("train", "val")]
    # a seed's pooled per-recording ratio is its metric; the gap is the means' difference
    assert one["train_per_seed"] == pytest.approx(want[0::2])
    assert one["gap"]["value"] == pytest.approx((sum(want[0::2]) - sum(want[1::2])) / 2)
    assert "| pck_0.05 |" in (tmp_path / "out" / "pose_generalisation.md").read_text()
    # --resume scores nothing again
    pg.score = lambda run, linked: pytest.fail("scored again")
    assert pg.main([str(table), "--out", str(tmp_path / "out"), "--resume"]) == 0


def _published(name: str) -> Path:
    return ROOT / "docs" / "results" / f"{name}-quick.json"


def test_decided_fraction_counts_the_published_tables_marks():
    mod = _load("decided_fraction")
    auto = mod.decided(_published("autoencoder"))
    doc = json.loads(_published("autoencoder").read_text(encoding="utf-8"))
    p = [q for f in doc["findings"] if not f.get("exploratory") for q in f["p_holm"]]
    # no rule holds this table's comparisons: decided is Holm p below 0.05
    assert all(f["rule"] is None for f in doc["findings"])
    assert (auto["decided"], auto["comparisons"]) == (sum(q < 0.05 for q in p), len(p))
    assert auto["hash"] == doc["protocol"]["hash"][:12] and auto["seeds"] == \
        sorted({len(r["seeds"]) for r in doc["results"].values()})


def test_decided_fraction_before_is_the_newest_version_under_another_hash(tmp_path):
    import shutil
    import subprocess

    mod = _load("decided_fraction")
    results = tmp_path / "docs" / "results"
    results.mkdir(parents=True)
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(git[:3] + ["init", "-q"], check=True)
    src = _published("autoencoder")
    doc = json.loads(src.read_text(encoding="utf-8"))
    shutil.copy(src.with_name(Path(doc["per_recording"]).name), results)
    for h in ("a" * 64, "b" * 64, doc["protocol"]["hash"]):  # old, older-but-newer, now
        (results / src.name).write_text(json.dumps(
            dict(doc, protocol=dict(doc["protocol"], hash=h))), encoding="utf-8")
        subprocess.run(git + ["add", "-A"], check=True)
        subprocess.run(git + ["commit", "-qm", h[:4]], check=True)
    second = subprocess.run(git + ["rev-parse", "--short=7", "HEAD~1"], check=True,
                            capture_output=True, text=True).stdout.strip()
    row = mod.table_row(results, "autoencoder")
    assert row["before_commit"] == second and row["before"]["hash"] == "b" * 12
    assert {k: v for k, v in row["before"].items() if k != "hash"} == \
        {k: v for k, v in row["after"].items() if k != "hash"}
    a = row["after"]
    assert f"| autoencoder | {a['decided']} of {a['comparisons']} |" in mod.render([row])


def test_the_decided_fractions_in_the_docs_are_the_generated_ones():
    mod = _load("decided_fraction")
    rows = json.loads((ROOT / "docs/results/decided_fraction.json").read_text(encoding="utf-8"))
    assert mod.render(rows) in (ROOT / "docs/results/decided_fraction.md").read_text(
        encoding="utf-8")
    text = (ROOT / "docs/reproduce.md").read_text(encoding="utf-8").splitlines()
    for r in rows:
        b, a, p = r["before"], r["after"], r["predicted"]
        # the table's row of five cells (the power table above has rows of four)
        line = [t for t in text if t.startswith(f"| {r['table']} | {b['decided']} of "
                                                f"{b['comparisons']} (") and t.count("|") == 6]
        assert len(line) == 1, r["table"]
        cells = [c.strip() for c in line[0].strip("|").split("|")]
        assert cells[2:] == [f"{p['published']} of {p['of']}",
                             cells[3], f"{p['registered']} of {p['of']}"]
        assert cells[3].startswith(f"{a['decided']} of {a['comparisons']} (")
