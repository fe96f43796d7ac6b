"""The benchmark's time to event end to end (#37 item 5): bsp-convert --benchmark stores
each window's frames to the event (``meta/tte``, hand-computed here from the rows), the
clip reader hands it out, a classification run scores AUROC and AP (the same for any
batch size, recomputable from test_per_recording.json's clips), and ``bsp-eval
--breakdown`` prints AUROC, AP and the three time-to-event bins with counts that add up.
Files without ``meta/tte`` stay readable and say why they have no time-to-event table."""
import json
import shutil

import h5py
import numpy as np
import pytest

import bsp_fast
from bsp_fast import conversion as cv
from bsp_fast.data import ClipDataset
from bsp_fast.metrics import ranking
from bsp_fast.training.evaluate import breakdown, evaluate
from bsp_fast.training.evaluate import main as eval_main
from bsp_fast.training.per_recording import FILE as PER_RECORDING
from bsp_fast.training.per_recording import pooled_clips
from bsp_testdata import recording, write_dataset

pytestmark = [pytest.mark.usefixtures("one_torch_thread"),
              pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]

# ten recordings of frames 0..99; crossers cross from frame 90. With the split's fill rule
# (six windows each) the test split is recordings 2 (a crosser) and 4 (not), val is 1.
CROSSERS = (True, False, True, False, False, True, True, False, True, False)
SPLITS = ("train", "val", "test")


def _uuid(k: int) -> str:
    return f"{k:08x}-0000-4000-8000-000000000000-0"


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    root = tmp_path_factory.mktemp("tte")
    rows = []
    for k, crosses in enumerate(CROSSERS):
        rows += recording(_uuid(k), range(100), crossing_from=90 if crosses else None, seed=k)
    rep = cv.convert(write_dataset(root / "ds", rows), root / "clips.h5", benchmark=True,
                     media=False)
    return root, rep["output"]


@pytest.fixture(scope="module")
def run(converted):
    root, h5 = converted
    return bsp_fast.train("classification", "lstm", data=h5, out=root / "run", epochs=1,
                          batch_size=8, hp={"hidden_size": 8, "num_layers": 1},
                          quiet=True).run_dir


def _split(h5, split):
    with h5py.File(h5, "r") as f:
        g = f[split]
        return {"tte": g["meta/tte"][()], "end": g["meta/end_frame"][()],
                "video": g["meta/video_id"].asstr()[()], "label": g["labels"][()],
                "dtype": g["meta/tte"].dtype}


def test_stored_time_to_event_by_hand(converted):
    _, h5 = converted
    seen = {}
    for split in SPLITS:
        d = _split(h5, split)
        assert d["dtype"] == np.int32
        for v, end, tte in zip(d["video"], d["end"], d["tte"]):
            k = int(v.split("/")[1][:8], 16)
            # a crosser's event is its first crossing frame, 90; a non-crosser's the last
            # frame - 3 = 96 (docs/hdf5-schema.md, Time to event); the window's last frame is end_frame - 1
            event = 90 if CROSSERS[k] else 96
            assert tte == event - (end - 1)
            seen.setdefault(k, {})[int(end) - 16] = int(tte)
    # crosser 0: frames 90-16-60 = 14 .. 60 kept, windows start 14, 20, ..., 44: the first
    # ends at frame 29 (61 frames to the event), the last at 59 (31 frames)
    assert seen[0] == {14: 61, 20: 55, 26: 49, 32: 43, 38: 37, 44: 31}
    # non-crosser 1: frames 20 .. 66, windows start 20 .. 50, the first ends at frame 35
    assert seen[1] == {20: 61, 26: 55, 32: 49, 38: 43, 44: 37, 50: 31}


def test_the_reader_hands_it_out_and_old_files_say_why_not(converted, tmp_path):
    _, h5 = converted
    ds = ClipDataset(h5, "test")
    want = _split(h5, "test")["tte"]
    assert ds.has_tte and ds.tte_problem() is None
    assert ds.time_to_event.tolist() == want.tolist()
    batch = ds[list(range(len(ds)))]
    assert batch["meta"]["tte"].tolist() == want.tolist()
    old = tmp_path / "old.h5"
    shutil.copyfile(h5, old)
    with h5py.File(old, "a") as f:
        for split in SPLITS:
            del f[f"{split}/meta/tte"]
    ds = ClipDataset(old, "test")
    assert not ds.has_tte and set(ds.time_to_event.tolist()) == {-1}
    assert ds[[0, 1]]["meta"]["tte"].tolist() == [-1, -1]
    assert "written before the time to event was stored" in ds.tte_problem()
    assert str(old) in ds.tte_problem()


