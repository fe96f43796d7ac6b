"""Issue 40, more rough edges a new user met: bsp-preview's frame count, bsp-eval finding
the run's dataset folder, bsp-synth's progress in a log file. (Item 3, the README's Quick
start run twice: test_readme.py; items 5 and 7, bsp-train's epoch lines and bsp-predict's
progress: test_training_output.py.)"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "python")] + sys.path))


# ------------------------------------------------------------------ 4: bsp-preview frames
def test_preview_frames_counts_the_frames_the_picture_shows(tmp_path, capsys):
    pytest.importorskip("cv2")
    from bsp_fast.preview.cli import main
    from bsp_fast.synth import generate

    ds = tmp_path / "ds"
    generate(ds, "sample", clips=2, frames=150, size="320x120", seed=1, workers=1,
             progress=False)
    out = tmp_path / "x.png"
    assert main(["frames", str(ds), "--recording", "0", "--frames", "60,140",
                 "--out", str(out)]) == 0
    assert re.fullmatch(rf"wrote {re.escape(str(out))} \(\d+x\d+, 2 frame\(s\)\)\n",
                        capsys.readouterr().out)
    assert main(["frames", str(ds), "--recording", "0", "--frames", "10:40:10",
                 "--out", str(tmp_path / "y.mp4")]) == 0
    assert "3 frame(s)" in capsys.readouterr().out  # MP4: one video frame each


# ------------------------------------------------------------------ 6: bsp-eval's dataset
def _uuid(k: int) -> str:
    return f"{k:08x}-0000-4000-8000-000000000000-0"


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_eval_reads_the_runs_dataset_folder_from_its_config(tmp_path, capsys, monkeypatch):
    pytest.importorskip("lightning")
    sys.path.insert(0, str(Path(__file__).parent))
    from bsp_testdata import recording, write_dataset

    from bsp_fast.training.evaluate import main as eval_main
    from bsp_fast.training.train import main as train_main

    rows = []
    for k in range(8):
        rows += recording(_uuid(k), range(36), crossing_from=18 if k % 2 else None, seed=k)
    ds = write_dataset(tmp_path / "ds", rows)
    run = tmp_path / "run"
    monkeypatch.chdir(tmp_path)  # trained with --data ds (relative), scored from elsewhere
    assert train_main(["classification", "lstm", "--data", "ds", "--clip-length", "12",
                       "--epochs", "1", "--batch-size", "8", "--threads", "1", "--hp",
                       "hidden_size=8", "--hp", "num_layers=1", "--out", str(run),
                       "--quiet"]) == 0
    capsys.readouterr()
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert eval_main([str(run)]) == 0
    printed = capsys.readouterr()
    assert "no dataset directory given" not in printed.err
    assert "reusing" in printed.err and "same conversion options and data.csv" in printed.err
    assert "test metrics" in printed.out

    # the run's file no longer matches the folder's data.csv: converted again, not scored
    csv = Path(ds) / "data.csv"
    lines = csv.read_text().splitlines(keepends=True)
    csv.write_text("".join(lines[:-12]))  # the last recording loses its last rows
    assert eval_main([str(run)]) == 0
    err = capsys.readouterr().err
    assert "converting again" in err and "no dataset directory given" not in err


# ------------------------------------------------------------------ 10: bsp-synth in a log
def test_synth_in_a_log_file_writes_plain_lines(tmp_path):
    log = tmp_path / "synth.log"
    with open(log, "w") as fh:
        r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", str(tmp_path / "ds"),
                            "--clips", "3", "--frames", "30", "--size", "160x60",
                            "--poses-only", "--workers", "2", "--seed", "3"],
                           stdout=fh, stderr=subprocess.STDOUT, env=_env(), timeout=600)
    text = log.read_text()
    assert r.returncode == 0, text
    assert "\r" not in text and "\x1b[" not in text and "it/s" not in text
    assert re.search(r"^\[ *\d+\.\d s\] clips 3/3 done$", text, re.M), text
    assert "wrote 3 clips" in text


def test_plain_lines_say_the_count_every_interval(capsys):
    from bsp_fast._plain_progress import PlainLines

    bar = PlainLines(3, "clips", interval=0.0)
    for _ in range(3):
        bar.update(1)
    bar.close()
    bar.close()
    lines = [ln.split("] ", 1)[1] for ln in capsys.readouterr().err.splitlines()]
    assert lines == ["clips 1/3", "clips 2/3", "clips 3/3 done"]


def test_synth_keeps_its_bar_on_a_terminal(monkeypatch):
    import importlib

    g = importlib.import_module("bsp_fast.synth.generate")  # the module, not the function

    monkeypatch.setattr("bsp_fast._plain_progress.is_terminal", lambda stream: True)
    assert type(g._progress_bar(3, True)).__name__ != "PlainLines"
    monkeypatch.setattr("bsp_fast._plain_progress.is_terminal", lambda stream: False)
    assert type(g._progress_bar(3, True)).__name__ == "PlainLines"
    assert getattr(g._progress_bar(3, False), "disable", False)  # progress=False: nothing
