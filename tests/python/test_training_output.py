"""What bsp-train prints (issue 28 items 3, 8, 9): a bad model option is refused before any
data is converted; in a log file or a pipe the progress is plain lines, not a bar redrawn
with carriage returns; --quiet still prints the results table and the path written."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("lightning")

from bsp_fast.data.testing import write_clip_file  # noqa: E402
from bsp_fast.training.train import main as train_main  # noqa: E402

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]
TINY = ["--hp", "hidden_size=8", "--hp", "num_layers=1", "--batch-size", "8",
        "--threads", "1"]


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    path = tmp_path_factory.mktemp("out") / "clips.h5"
    write_clip_file(path, clips=(24, 8, 8), clip_length=8, seed=3)
    return path


def test_bad_model_option_is_refused_before_any_conversion(tmp_path, capsys):
    from bsp_fast.synth import generate

    ds = tmp_path / "ds"
    generate(ds, "sample", clips=2, frames=40, size="320x120", seed=1, poses_only=True,
             workers=1, progress=False)
    rc = train_main(["autoencoder", "simple_transformer", "--data", str(ds), "--hp",
                     "nhead=3", "--out", str(tmp_path / "run"), "--quiet"])
    assert rc == 2
    assert "simple_transformer" in capsys.readouterr().err
    assert sorted(p.name for p in ds.iterdir()) == ["config.yaml", "data.csv"]  # no cache


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))


@pytest.fixture(scope="module")
def piped_run(clips, tmp_path_factory):
    """bsp-train with its stdout and stderr in a pipe (not a terminal): (result, run)."""
    run = tmp_path_factory.mktemp("piped") / "run"
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "train", "classification", "lstm",
                        "--data", str(clips), "--epochs", "3", "--out", str(run)] + TINY,
                       capture_output=True, text=True, env=_env(), timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    return p, run


def test_progress_in_a_pipe_is_plain_lines(piped_run):
    p, _ = piped_run
    assert "\r" not in p.stderr and "\x1b[" not in p.stderr
    done = [ln for ln in p.stderr.splitlines() if " done: " in ln]
    assert [ln.split("] ")[1].split(" done")[0] for ln in done] == \
        ["epoch 1/3", "epoch 2/3", "epoch 3/3"]
    assert "val/loss" in done[-1] and len(p.stderr) < 5000


def test_every_epoch_line_has_its_own_train_loss(piped_run):
    """Issue 40 item 5: the first epoch's line had no train/loss (the module logs it after
    the callbacks' epoch end) and each later line showed the epoch before's."""
    import csv

    p, run = piped_run
    done = [ln for ln in p.stderr.splitlines() if " done: " in ln]
    shown = [float(re.search(r"train/loss (\S+?)(,|$)", ln).group(1)) for ln in done]
    with open(next(run.glob("logs/version_*/metrics.csv")), newline="") as fh:
        logged = [float(r["train/loss"]) for r in csv.DictReader(fh) if r.get("train/loss")]
    assert len(shown) == len(logged) == 3
    assert shown == pytest.approx(logged, rel=1e-3)  # printed with 4 significant digits
    assert all("val/loss" in ln for ln in done)


def test_predict_in_a_pipe_has_no_lightning_bar(piped_run, tmp_path):
    """Issue 40 item 7: bsp-predict off a terminal writes bsp-train's plain lines, not
    Lightning's bar ("Predicting: | 0/?" redrawn with carriage returns)."""
    _, run = piped_run
    out = tmp_path / "preds.h5"
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "predict", str(run), "--out",
                        str(out)], capture_output=True, text=True, env=_env(), timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    both = p.stdout + p.stderr
    assert "\r" not in both and "\x1b[" not in both and "Predicting" not in both
    assert "it/s" not in both and "|" not in both
    assert re.search(r"^\[ *\d+\.\d s\] predicting done: 1 batch\(es\)$", p.stderr, re.M), \
        p.stderr
    assert p.stdout.startswith(f"wrote {out}: 8 test clips") and out.is_file()


def test_quiet_keeps_the_results_table_and_the_path(clips, tmp_path, capsys):
    out = tmp_path / "run"
    assert train_main(["classification", "lstm", "--data", str(clips), "--epochs", "1",
                       "--out", str(out), "--quiet"] + TINY) == 0
    printed = capsys.readouterr().out
    assert "| model " in printed and "| F1 " in printed and f"wrote {out}" in printed
    assert "initial metrics" not in printed  # the per-run chatter stays off