def test_metrics_have_auroc_and_ap_from_the_per_recording_clips(converted, run):
    _, h5 = converted
    metrics = json.loads((run / "metrics.json").read_text())
    doc = json.loads((run / PER_RECORDING).read_text())
    assert doc["clip_fields"] == ["score", "label", "tte"]
    test = doc["test"]
    assert len(test["clips"]) == len(test["recordings"]) == 2
    c = pooled_clips(test)
    d = _split(h5, "test")
    assert sorted(c["tte"].tolist()) == sorted(d["tte"].tolist())
    assert sorted(c["label"].tolist()) == sorted(d["label"].tolist())
    # the recordings' clips pooled give the run's numbers exactly (a bootstrap's resample
    # of all recordings once each)
    assert metrics["test"]["auroc"] == ranking.auroc(c["score"], c["label"])
    assert metrics["test"]["ap"] == ranking.average_precision(c["score"], c["label"])
    assert 0 <= metrics["test"]["auroc"] <= 1 and 0 < metrics["test"]["ap"] <= 1
    # one recording drawn twice: its clips twice
    assert len(pooled_clips(test, [1, 1])["score"]) == 2 * len(test["clips"][1])
    assert doc["initial"]["clips"]  # the trivial baseline's, for paired comparisons
    # the split's AUROC and AP do not depend on how it is batched
    one, many = (evaluate(run, batch_size=b).metrics for b in (1, 5))
    assert (one["auroc"], one["ap"]) == (many["auroc"], many["ap"]) \
        == (metrics["test"]["auroc"], metrics["test"]["ap"])


