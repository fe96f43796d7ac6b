"""Resuming an interrupted run at any ``--epochs`` (issue 34): it finishes the interrupted
epoch, or stops at once when its epochs were done, then tests the best checkpoint (the
last one, said so, when no validation ever ran) and writes metrics.json; never a traceback.

The SIGTERM lands at a chosen batch: the run's Lifecycle hook is wrapped so that, at that
batch, a real bsp-train subprocess writes a file and waits for the test's signal (or, in
process, sends the signal to itself)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bsp_fast.data.testing import write_clip_file
from bsp_fast.training import lifecycle, stopping
from bsp_fast.training.train import main as train_main

pytestmark = pytest.mark.usefixtures("one_torch_thread")

REPO = Path(__file__).resolve().parents[2]
# 48 train clips in batches of 8: 6 batches per epoch (batch_idx 5 is an epoch's last)
ARGS = ["lifting", "baseline_3d", "--epochs", "3", "--batch-size", "8", "--threads", "1",
        "--seed", "7", "--quiet", "--hp", "linear_size=32", "--hp", "num_blocks=1"]
LAST = 5

# bsp-train with its Lifecycle hook wrapped: at batch STOP_AT=epoch,batch_idx it writes
# READY and waits for the signal, which the test sends (then the run handles it as always)
LAUNCHER = """
import os, sys, time
from pathlib import Path
from bsp_fast.training import lifecycle, stopping
epoch, batch = map(int, os.environ["STOP_AT"].split(","))
orig = lifecycle.Lifecycle.on_train_batch_end
def hook(self, trainer, pl_module, outputs, b, batch_idx):
    if (trainer.current_epoch, batch_idx) == (epoch, batch):
        Path(os.environ["READY"]).write_text("ready")
        t0 = time.monotonic()
        while self.sig.received is None and time.monotonic() - t0 < 120:
            time.sleep(0.01)
    return orig(self, trainer, pl_module, outputs, b, batch_idx)
