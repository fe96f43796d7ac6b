"""Runs that survive interruption: SIGTERM/SIGINT sent to real bsp-train processes,
``kill -9`` then ``--resume``, a full disk while saving, broken checkpoints to resume,
and a resumed run ending exactly where an uninterrupted one does (CPU, one thread)."""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

import bsp_fast
from bsp_fast.data.testing import write_clip_file
from bsp_fast.training import lifecycle, stopping
from bsp_fast.training import runs as runs_mod
from bsp_fast.training.config import parse_duration
from bsp_fast.training.train import main as train_main

REPO = Path(__file__).resolve().parents[2]
MODEL = ["lifting", "baseline_3d"]
HP = {"linear_size": 32, "num_blocks": 1}  # with dropout: the random state must resume too
EPOCHS = 60


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("lifecycle")
    write_clip_file(root / "clips.h5", clips=(48, 16, 16), clip_length=8, seed=3)
    return root / "clips.h5"


def _opts(**kw):
    return dict(dict(epochs=EPOCHS, batch_size=8, hp=HP, quiet=True, threads=1, seed=7), **kw)


@pytest.fixture(scope="module")
def uninterrupted(clips, tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "run"
    return bsp_fast.train(*MODEL, data=clips, out=out, **_opts())


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO / "python")] +
                                        [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _start(clips, out, *extra, cwd=None):
    hp = [f"--hp={k}={v}" for k, v in HP.items()]
    cmd = [sys.executable, "-m", "bsp_fast", "train", *MODEL, "--data", str(clips), "--out",
           str(out), "--epochs", str(EPOCHS), "--batch-size", "8", "--threads", "1",
           "--seed", "7", "--quiet", *hp, *extra]
    return subprocess.Popen(cmd, env=_env(), cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _resume(out, *extra):
    """``bsp-train --resume out --quiet`` started in a process of its own."""
    cmd = [sys.executable, "-m", "bsp_fast", "train", "--resume", str(out), "--quiet", *extra]
    return subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _wait_for_marker(out: Path, proc, ok=lambda marker: True, timeout: float = 120.0) -> Path:
    """The temporary directory of ``proc``'s run (its marker names the process) once the
    marker satisfies ``ok``; the temporary directories of other processes are ignored."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        assert proc.poll() is None, proc.communicate()
        for tmp in out.parent.glob(f".{out.name}.tmp-*"):
            marker = runs_mod.read_marker(tmp) or {}
            if marker.get("pid") == proc.pid and ok(marker):
                return tmp
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("bsp-train's run did not get there in time")


def _wait_for_training(out: Path, proc, epoch: int = 3) -> Path:
    """The run's temporary directory once its marker says ``epoch`` was reached."""
    return _wait_for_marker(out, proc, lambda marker: (marker.get("epoch") or 0) >= epoch)


def _wait_for_best(out: Path, proc, timeout: float = 120.0) -> Path:
    """The run's temporary directory once its first validation wrote best.ckpt: training
    is in its second epoch or later (the default --checkpoint-every has saved nothing)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        assert proc.poll() is None, proc.communicate()
        for tmp in out.parent.glob(f".{out.name}.tmp-*"):
            if (tmp / "checkpoints" / "best.ckpt").is_file():
                return tmp
        time.sleep(0.05)
    proc.kill()
    raise AssertionError("bsp-train did not validate in time")


def _stop_after_first_validation(clips, out: Path) -> None:
    """A run stopped by SIGTERM once it validated: an incomplete run at ``out``."""
    proc = _start(clips, out)
    _wait_for_best(out, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err


def _test_metrics(run: Path) -> dict:
    return json.loads((run / "metrics.json").read_text())["test"]


@pytest.mark.parametrize("signum,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_saves_and_resume_ends_like_an_uninterrupted_run(clips, uninterrupted,
                                                                tmp_path, signum, code):
    out = tmp_path / "run"
    proc = _start(clips, out, cwd=tmp_path)  # outside the repository
    tmp = _wait_for_best(out, proc)
    assert not (tmp / "checkpoints" / "last.ckpt").exists()  # none due yet (5m)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert f"continue with: bsp-train --resume {out}" in err
    assert "interrupted" in err and "Traceback" not in err
    # an incomplete run: a marker with the position, a checkpoint, no metrics.json
    assert not (out / "metrics.json").exists()
    marker = json.loads((out / "incomplete.json").read_text())
    assert marker["state"] == "interrupted" and marker["signal"] == signal.Signals(signum).name
    assert f"epoch {marker['epoch']} step {marker['step']}" in err
    ckpt = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)
    assert ckpt["global_step"] == marker["step"] > 0
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    # nothing takes it for a finished run
    from bsp_fast.training.evaluate import main as eval_main

    assert eval_main([str(out)]) == 1
    # resumed from another directory: the saved config's paths still work
    res = subprocess.run([sys.executable, "-m", "bsp_fast", "train", "--resume", str(out),
                          "--quiet"], env=_env(), cwd=tmp_path.parent, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert not (out / "incomplete.json").exists()
    # bit-identical on CPU: same weights, same test metrics (tolerance 0)
    assert _test_metrics(out) == uninterrupted.metrics
    a = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)["state_dict"]
    b = torch.load(uninterrupted.last_checkpoint, weights_only=True)["state_dict"]
    assert all(torch.equal(a[k], b[k]) for k in b)


def test_a_stopped_run_continued_then_killed_resumes_from_the_continuation(clips,
                                                                           uninterrupted,
                                                                           tmp_path):
    # stopped (SIGTERM: published as an incomplete run), continued, killed (-9) after the
    # continuation saved later steps: --resume continues from the continuation's checkpoint,
    # not the older published one (hours of work on a long run), and the published run
    # leaves no hidden copy behind, nor the copy of a continuation killed before its save
    out = tmp_path / "run"
    _stop_after_first_validation(clips, out)
    stopped_at = runs_mod.read_marker(out)["step"]
    # a continuation killed before it saved: a copy of the stopped run, nothing more
    early = _resume(out)
    _wait_for_marker(out, early)
    early.kill()
    early.communicate(timeout=60)
    # a continuation killed after saving later steps
    proc = _resume(out, "--checkpoint-every", "0.05s")
    ahead = _wait_for_marker(out, proc, lambda m: (m.get("step") or 0) > stopped_at + 12)
    proc.kill()
    proc.communicate(timeout=60)
    assert runs_mod.resumable(out) == ahead
    assert runs_mod.resolve_checkpoint(out, "last")[0] == ahead / "checkpoints" / "last.ckpt"
    res = bsp_fast.train(resume=out, quiet=True)
    assert res.run_dir == out and not (out / "incomplete.json").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert _test_metrics(out) == uninterrupted.metrics


def test_a_signal_between_epochs_trains_on_to_the_next_batch_and_saves(clips, uninterrupted,
                                                                       tmp_path, monkeypatch):
    # the window CI's race hit: a signal after an epoch's end saved nothing (the default
    # cadence not yet due) and before the next epoch starts. It used to stop there with no
    # last.ckpt of the process (the run discarded); now the next batch end saves and stops
    real = lifecycle.Lifecycle.on_train_epoch_start

    def signalled(self, trainer, pl_module):
        if trainer.current_epoch == 2:
            os.kill(os.getpid(), signal.SIGINT)  # handled (deferred) before the next line
        return real(self, trainer, pl_module)

    monkeypatch.setattr(lifecycle.Lifecycle, "on_train_epoch_start", signalled)
    out = tmp_path / "run"
    with pytest.raises(stopping.Interrupted):
        bsp_fast.train(*MODEL, data=clips, out=out, **_opts())
    monkeypatch.setattr(lifecycle.Lifecycle, "on_train_epoch_start", real)
    ckpt = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)
    assert ckpt["global_step"] == 2 * 6 + 1  # two epochs of 6 batches, then one batch
    marker = json.loads((out / "incomplete.json").read_text())
    assert (marker["state"], marker["step"]) == ("interrupted", 13)
    bsp_fast.train(resume=out, quiet=True)
    assert _test_metrics(out) == uninterrupted.metrics


@pytest.mark.parametrize("carry", [[1000.0, 900.0], None])
def test_fit_seconds_add_up_over_the_processes_of_a_resumed_run(clips, uninterrupted,
                                                                tmp_path, carry):
    # the seconds a run records are its whole fit's, not its last process's: every
    # checkpoint carries the fit seconds so far, and a resumed run adds its own to them
    out = tmp_path / "run"
    _stop_after_first_validation(clips, out)
    last = out / "checkpoints" / "last.ckpt"
    ckpt = torch.load(last, weights_only=True)
    wall, cpu = ckpt["callbacks"]["BSPLifecycle"]["fit_seconds"]
    assert 0 < cpu and 0 < wall
    # a known carry, so that the sum can be checked: as if earlier processes had trained
    # for 1,000 s (wall) and 900 s (CPU); None: a checkpoint written before the carry
    if carry is None:
        del ckpt["callbacks"]["BSPLifecycle"]["fit_seconds"]
    else:
        ckpt["callbacks"]["BSPLifecycle"]["fit_seconds"] = carry
    torch.save(ckpt, last)
    t0, c0 = time.perf_counter(), time.process_time()
    bsp_fast.train(resume=out, quiet=True)
    took, took_cpu = time.perf_counter() - t0, time.process_time() - c0
    sec = json.loads((out / "metrics.json").read_text())["seconds"]
    wall, cpu = carry or (0.0, 0.0)
    assert wall < sec["fit"] < wall + took and cpu < sec["fit_cpu"] < cpu + took_cpu
    # the record says whether it covers every process: carried, or partial (a lower bound)
    assert (sec.get("carried"), sec.get("partial")) == ((True, None) if carry else (None, True))
    assert _test_metrics(out) == uninterrupted.metrics


@pytest.mark.parametrize("every, saves", [("1h", 1), ("0", EPOCHS)])
def test_last_ckpt_is_saved_by_time_and_after_the_last_epoch(clips, uninterrupted, tmp_path,
                                                              monkeypatch, every, saves):
    # a save at every epoch end cost 7 % of a run of short epochs; by time, the finished
    # run still ends with its final state in last.ckpt (0: every epoch end, as before)
    written = []
    real = lifecycle.write_bytes

    def counting(path, data, **kw):
        written.append(Path(path).name)
        real(path, data, **kw)

    monkeypatch.setattr(lifecycle, "write_bytes", counting)
    out = tmp_path / "run"
    res = bsp_fast.train(*MODEL, data=clips, out=out, **_opts(checkpoint_every=every))
    assert written.count("last.ckpt") == saves
    assert res.metrics == uninterrupted.metrics
    a = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)
    b = torch.load(uninterrupted.last_checkpoint, weights_only=True)
    assert a["global_step"] == b["global_step"] == EPOCHS * 6  # 48 clips / batch 8
    assert all(torch.equal(a["state_dict"][k], b["state_dict"][k]) for k in b["state_dict"])


def test_kill_9_resumes_from_the_last_periodic_checkpoint(clips, uninterrupted, tmp_path):
    out = tmp_path / "run"
    proc = _start(clips, out, "--checkpoint-every", "0.05s")
    tmp = _wait_for_training(out, proc, epoch=4)
    proc.kill()  # SIGKILL: no handler runs
    proc.communicate(timeout=60)
    assert not out.exists() and tmp.is_dir()
    marker = runs_mod.read_marker(tmp)
    assert marker["state"] == "running" and marker["pid"] == proc.pid
    ckpt = torch.load(tmp / "checkpoints" / "last.ckpt", weights_only=True)
    assert ckpt["global_step"] > 0
    res = bsp_fast.train(resume=out, quiet=True)  # finds the killed run's directory
    assert res.run_dir == out and not tmp.exists()
    assert _test_metrics(out) == uninterrupted.metrics


def test_a_continued_killed_run_stopped_again_leaves_no_stale_copy(clips, uninterrupted,
                                                                   tmp_path):
    # killed (-9) at epoch 2, continued, then stopped with SIGTERM: the stopped run is
    # published under its name and the killed run's temporary directory, now superseded,
    # is removed (a copy left behind would be found again as a run to continue)
    out = tmp_path / "run"
    proc = _start(clips, out, "--checkpoint-every", "0.05s")
    orphan = _wait_for_training(out, proc, epoch=2)
    proc.kill()
    proc.communicate(timeout=60)
    killed_at = runs_mod.read_marker(orphan)["epoch"]
    proc = _resume(out)  # its own temporary directory, past the killed epoch:
    _wait_for_marker(out, proc, lambda m: (m.get("epoch") or 0) > killed_at)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert (out / "incomplete.json").is_file() and not orphan.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert runs_mod.resumable(out) == out
    res = bsp_fast.train(resume=out, quiet=True)
    assert res.run_dir == out and not (out / "incomplete.json").exists()
    assert _test_metrics(out) == uninterrupted.metrics


def test_mid_epoch_checkpoint_resumes_exactly(clips, uninterrupted, tmp_path, monkeypatch):
    # a checkpoint after every batch, and the run stopped by a full disk mid-epoch
    out = tmp_path / "run"
    calls = {"n": 0}
    real = lifecycle.write_bytes

    def failing(path, data, **kw):
        calls["n"] += 1
        last = Path(path).with_name("last.ckpt")
        if calls["n"] > 15 and last.is_file():  # the disk fills after a mid-epoch save
            done = torch.load(last, weights_only=True)["callbacks"]["BSPLifecycle"]
            if done["batches_done"] < 6:
                raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, data, **kw)

    monkeypatch.setattr(lifecycle, "write_bytes", failing)
    args = [*MODEL, "--data", str(clips), "--out", str(out), "--epochs", str(EPOCHS),
            "--batch-size", "8", "--threads", "1", "--seed", "7", "--quiet",
            "--checkpoint-every", "0.001s", *[f"--hp={k}={v}" for k, v in HP.items()]]
    code = train_main(args)
    assert code == 1
    monkeypatch.setattr(lifecycle, "write_bytes", real)
    marker = runs_mod.read_marker(out)
    assert marker["state"] == "failed" and "No space left on device" in marker["reason"]
    before = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)
    assert before["global_step"] == marker["step"] > 0  # the previous checkpoint, whole
    assert 0 < before["callbacks"]["BSPLifecycle"]["batches_done"] < 6  # mid-epoch
    assert train_main(["--resume", str(out), "--quiet"]) == 0
    assert _test_metrics(out) == uninterrupted.metrics


@pytest.mark.parametrize("caps", [["--max-steps", "340", "--early-stop", "20"],
                                  ["--early-stop", "20"]])
def test_kill_9_after_an_epoch_end_checkpoint_with_update_cap_and_early_stop(clips, tmp_path,
                                                                            caps):
    # the matched-updates rows' settings: Lightning resumed an epoch-end checkpoint of a
    # run with max_steps by re-running the epoch's end hooks, and EarlyStopping raised
    # ("val/loss ... not available"): such a run could not be resumed at all
    whole = tmp_path / "whole"
    proc = _start(clips, whole, "--checkpoint-every", "0", *caps)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    out = tmp_path / "run"
    proc = _start(clips, out, "--checkpoint-every", "0", *caps)  # epoch-end saves only
    tmp = _wait_for_training(out, proc, epoch=4)
    proc.kill()
    proc.communicate(timeout=60)
    marker = runs_mod.read_marker(tmp)
    ckpt = torch.load(tmp / "checkpoints" / "last.ckpt", weights_only=True)
    assert marker["state"] == "running" and marker["batches_done"] == 6  # an epoch's end
    assert ckpt["global_step"] == marker["step"] == 6 * marker["epoch"]  # epochs done
    res = subprocess.run([sys.executable, "-m", "bsp_fast", "train", "--resume", str(out),
                          "--quiet"], env=_env(), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    a = json.loads((whole / "metrics.json").read_text())
    b = json.loads((out / "metrics.json").read_text())
    assert (b["test"], b["best_epoch"], b["epochs"]) == (a["test"], a["best_epoch"], a["epochs"])
    assert a["epochs"] < EPOCHS  # early stopping ended both, at the same epoch
    wa = torch.load(whole / "checkpoints" / "last.ckpt", weights_only=True)
    wb = torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)
    assert wa["global_step"] == wb["global_step"]
    assert all(torch.equal(wa["state_dict"][k], wb["state_dict"][k]) for k in wa["state_dict"])


def test_full_disk_message(clips, tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    real = lifecycle.write_bytes
    calls = {"n": 0}

    def failing(path, data, **kw):
        calls["n"] += Path(path).name == "last.ckpt"
        if calls["n"] == 2 and Path(path).name == "last.ckpt":  # end of epoch 2 (1-based)
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, data, **kw)

    monkeypatch.setattr(lifecycle, "write_bytes", failing)
    code = train_main([*MODEL, "--data", str(clips), "--out", str(out), "--epochs", "5",
                       "--batch-size", "8", "--threads", "1", "--quiet",
                       "--checkpoint-every", "0",  # a save at every epoch end
                       *[f"--hp={k}={v}" for k, v in HP.items()]])
    err = capsys.readouterr().err
    assert code == 1
    lines = [ln for ln in err.splitlines() if ln.startswith("bsp-train:")]
    assert len(lines) == 1, err
    assert "last.ckpt: cannot save the checkpoint (No space left on device); the previous " \
           "one is intact" in lines[0]
    assert f"continue with: bsp-train --resume {out}" in lines[0]
    assert torch.load(out / "checkpoints" / "last.ckpt", weights_only=True)["epoch"] == 0


def test_full_disk_on_metrics_json_then_resume_tests_only(clips, tmp_path, monkeypatch,
                                                          capsys):
    out = tmp_path / "run"
    real = runs_mod.write_text

    def failing(path, text, **kw):
        if Path(path).name == "metrics.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, text, **kw)

    monkeypatch.setattr(runs_mod, "write_text", failing)
    base = [*MODEL, "--data", str(clips), "--epochs", "3", "--batch-size", "8", "--threads",
            "1", "--quiet", *[f"--hp={k}={v}" for k, v in HP.items()]]
    assert train_main(base + ["--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "metrics.json: cannot write the run's results (No space left on device)" in err
    assert not (out / "metrics.json").exists()
    assert runs_mod.read_marker(out)["fit_done"] == 3
    monkeypatch.setattr(runs_mod, "write_text", real)
    assert train_main(["--resume", str(out), "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["epochs"] == 3  # no epoch trained again
    assert train_main(base + ["--out", str(tmp_path / "whole")]) == 0
    assert _test_metrics(tmp_path / "whole") == metrics["test"]


def test_read_only_out_is_one_line(clips, tmp_path, capsys):
    ro = Path("/proc/bsp_fast_cannot_write_here")
    code = train_main([*MODEL, "--data", str(clips), "--out", str(ro), "--epochs", "1",
                       "--quiet", *[f"--hp={k}={v}" for k, v in HP.items()]])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert f"--out {ro}: cannot write the run directory there" in err


@pytest.fixture(scope="module")
def finished(clips, tmp_path_factory):
    out = tmp_path_factory.mktemp("finished") / "run"
    return bsp_fast.train(*MODEL, data=clips, out=out, **_opts(epochs=1))


@pytest.mark.parametrize("damage", ["truncated", "pickled", "foreign"])
def test_resume_refuses_broken_checkpoints(finished, clips, tmp_path, damage, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished.run_dir, run)
    last = run / "checkpoints" / "last.ckpt"
    if damage == "truncated":
        data = last.read_bytes()
        last.write_bytes(data[:len(data) // 2])
        why = "not a readable checkpoint"
    elif damage == "pickled":
        torch.save({"payload": Path("x")}, last)  # arbitrary Python objects
        why = "not a readable checkpoint"
    else:
        other = bsp_fast.train("classification", "lstm", data=clips, out=tmp_path / "cls",
                               epochs=1, batch_size=8, quiet=True,
                               hp={"hidden_size": 8, "num_layers": 1})
        shutil.copy(other.last_checkpoint, last)
        why = "is a 'classification' checkpoint of model 'lstm', but its run is 'lifting'"
    code = train_main(["--resume", str(run)])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert str(last) in err and why in err


def test_eval_refuses_a_checkpoint_of_another_task(finished, clips, tmp_path, capsys):
    from bsp_fast.training.evaluate import main as eval_main

    run = tmp_path / "run"
    shutil.copytree(finished.run_dir, run)
    other = bsp_fast.train("classification", "lstm", data=clips, out=tmp_path / "cls",
                           epochs=1, batch_size=8, quiet=True,
                           hp={"hidden_size": 8, "num_layers": 1})
    shutil.copy(other.best_checkpoint, run / "checkpoints" / "best.ckpt")
    assert eval_main([str(run)]) == 1
    err = capsys.readouterr().err
    assert "is a 'classification' checkpoint of model 'lstm'" in err
    assert "is a 'lifting' run of model 'baseline_3d'" in err


def test_config_yaml_holds_absolute_paths(finished):
    import yaml

    doc = yaml.safe_load((finished.run_dir / "config.yaml").read_text())
    assert doc["resolved"]["data"] == str(Path(doc["data"]).absolute())
    assert Path(doc["resolved"]["out"]).is_absolute()


def test_checkpoint_every_is_checked_before_any_work(clips, tmp_path, capsys):
    assert train_main([*MODEL, "--data", str(clips), "--out", str(tmp_path / "r"),
                       "--checkpoint-every", "soon"]) == 2
    assert "checkpoint_every expects a duration" in capsys.readouterr().err
    assert parse_duration("10m") == 600 and parse_duration("0") == 0
    assert parse_duration("1.5h") == 5400 and parse_duration("90s") == 90


def test_reproduce_continues_an_interrupted_row(tmp_path, monkeypatch):
    from bsp_fast.reproduction import worker
    from bsp_fast.reproduction import runner as seeds

    run = tmp_path / "stopped"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "last.ckpt").write_bytes(b"x")
    (run / "config.yaml").write_text("task: lifting\nmodel: lstm\n")
    runs_mod.write_marker(run, state="interrupted", epoch=2, step=10)
    assert runs_mod.resumable(run) == run
    assert runs_mod.resumable(tmp_path / "finished-or-absent") is None
    job = seeds._job(tmp_path / "c.yaml", True, run)
    assert worker._argv(job) == ["--resume", str(run), "--quiet"]
    calls = []
    monkeypatch.setattr("bsp_fast.training.train.train", lambda **kw: calls.append(kw))
    seeds._run([("row seed 1", tmp_path / "c.yaml", run)], 1, True, lambda *_: None)
    assert calls == [{"resume": str(run), "quiet": True}]


def test_fit_time_of_runs_resumed_before_it_was_carried_is_a_lower_bound(tmp_path):
    from bsp_fast.reporting.reproduced import cost_cells
    from bsp_fast.reproduction.runner import _seconds

    run = tmp_path / "run"
    (run / "logs" / "version_0").mkdir(parents=True)
    old = {"fit": 600.0, "fit_cpu": 540.0}  # a record of a run's last process only
    assert _seconds(run, old) == old  # one process: its whole fit
    (run / "logs" / "version_1").mkdir()  # resumed once
    assert _seconds(run, old) == dict(old, partial=True)
    new = dict(old, carried=True)  # fit seconds summed over its processes
    assert _seconds(run, new) == new
    cost = {"parameters": 10, "flops_per_clip": 2e6}
    assert cost_cells([new, new], cost)[2] == "10.0; 9.0"
    assert cost_cells([new, dict(old, partial=True)], cost)[2] == "≥ 10.0; 9.0"


def test_bench_checkpoint_cadence_smoke(tmp_path, monkeypatch, capsys):
    """benchmarks/bench_checkpoint_cadence.py, one round of 3 short epochs: both cadences
    run, save last.ckpt as many times as the rule says, and score the same."""
    import importlib

    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    bench = importlib.import_module("bench_checkpoint_cadence")
    out = tmp_path / "rows.jsonl"
    assert bench.main(["--rounds", "1", "--epochs", "3", "--train-clips", "64",
                       "--json", str(out)]) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["cadence"], r["last_ckpt_saves"]) for r in rows] == [("0", 3), ("5m", 1)]
    assert all(r["fit_cpu_s"] > 0 and r["same_test_metrics"] for r in rows)
    assert rows[0]["vs_every_epoch"] == 1.0
    assert "| 5m |" in capsys.readouterr().out
