"""``bsp-train --compile on`` (#36, item 2): the same updates give the same model within
float32 rounding, the checkpoint keeps the eager module's keys (bsp-eval loads it without
torch.compile), and the option is recorded in the run's config.yaml."""
from __future__ import annotations

import shutil

import pytest
import torch
import yaml

import bsp_fast
from bsp_fast.data.testing import write_clip_file

pytestmark = pytest.mark.skipif(shutil.which("g++") is None and shutil.which("gcc") is None,
                                reason="torch.compile's inductor needs a C compiler on CPU")


def test_compiled_run_matches_eager(tmp_path):
    h5 = tmp_path / "clips.h5"
    write_clip_file(h5, clips=(64, 16, 16), clip_length=8, seed=5, rotations=False)
    common = dict(data=h5, epochs=1, batch_size=16, precision="32", threads=1, seed=3,
                  accelerator="cpu", quiet=True)
    from torch._dynamo.utils import counters

    counters.clear()
    eager = bsp_fast.train("lifting", "lstm", out=tmp_path / "eager", **common)
    assert not counters["stats"]["unique_graphs"]
    compiled = bsp_fast.train("lifting", "lstm", out=tmp_path / "compiled", compile="on",
                              **common)
    assert counters["stats"]["unique_graphs"] >= 1  # the model was compiled
    assert compiled.val["loss"] == pytest.approx(eager.val["loss"], rel=1e-4)
    assert compiled.metrics["mpjpe_mm"] == pytest.approx(eager.metrics["mpjpe_mm"], rel=1e-4)
    a = torch.load(eager.best_checkpoint, map_location="cpu", weights_only=False)["state_dict"]
    b = torch.load(compiled.best_checkpoint, map_location="cpu", weights_only=False)["state_dict"]
    assert list(a) == list(b)  # no "_orig_mod." prefix: bsp-eval needs no compile
    for k in a:
        torch.testing.assert_close(b[k], a[k], rtol=1e-4, atol=1e-6)
    cfg = yaml.safe_load((tmp_path / "compiled" / "config.yaml").read_text())
    assert cfg["compile"] == "on"
    assert yaml.safe_load((tmp_path / "eager" / "config.yaml").read_text())["compile"] == "off"


def test_bench_train_loop_smoke(capsys, monkeypatch, tmp_path):
    """benchmarks/bench_train_loop.py on one fast model, the eager plain loop and bsp-train
    (its worker processes are spawned and import the benchmark by name)."""
    import importlib
    import json
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    bench = importlib.import_module("bench_train_loop")
    out = tmp_path / "rows.jsonl"
    assert bench.main(["--models", "lifting/lstm", "--train-clips", "64", "--epochs", "1",
                       "--updates", "3", "--modes", "eager32", "bsp_train32",
                       "--repeat", "2", "--json", str(out)]) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["mode"] for r in rows] == ["eager32", "bsp_train32"]
    assert rows[0]["updates"] == 3 and rows[0]["clips_per_s"] > 0
    # two runs done in each process, its CPU seconds counted
    assert [r["repeat"] for r in rows] == [2, 2] and all(r["cpu_s"] > 0 for r in rows)
    assert rows[1]["total_s"] >= rows[1]["fit_s"] > 0
    assert "| lifting/lstm | 64 | eager32 |" in capsys.readouterr().out
