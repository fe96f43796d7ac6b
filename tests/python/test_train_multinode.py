"""DDP training on CPU (gloo). Two ranks with batch B train exactly like one process with
batch 2B (each rank takes its half of every 2B super-batch and the gradients are
averaged), so the final metrics agree. And across machines, simulated on one: two
bsp-train processes started by hand with MASTER_ADDR / MASTER_PORT / NODE_RANK and
--num-nodes 2 make one run directory whose test metrics, reduced over both, equal a
one-process evaluation of its checkpoint."""
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("lightning")

import bsp_fast  # noqa: E402
from bsp_fast.data.testing import write_clip_file  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_machines_by_node_rank_make_one_run(tmp_path):
    h5 = tmp_path / "clips.h5"
    info = write_clip_file(h5, clips=(32, 8, 8), clip_length=8, seed=3)
    assert info["clips"]["test"] % 2 == 0
    out = tmp_path / "run"
    port = str(_free_port())
    cmd = [sys.executable, "-m", "bsp_fast", "train", "lifting", "baseline_3d", "--data",
           str(h5), "--out", str(out), "--epochs", "1", "--batch-size", "8",
           "--accelerator", "cpu", "--devices", "1", "--num-nodes", "2", "--strategy", "ddp",
           "--threads", "1", "--quiet", "--hp", "linear_size=32", "--hp", "num_blocks=1"]
    procs = []
    for node in (0, 1):
        env = dict(os.environ, MASTER_ADDR="127.0.0.1", MASTER_PORT=port,
                   NODE_RANK=str(node), WORLD_SIZE="2", OMP_NUM_THREADS="1",
                   PYTHONPATH=os.pathsep.join([str(REPO / "python"),
                                               os.environ.get("PYTHONPATH", "")]))
        procs.append(subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True))
    results = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, results):
        assert p.returncode == 0, err[-3000:]
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["world_size"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clips.h5", "run"]  # no temporaries
    single = bsp_fast.evaluate(out)
    assert single.metrics == pytest.approx(saved["test"], rel=1e-6)


def _env(**extra):
    return dict(os.environ, OMP_NUM_THREADS="1", **extra,
                PYTHONPATH=os.pathsep.join([str(REPO / "python"),
                                            os.environ.get("PYTHONPATH", "")]))


def test_two_ranks_train_like_one_process_with_twice_the_batch(tmp_path):
    h5 = tmp_path / "clips.h5"
    info = write_clip_file(h5, clips=(32, 8, 8), clip_length=8, seed=3)
    assert info["clips"]["train"] % 8 == 0  # whole super-batches: no clip repeated
    # an LSTM (no dropout, no batch norm), no input noise: nothing but the batches differs
    common = [sys.executable, "-m", "bsp_fast", "train", "lifting", "lstm", "--data", str(h5),
              "--epochs", "2", "--accelerator", "cpu", "--threads", "1", "--quiet",
              "--noise", "0", "--no-augment", "--mjp", "0", "--lr", "1e-2",
              "--hp", "hidden_size=8", "--hp", "num_layers=1"]
    runs = {"one": ["--devices", "1", "--batch-size", "8"],
            "ddp": ["--devices", "2", "--strategy", "ddp", "--batch-size", "4"]}
    metrics = {}
    for name, extra in runs.items():
        proc = subprocess.run(common + extra + ["--out", str(tmp_path / name)], env=_env(),
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        metrics[name] = json.loads((tmp_path / name / "metrics.json").read_text())
    assert (metrics["one"]["world_size"], metrics["ddp"]["world_size"]) == (1, 2)
    assert metrics["ddp"]["test"] == pytest.approx(metrics["one"]["test"], rel=1e-6)
    assert metrics["ddp"]["test"]["mpjpe_mm"] > 0