lifecycle.Lifecycle.on_train_batch_end = hook
from bsp_fast.training.train import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("resume_epochs")
    write_clip_file(root / "clips.h5", clips=(48, 16, 16), clip_length=8, seed=3)
    return root / "clips.h5"


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "python")] +
                                        [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _metrics(run: Path) -> dict:
    return json.loads((run / "metrics.json").read_text())


def _incomplete(run: Path) -> dict:
    assert not (run / "metrics.json").exists()
    marker = json.loads((run / "incomplete.json").read_text())
    assert marker["state"] == "interrupted" and marker["signal"] == "SIGTERM"
    return marker


@pytest.mark.parametrize("batch", [2, LAST])
def test_sigterm_in_first_epoch_then_resume_with_epochs_1(clips, tmp_path, batch):
    """The issue's case, with real processes: SIGTERM in epoch 1, ``--resume --epochs 1``
    finishes that epoch (or, signalled in its last batch, the run had stopped after its
    validation: no more training), tests best.ckpt and writes metrics.json."""
    out, ready = tmp_path / "run", tmp_path / "ready"
    launcher = tmp_path / "launch.py"
    launcher.write_text(LAUNCHER)
    env = dict(_env(), STOP_AT=f"0,{batch}", READY=str(ready))
    proc = subprocess.Popen([sys.executable, str(launcher), *ARGS, "--data", str(clips),
                             "--out", str(out)], env=env, cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while not ready.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < 120, "bsp-train did not reach the batch in time"
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "Traceback" not in err
    marker = _incomplete(out)
    assert (marker["epoch"], marker["batches_done"]) == (1, batch + 1)
    assert f"interrupted (SIGTERM) at epoch 1 step {batch + 1}" in err

    res = subprocess.run([sys.executable, "-m", "bsp_fast", "train", "--resume", str(out),
                          "--epochs", "1", "--quiet"], env=_env(), cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    assert ("no more training" in res.stderr) == (batch == LAST), res.stderr
    assert "no validation ran" not in res.stderr
    assert not (out / "incomplete.json").exists()
    m = _metrics(out)
    assert m["epochs"] == 1 and m["best_epoch"] == 1 and m["tested"] == "best"
    assert {"mpjpe_mm", "loss"} <= set(m["test"]) and m["val"]
    assert (out / "checkpoints" / "best.ckpt").is_file()


# ---------------------------------------------------------------------- in process
def _stop_at(monkeypatch, epoch: int, batch: int, legacy: bool = False):
    """A real SIGTERM to this process at that batch. ``legacy``: stop there even after an
    epoch's last batch, as bsp-train did before (a checkpoint Lightning resumes as a
    finished epoch without its validation)."""
    orig = lifecycle.Lifecycle.on_train_batch_end

    def hook(self, trainer, pl_module, outputs, b, batch_idx):
        if (trainer.current_epoch, batch_idx) == (epoch, batch):
            os.kill(os.getpid(), signal.SIGTERM)
            t0 = time.monotonic()
            while self.sig.received is None and time.monotonic() - t0 < 10:
                time.sleep(0.001)
            if legacy:
                self.epoch, self.batches_done = trainer.current_epoch, batch_idx + 1
                self.step = trainer.global_step
                self.save(trainer, state="interrupted", signal="SIGTERM")
                raise stopping.Interrupted(self.sig.received)
        return orig(self, trainer, pl_module, outputs, b, batch_idx)

    monkeypatch.setattr(lifecycle.Lifecycle, "on_train_batch_end", hook)


def _stop_in_validation(monkeypatch, epoch: int):
    """A real SIGTERM to this process during the validation of that epoch."""
    def hook(self, trainer, pl_module, outputs, b, batch_idx, dataloader_idx=0):
        if trainer.current_epoch == epoch and batch_idx == 0 and self.sig.received is None:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(lifecycle.Lifecycle, "on_validation_batch_end", hook, raising=False)


def _interrupt(monkeypatch, capsys, clips, out, epoch, batch, *extra, legacy=False) -> dict:
    with monkeypatch.context() as m:
        if batch is None:
            _stop_in_validation(m, epoch)
        else:
            _stop_at(m, epoch, batch, legacy)
        code = train_main([*ARGS, "--data", str(clips), "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert code == 143, err
    assert "Traceback" not in err
    return _incomplete(out)


def _resume(capsys, out, epochs: int) -> str:
    code = train_main(["--resume", str(out), "--epochs", str(epochs), "--quiet"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "Traceback" not in err
    assert not (out / "incomplete.json").exists()
    assert (out / "checkpoints" / "best.ckpt").is_file()
    return err


def test_epochs_already_done_stops_at_once(clips, tmp_path, monkeypatch, capsys):
    """Interrupted in epoch 2 of 3, resumed with --epochs 1: epoch 1 was done (validated),
    so no more training; its best checkpoint is tested."""
    out = tmp_path / "run"
    marker = _interrupt(monkeypatch, capsys, clips, out, 1, 2)
    assert (marker["epoch"], marker["batches_done"]) == (2, 3)
    err = _resume(capsys, out, 1)
    assert "the run had already completed its 1 epoch: no more training" in err
    m = _metrics(out)
    assert (m["epochs"], m["best_epoch"], m["tested"]) == (1, 1, "best")


def test_signal_in_first_validation_then_epochs_1(clips, tmp_path, monkeypatch, capsys):
    """SIGTERM while epoch 1 validates: the run stops after it with the end-of-epoch
    last.ckpt, which holds that epoch's best score: --epochs 1 tests its best.ckpt."""
    out = tmp_path / "run"
    marker = _interrupt(monkeypatch, capsys, clips, out, 0, None)
    assert (marker["epoch"], marker["batches_done"]) == (1, LAST + 1)
    err = _resume(capsys, out, 1)
    assert "the run had already completed its 1 epoch: no more training" in err
    m = _metrics(out)
    assert (m["epochs"], m["best_epoch"], m["tested"]) == (1, 1, "best")


def test_signal_in_last_batch_stops_after_validation_and_epochs_below(clips, tmp_path,
                                                                       monkeypatch, capsys):
    """A signal in an epoch's last batch stops after that epoch's validation (a checkpoint
    there would be resumed without it); --epochs below the epochs done keeps them."""
    out = tmp_path / "run"
    marker = _interrupt(monkeypatch, capsys, clips, out, 1, LAST)
    assert (marker["epoch"], marker["batches_done"]) == (2, LAST + 1)
    err = _resume(capsys, out, 1)
    assert "--epochs 1 is below the 2 epochs this run had already completed" in err
    m = _metrics(out)
    assert m["epochs"] == 2 and m["best_epoch"] in (1, 2) and m["tested"] == "best"
    assert "epochs: 2" in (out / "config.yaml").read_text()


def test_no_validation_ever_tests_the_last_checkpoint(clips, tmp_path, monkeypatch, capsys):
    """--max-steps within the first epoch: no epoch was validated, so the last checkpoint is
    validated and tested, said so, and saved as best.ckpt for bsp-eval."""
    out = tmp_path / "run"
    _interrupt(monkeypatch, capsys, clips, out, 0, 1, "--max-steps", "4")
    err = _resume(capsys, out, 1)
    assert "no validation ran in this run" in err and "tested the last one" in err
    m = _metrics(out)
    assert m["tested"] == "last" and m["best_epoch"] is None and m["epochs"] == 1
    assert {"mpjpe_mm", "loss"} <= set(m["test"]) and {"mpjpe_mm", "loss"} <= set(m["val"])
    from bsp_fast.training.evaluate import main as eval_main

    assert eval_main([str(out), "--quiet"]) == 0, capsys.readouterr().err


def test_legacy_checkpoint_after_the_last_batch(clips, tmp_path, monkeypatch, capsys):
    """A run left by an earlier bsp-train with last.ckpt taken after epoch 1's last batch
    (Lightning resumes it as a finished epoch, without its validation): --epochs 1 tests
    the last checkpoint and says so, instead of Lightning's ValueError."""
    out = tmp_path / "run"
    marker = _interrupt(monkeypatch, capsys, clips, out, 0, LAST, legacy=True)
    assert (marker["epoch"], marker["batches_done"]) == (1, LAST + 1)
    err = _resume(capsys, out, 1)
    assert "no validation ran in this run" in err
    assert _metrics(out)["tested"] == "last"