def test_breakdown_prints_auroc_ap_and_the_time_to_event_bins(converted, run, capsys):
    _, h5 = converted
    assert eval_main([str(run), "--breakdown", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "| split | clips | F1 | precision | recall | accuracy | AUROC | AP |" in out
    assert "### per time to event (count: clips)" in out
    doc = breakdown(run, quiet=True)
    assert doc["summary"]["auroc"] == doc["metrics"]["auroc"]
    assert doc["summary"]["ap"] == doc["metrics"]["ap"]
    t = next(t for t in doc["tables"] if t["title"] == "per time to event")
    # test windows end 31, 37, 43, 49, 55 and 61 frames before the event, two each
    counts = {r["bin"]: r["count"] for r in t["rows"]}
    assert counts == {"30-39": 4, "40-49": 4, "50-61": 4}
    assert sum(counts.values()) == t["total"] == doc["totals"]["clips"] == 12
    for r in t["rows"]:
        assert f"| {r['bin']} | {r['count']} | {r['crossing']} |" in out
    d = _split(h5, "test")
    for r, (lo, hi) in zip(t["rows"], ((30, 39), (40, 49), (50, 61))):
        sel = (d["tte"] >= lo) & (d["tte"] <= hi)
        assert r["crossing"] == int(d["label"][sel].sum())
        assert set(r) >= {"f1", "precision", "recall", "accuracy", "auroc", "ap"}
    assert not any("time-to-event" in n for n in doc["notes"])


def test_no_event_no_table_and_the_note_says_why(converted, run, tmp_path):
    _, h5 = converted
    old = tmp_path / "old.h5"
    shutil.copyfile(h5, old)
    with h5py.File(old, "a") as f:
        for split in SPLITS:
            del f[f"{split}/meta/tte"]
    doc = breakdown(run, data=old, quiet=True)
    assert all(t["title"] != "per time to event" for t in doc["tables"])
    assert any(n.startswith("no time-to-event table:") and "convert it again" in n
               for n in doc["notes"])
    assert np.isfinite(doc["summary"]["auroc"])  # AUROC and AP need no event


def test_table_breakdown_aggregates_the_time_to_event_bins_over_seeds():
    """bsp-reproduce --breakdown: the time-to-event table's F1, AUROC and AP, mean ± std
    over seeds; a seed's document saved before the table existed adds nothing to it."""
    from bsp_fast.reporting.breakdown import format_aggregate
    from bsp_fast.reproduction.table_breakdown import aggregate
    from bsp_fast.training.tasks import metric_formats

    profile = {"title": "per age/gender profile", "by": "profile", "count": "clips",
               "columns": {"crossing": "crossing clips", "f1": "F1"},
               "rows": [{"bin": "adult/female", "count": 12, "crossing": 6, "f1": 0.5}]}

    def doc(f1, auc):
        rows = [{"bin": "30-39", "count": 4, "crossing": 2, "f1": f1, "auroc": auc,
                 "ap": 0.75}]
        tte = {"title": "per time to event", "by": "frames to the event", "count": "clips",
               "columns": {"crossing": "crossing clips", "f1": "F1", "auroc": "AUROC",
                           "ap": "AP"}, "rows": rows, "aggregate": ["f1", "auroc", "ap"]}
        return {"tables": [profile, tte]}

    old = {"tables": [profile]}  # saved before the time-to-event table
    agg = aggregate({"lstm": [doc(0.5, 0.6), doc(0.7, 0.8), old]})
    assert [a["title"] for a in agg] == ["per age/gender profile", "per time to event",
                                         "per time to event (AUROC)", "per time to event (AP)"]
    f1, auc, ap = (a["rows"]["lstm"]["30-39"] for a in agg[1:])
    assert f1["mean"] == pytest.approx(0.6) and f1["seeds"] == 2
    assert auc["mean"] == pytest.approx(0.7) and auc["std"] == pytest.approx(0.02 ** 0.5)
    assert ap == {"mean": 0.75, "std": 0.0, "seeds": 2, "count": 4.0}
    assert agg[0]["rows"]["lstm"]["adult/female"]["seeds"] == 3
    md = format_aggregate(agg, {"lstm": "LSTM"}, 3, "## t", metric_formats())
    assert "### per time to event (AUROC): AUROC (count: clips)" in md
    assert "| 30-39 | 0.700 ± 0.141 (n 4) |" in md


def test_two_ddp_ranks_gather_every_clip(converted, tmp_path):
    """Under DDP (two gloo ranks on CPU) AUROC and AP are computed from both ranks' clips
    and the per-recording file holds every test clip once: the same numbers as a
    one-process evaluation of the checkpoint."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    _, h5 = converted
    repo = Path(__file__).resolve().parents[2]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(
        [str(repo / "python"), os.environ.get("PYTHONPATH", "")]))
    out = tmp_path / "ddp"
    proc = subprocess.run(
        [sys.executable, "-m", "bsp_fast", "train", "classification", "lstm", "--data",
         str(h5), "--out", str(out), "--epochs", "1", "--batch-size", "4", "--accelerator",
         "cpu", "--devices", "2", "--strategy", "ddp", "--threads", "1", "--quiet",
         "--hp", "hidden_size=8", "--hp", "num_layers=1"],
        env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["world_size"] == 2
    c = pooled_clips(json.loads((out / PER_RECORDING).read_text())["test"])
    assert sorted(c["tte"].tolist()) == sorted(_split(h5, "test")["tte"].tolist())
    assert saved["test"]["auroc"] == ranking.auroc(c["score"], c["label"])
    single = evaluate(out).metrics
    assert (single["auroc"], single["ap"]) == pytest.approx(
        (saved["test"]["auroc"], saved["test"]["ap"]), rel=1e-6)


def test_the_conversion_cache_reconverts_a_benchmark_file_without_tte(converted, tmp_path):
    from bsp_fast.data import cache

    root, h5 = converted
    settings = cv.conversion_settings(root / "ds", benchmark=True, media=False)
    csv = root / "ds" / "data.csv"
    assert cache.stale_reason(h5, settings, csv) is None
    old = tmp_path / "old.h5"
    shutil.copyfile(h5, old)
    with h5py.File(old, "a") as f:
        del f["test/meta/tte"]
    assert "meta/tte" in cache.stale_reason(old, settings, csv)
