"""bsp-reproduce's long-lived training workers (reproduction/worker.py): a run trained after
another in the same worker is the run trained alone, failures name the run, and the
workers end with the table."""
from __future__ import annotations

import json
import time

import pytest
import torch
import yaml

from bsp_fast.data.testing import write_clip_file
from bsp_fast.reproduction import runner
from bsp_fast.training.runs import RunError


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    root = tmp_path_factory.mktemp("worker")
    write_clip_file(root / "clips.h5", clips=(24, 8, 8), clip_length=16, seed=5)
    return root / "clips.h5"


def _config(path, data, out, **kw):
    # the autoencoder has dropout and noise draws: any random state left over from the
    # previous run of the worker would change its weights
    cfg = dict(task="autoencoder", model="simple_transformer", data=str(data), out=str(out),
               epochs=2, batch_size=8, threads=1, seed=11, noise=3.0,
               hp={"num_layers": 1, "nhead": 2, "dim_feedforward": 32})
    cfg.update(kw)
    path.write_text(yaml.safe_dump(cfg))
    return path


def _weights(run):
    state = torch.load(run / "checkpoints" / "last.ckpt", map_location="cpu",
                       weights_only=True)["state_dict"]
    return {k: v.clone() for k, v in state.items()}


def _train_in_one_worker(*configs):
    """Trains ``configs`` one after the other in one fresh worker process."""
    w = runner._Worker(runner._env(), True)
    try:
        for cfg in configs:
            w.send(cfg.stem, runner._job(cfg, True))
            deadline = time.monotonic() + 300
            while (code := w.answer()) is None:
                assert time.monotonic() < deadline, w.tail()
                time.sleep(0.1)
            assert code == 0, w.tail()
    finally:
        w.close(stop=False)
    assert w.proc.returncode == 0  # end of input: the worker exits by itself


def test_a_run_after_another_in_one_worker_equals_the_run_alone(clips, tmp_path):
    first = _config(tmp_path / "a.yaml", clips, tmp_path / "a", seed=3, lr=3e-3)
    second = _config(tmp_path / "b.yaml", clips, tmp_path / "b")
    alone = _config(tmp_path / "c.yaml", clips, tmp_path / "c")
    _train_in_one_worker(first, second)
    _train_in_one_worker(alone)
    metrics = {r: json.loads((tmp_path / r / "metrics.json").read_text())["test"]
               for r in "bc"}
    assert metrics["b"] == metrics["c"]
    wb, wc = _weights(tmp_path / "b"), _weights(tmp_path / "c")
    assert wb.keys() == wc.keys()
    assert all(torch.equal(wb[k], wc[k]) for k in wb)
    assert not all(torch.equal(wb[k], v) for k, v in _weights(tmp_path / "a").items())


def test_one_worker_trains_the_runs_of_its_slot_in_turn(clips, tmp_path):
    cfgs = [("r%d" % i, _config(tmp_path / f"r{i}.yaml", clips, tmp_path / f"r{i}",
                                seed=20 + i, epochs=1), None) for i in range(3)]
    with runner_worker_count() as count:
        runner._run(cfgs, 2, True, lambda *_: None)
    assert count() == 2  # three runs, two slots: the first worker's process trains two
    assert all((tmp_path / f"r{i}" / "metrics.json").is_file() for i in range(3))


def test_a_failing_run_names_itself_and_its_error(clips, tmp_path):
    good = _config(tmp_path / "good.yaml", clips, tmp_path / "good", epochs=1)
    bad = _config(tmp_path / "bad.yaml", tmp_path / "missing.h5", tmp_path / "bad")
    with pytest.raises(RunError) as err:
        runner._run([("good", good, None), ("bad", bad, None)], 2, True, lambda *_: None)
    assert "bad: bsp-train exited with" in str(err.value)
    assert "missing.h5" in str(err.value)
    assert not (tmp_path / "bad").exists()


class runner_worker_count:
    """Counts the worker processes :func:`runner._run` starts."""

    def __enter__(self):
        self.n, self.orig = 0, runner._Worker.__init__

        def init(w, *a, **kw):
            self.n += 1
            self.orig(w, *a, **kw)

        runner._Worker.__init__ = init
        return lambda: self.n

    def __exit__(self, *exc):
        runner._Worker.__init__ = self.orig


def test_bench_reproduce_workers_smoke(tmp_path, monkeypatch, clips):
    """benchmarks/bench_reproduce_workers.py on two one-epoch runs: both modes finish, the
    metrics agree run by run (the benchmark checks it) and the summary has its ratios."""
    import importlib
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    bench = importlib.import_module("bench_reproduce_workers")
    out = tmp_path / "summary.json"
    assert bench.main(["--data", str(clips), "--task", "lifting", "--model", "baseline_3d",
                       "--runs", "2", "--repeats", "1", "--batch-size", "8",
                       "--json", str(out)]) == 0
    s = json.loads(out.read_text())
    assert [r["mode"] for r in s["rows"]] == ["fresh", "workers"]
    assert s["same_metrics"] and s["wall_ratio"] > 0 and s["cpu_ratio"] > 0
    assert all(r["cpu_s"] > 0 for r in s["rows"])


def test_sigterm_stops_the_workers_runs_resumably_and_a_rerun_finishes_them(tmp_path):
    """A real bsp-reproduce with two workers, SIGTERM to it mid-training (what a batch
    scheduler sends): exit 143, both runs left resumable, the same command finishes them."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from bsp_fast.training.runs import resumable

    root = Path(__file__).resolve().parents[2]
    doc = yaml.safe_load((root / "experiments" / "autoencoder.yaml").read_text())
    doc.pop("deviations", None)
    doc["table"] = "tiny_stop"
    doc["common"]["hp"] = {"num_layers": 1, "dim_feedforward": 32}
    doc["rows"] = doc["rows"][:1]
    doc["findings"] = doc["findings"][:0]
    doc["budgets"]["smoke"] = {"epochs": 150, "batch_size": 8, "accelerator": "cpu",
                               "precision": "32", "early_stop": 0}
    clips = tmp_path / "l30.h5"  # the autoencoder table's clip length
    write_clip_file(clips, clips=(24, 8, 8), clip_length=30, seed=6)
    table = tmp_path / "tiny_stop.yaml"
    table.write_text(yaml.safe_dump(doc, sort_keys=False))
    argv = [sys.executable, "-m", "bsp_fast", "reproduce", str(table), "--data",
            str(clips), "--budget", "smoke", "--seeds", "2", "--jobs", "2", "--out",
            str(tmp_path / "runs")]
    env = runner._env()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    base = tmp_path / "runs" / "tiny_stop-smoke"
    deadline = time.monotonic() + 240
    # both runs past their first epoch's validation (best.ckpt; last.ckpt waits for
    # --checkpoint-every): a signal before training (in the setup, where it stops at once)
    # leaves nothing to continue, and on a loaded machine the CSV log this waited for
    # first appears well before training starts
    while len(list(base.glob("*/.seed-*/checkpoints/best.ckpt"))) < 2:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the two runs never started training"
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "interrupted (SIGTERM)" in err
    runs = sorted(base.glob("*/seed-*"))
    assert len(runs) == 2 and all(resumable(r) == r for r in runs), err
    again = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("continuing the interrupted run") == 2
    for r in runs:
        m = json.loads((r / "metrics.json").read_text())
        assert m["epochs"] == 150
