"""--precision auto decided on this machine (#36): a timed probe of the run's own model on
one of its batches, cached per model, CPU and thread count, recorded in config.yaml."""
import json
import re

import pytest
import yaml

import bsp_fast
from bsp_fast.data.testing import write_clip_file
from bsp_fast.training import precision as P

NATIVE = bool(re.search(r"avx512_bf16|amx_bf16", open("/proc/cpuinfo").read()))


@pytest.fixture
def probe_on(tmp_path, monkeypatch):
    monkeypatch.setenv("BSP_PRECISION_PROBE", "1")
    monkeypatch.setenv("BSP_PRECISION_CACHE", str(tmp_path / "cache" / "precision.json"))
    return tmp_path / "cache" / "precision.json"


def _fake(fp32, bf16, calls):
    def probe(use_bf16):
        calls.append(use_bf16)
        return bf16 if use_bf16 else fp32
    return probe


def test_the_probe_decides_caches_and_says_why(probe_on, monkeypatch):
    import bsp_fast.models.lstm as lstm

    monkeypatch.setattr(lstm, "cpu_bf16", lambda: True)
    calls = []
    got, why = P.decide_precision("auto", "cpu", None, probe=_fake(1.0, 0.5, calls), key="k1")
    assert got == "bf16-mixed" and "probe" in why and "x2.00" in why and calls == [False, True]
    doc = json.loads(probe_on.read_text())
    assert doc["k1"]["precision"] == "bf16-mixed" and doc["k1"]["fp32_s"] == 1.0
    # the machine decided once: the next run reads the cache, measures nothing
    again, why = P.decide_precision("auto", "cpu", None, probe=_fake(1.0, 9.0, calls),
                                    key="k1")
    assert again == "bf16-mixed" and "cached" in why and len(calls) == 2
    # within the margin: float32 (bf16 must be at least 10 % faster)
    got, _ = P.decide_precision("auto", "cpu", None, probe=_fake(1.0, 0.95, []), key="k2")
    assert got == "32"
    # given, or a CPU without native bf16: no probe at all
    calls = []
    assert P.decide_precision("bf16-mixed", "cpu", None, probe=_fake(1, 1, calls),
                              key="k3")[0] == "bf16-mixed"
    monkeypatch.setattr(lstm, "cpu_bf16", lambda: False)
    got, why = P.decide_precision("auto", "cpu", None, probe=_fake(1.0, 0.1, calls), key="k4")
    assert got == "32" and "no native bf16" in why and calls == []


def test_a_gpu_is_probed_too(probe_on, monkeypatch):
    """On an H100 bf16 autocast was slower for every model here (x0.68-0.98): a GPU with
    bf16 is measured like a CPU, and without bf16 gets float32 unmeasured. (CI has no GPU:
    torch.cuda's answers are stood in; benchmarks/gpu_check.sh ran the real probe there.)"""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda: True)
    calls = []
    got, why = P.decide_precision("auto", "gpu", None, probe=_fake(1.0, 1.2, calls), key="g")
    assert got == "32" and "probe on this GPU" in why and "x0.83" in why
    assert calls == [False, True] and json.loads(probe_on.read_text())["g"]["precision"] == "32"
    got, why = P.decide_precision("auto", "auto", None, probe=_fake(1.0, 0.5, []), key="g2")
    assert got == "bf16-mixed" and "this GPU" in why
    monkeypatch.setenv("BSP_PRECISION_PROBE", "0")
    assert P.decide_precision("auto", "gpu", None, probe=_fake(1.0, 9.0, []),
                              key="g3")[0] == "bf16-mixed"
    monkeypatch.setenv("BSP_PRECISION_PROBE", "1")
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda: False)
    calls = []
    got, why = P.decide_precision("auto", "gpu", None, probe=_fake(1.0, 0.1, calls), key="g4")
    assert got == "32" and "without bf16" in why and calls == []


def test_the_probe_off_falls_back_on_the_models_policy(monkeypatch):
    import bsp_fast.models.lstm as lstm
    from bsp_fast import models

    monkeypatch.setenv("BSP_PRECISION_PROBE", "0")
    monkeypatch.setattr(lstm, "cpu_bf16", lambda: True)
    fast = models.model_class("lifting", "baseline_3d")
    got, why = P.decide_precision("auto", "cpu", fast, probe=_fake(1, 9, []), key="k")
    assert got == "bf16-mixed" and "probe is off" in why


def test_the_probe_leaves_the_runs_weights_and_random_state(tmp_path):
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    h5 = tmp_path / "c.h5"
    write_clip_file(h5, clips=(16, 4, 4), clip_length=8, seed=1)
    batch = ClipDataset(h5, "train", "lifting")[list(range(8))]
    torch.manual_seed(3)
    net = models.create("lifting", "baseline_3d", linear_size=32, num_blocks=1)
    before = [p.detach().clone() for p in net.parameters()]
    state = torch.get_rng_state()
    probe = P.time_steps(net, batch, steps=2, warmup=1)
    assert probe(False) > 0 and probe(True) > 0
    assert all(torch.equal(a, b) for a, b in zip(before, net.parameters()))
    assert torch.equal(state, torch.get_rng_state())


def test_the_probe_alternates_the_precisions_and_times_cpu_with_one_thread(tmp_path,
                                                                          monkeypatch):
    import time

    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    h5 = tmp_path / "c.h5"
    write_clip_file(h5, clips=(16, 4, 4), clip_length=8, seed=1)
    batch = ClipDataset(h5, "train", "lifting")[list(range(8))]
    net = models.create("lifting", "baseline_3d", linear_size=32, num_blocks=1)
    seen = []
    forward = type(net).forward_batch

    def spy(self, b):
        seen.append(torch.is_autocast_enabled("cpu"))
        return forward(self, b)

    monkeypatch.setattr(type(net), "forward_batch", spy)
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        assert P.probe_clock() == (time.process_time, "CPU time")
        probe = P.time_steps(net, batch, steps=3, warmup=2)
        fp32 = probe(False)
        # one call measured both: warm-up and timed steps alternate float32 and bf16
        assert seen == [False, True] * 5
        assert probe(True) > 0 and probe(False) == fp32 and len(seen) == 10
        torch.set_num_threads(2)
        assert P.probe_clock() == (time.perf_counter, "wall time")
    finally:
        torch.set_num_threads(threads)


def test_a_run_records_what_auto_picked_and_why_and_bsp_eval_uses_it(probe_on, tmp_path):
    from bsp_fast.training.evaluate import evaluate

    h5 = tmp_path / "c.h5"
    write_clip_file(h5, clips=(16, 4, 4), clip_length=8, seed=1)
    opts = dict(data=h5, epochs=1, batch_size=8, quiet=True,
                hp={"linear_size": 32, "num_blocks": 1})
    run = bsp_fast.train("lifting", "baseline_3d", out=tmp_path / "a", **opts)
    res = yaml.safe_load((run.run_dir / "config.yaml").read_text())["resolved"]
    if NATIVE:
        assert "probe on this CPU" in res["precision_reason"]
        assert res["precision"] in ("32", "bf16-mixed") and probe_on.is_file()
        again = bsp_fast.train("lifting", "baseline_3d", out=tmp_path / "b", **opts)
        res2 = yaml.safe_load((again.run_dir / "config.yaml").read_text())["resolved"]
        assert "cached" in res2["precision_reason"] and res2["precision"] == res["precision"]
    else:
        assert res["precision"] == "32" and "no native bf16" in res["precision_reason"]
    # bsp-eval scores in what the run trained in (not decided again)
    assert evaluate(run.run_dir, "test").config["precision"] == res["precision"]


def test_the_key_names_the_cpus_flags_and_its_kernels_isa(monkeypatch):
    """A virtual machine's model name ("AMD EPYC") is the same on AVX2-only and AVX512-BF16
    generations: the key also holds the flags and the ISA torch's kernels use, so an
    answer cached on one is not reused on the other (nor under ATEN_CPU_CAPABILITY or
    ONEDNN_MAX_CPU_ISA, which lower that ISA on the same CPU)."""
    import torch

    monkeypatch.setattr(P, "_cpu_name", lambda: "AMD EPYC")
    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
    monkeypatch.delenv("DNNL_MAX_CPU_ISA", raising=False)
    keys = {}
    for flags, isa in ((["avx2", "avx512f", "avx512_bf16"], "AVX512"), (["avx2"], "AVX2")):
        monkeypatch.setattr(P, "cpu_flags", lambda f=flags: f)
        monkeypatch.setattr(torch.backends.cpu, "get_cpu_capability", lambda i=isa: i)
        keys[isa] = P.probe_key("classification/lstm {} batch 64", 1)
    assert keys["AVX512"] != keys["AVX2"]
    assert "AMD EPYC [avx2 avx512f avx512_bf16; kernels AVX512]" in keys["AVX512"]
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "AVX2")
    assert P.probe_key("classification/lstm {} batch 64", 1) != keys["AVX2"]
    assert "oneDNN AVX2" in P.probe_key("classification/lstm {} batch 64", 1)


def test_a_resumed_run_keeps_the_precision_auto_picked_at_its_start(probe_on, tmp_path):
    """Its auto answer is not asked again: a probe could now answer otherwise (here the
    cache is gone and the models' policy says the opposite) and switch the precision in
    the middle of the run. --precision given on --resume still overrides."""
    from bsp_fast.training.train import main as train_main

    h5 = tmp_path / "c.h5"
    write_clip_file(h5, clips=(16, 4, 4), clip_length=8, seed=1)
    out = tmp_path / "run"
    args = ["lifting", "baseline_3d", "--data", str(h5), "--out", str(out), "--epochs", "1",
            "--batch-size", "8", "--quiet", "--hp", "linear_size=32", "--hp", "num_blocks=1"]
    assert train_main(args) == 0
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    started = cfg["resolved"]["precision"]
    other = "32" if started == "bf16-mixed" else "bf16-mixed"
    # as an interrupted run whose auto had picked the other precision
    cfg["resolved"]["precision"] = other
    cfg["resolved"]["precision_reason"] = "auto: probe on this CPU (a stand-in answer)"
    (out / "config.yaml").write_text(yaml.safe_dump(cfg))
    probe_on.unlink(missing_ok=True)
    kept = P.kept_precision(cfg)
    assert kept == (other, "auto, kept from the run's start: auto: probe on this CPU "
                           "(a stand-in answer)")
    assert P.kept_precision(dict(cfg, resolved=dict(cfg["resolved"],
                                                    precision_reason=kept[1]))) == kept
    assert P.kept_precision(dict(cfg, precision="32")) is None  # not auto: as given
    assert train_main(["--resume", str(out), "--epochs", "2", "--quiet"]) == 0
    res = yaml.safe_load((out / "config.yaml").read_text())["resolved"]
    assert (res["precision"], res["precision_reason"]) == kept
    assert json.loads((out / "metrics.json").read_text())["precision"] == other
    assert not probe_on.exists()  # nothing was probed
    assert train_main(["--resume", str(out), "--epochs", "3", "--quiet",
                       "--precision", "32"]) == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["resolved"]["precision"] == "32"


@pytest.mark.skipif(not NATIVE, reason="the probe runs on CPUs with native bf16 only")
def test_a_models_speed_revision_makes_the_probe_measure_again(probe_on, tmp_path,
                                                               monkeypatch):
    """A code change that alters a model's step times raises its speed_revision: the
    answer cached before is then not reused (pose_temporal's NCHW layout did)."""
    from bsp_fast.models.martinez import Baseline3D

    h5 = tmp_path / "c.h5"
    write_clip_file(h5, clips=(16, 4, 4), clip_length=8, seed=1)
    opts = dict(data=h5, epochs=1, batch_size=8, quiet=True,
                hp={"linear_size": 32, "num_blocks": 1})
    bsp_fast.train("lifting", "baseline_3d", out=tmp_path / "a", **opts)
    monkeypatch.setattr(Baseline3D, "speed_revision", 3)
    run = bsp_fast.train("lifting", "baseline_3d", out=tmp_path / "b", **opts)
    res = yaml.safe_load((run.run_dir / "config.yaml").read_text())["resolved"]
    assert "probe on this CPU" in res["precision_reason"] and "cached" not in \
        res["precision_reason"]
    keys = sorted(json.loads(probe_on.read_text()))
    assert len(keys) == 2 and sum(" speed 3 |" in k for k in keys) == 1


#: bf16 autocast against float32 on the same weights and clips, per task: the metric and
#: its tolerance (relative for losses and errors in mm, absolute for a share of joints)
TOLERANCE = {"classification": ("loss", dict(rel=0.02)),
             "lifting": ("mpjpe_mm", dict(rel=0.02)),
             "pose_estimation": ("pck_0.05", dict(abs=0.01))}


@pytest.mark.parametrize("task,name", [("classification", "lstm"),
                                       ("classification", "pedestrian_graph"),
                                       ("lifting", "lstm"), ("lifting", "lstm_relative_rot"),
                                       ("lifting", "poseformer"),
                                       ("pose_estimation", "pose_cnn")])
def test_bf16_metrics_stay_within_tolerance_of_fp32_for_every_model(tmp_path, task, name):
    """The probe may pick bf16 for any model (here: all of them on a CPU with native bf16);
    each stays within the stated tolerance of float32 (baseline_3d and simple_transformer:
    test_precision_choice.py)."""
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset
    from bsp_fast.training.scoring import TaskMetrics

    h5 = tmp_path / "c.h5"
    if task == "pose_estimation":
        write_clip_file(h5, clips=(8, 8, 8), clip_length=4, media=True, crop_size=32, seed=4)
    else:
        write_clip_file(h5, clips=(8, 8, 8), clip_length=16, seed=4)
    b = ClipDataset(h5, "test", task, noise=5.0 if task != "pose_estimation" else 0.0)[:8]
    torch.manual_seed(0)
    m = models.create(task, name).eval()
    metric, tol = TOLERANCE[task]
    values = {}
    for bf16 in (False, True):
        with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = m.forward_batch(b)
            loss = float(m.loss(out, b))
        tm = TaskMetrics(task)
        tm.update(out.float(), b, m)
        values[bf16] = loss if metric == "loss" else tm.compute()[metric]
    assert values[True] == pytest.approx(values[False], **tol), (name, values)


def test_bench_precision_probe_smoke(monkeypatch, capsys):
    """benchmarks/bench_precision_probe.py on its fastest model."""
    import importlib.util
    from pathlib import Path

    import torch

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_precision_probe.py"
    spec = importlib.util.spec_from_file_location("bench_precision_probe", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    monkeypatch.setenv("BSP_PRECISION_PROBE", "0")  # restored afterwards: the bench sets it
    monkeypatch.setenv("BSP_PRECISION_CACHE", "unused")
    threads = torch.get_num_threads()
    try:
        assert bench.main(["--models", "lifting/lstm"]) == 0
    finally:
        torch.set_num_threads(threads)
    out = capsys.readouterr().out
    row = [line for line in out.splitlines() if line.startswith("| lifting/lstm |")]
    assert len(row) == 1 and ("bf16-mixed" in row[0] or "| 32 |" in row[0])
    assert ("probe on this CPU" in row[0]) == NATIVE
    # --steps: the medians too, measured even where auto does not probe
    try:
        assert bench.main(["--models", "lifting/lstm", "--steps"]) == 0
    finally:
        torch.set_num_threads(threads)
    row = [line for line in capsys.readouterr().out.splitlines()
           if line.startswith("| lifting/lstm |")][0].strip("| ").split(" | ")
    f32, b16, ratio = float(row[-3]), float(row[-2]), float(row[-1].lstrip("x"))
    assert f32 > 0 and b16 > 0 and ratio == pytest.approx(f32 / b16, rel=0.05, abs=0.01)


def test_parallel_runs_wait_for_one_probe(probe_on):
    """Two processes deciding the same key at once: one probes, the other reads its answer
    (bsp-reproduce's seeds must not train in different precisions)."""
    import subprocess
    import sys

    if not NATIVE:
        pytest.skip("the probe runs only on a CPU with native bf16")
    code = ("import sys, time\n"
            "from bsp_fast.training import precision as P\n"
            "def probe(bf16):\n"
            "    time.sleep(1.0)\n"
            "    print('probed', flush=True)\n"
            "    return 0.5 if bf16 else 1.0\n"
            "print(P.decide_precision('auto', 'cpu', None, probe=probe, key='same'))\n")
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=120)[0] for p in procs]
    assert sum(o.count("probed") for o in outs) == 2  # one process, both precisions
    assert sum("cached" in o for o in outs) == 1
    assert all("bf16-mixed" in o for o in outs)


def test_bench_seed_layout_smoke(capsys, monkeypatch):
    """benchmarks/bench_seed_layout.py on one fast model (its worker processes are spawned
    and import the benchmark by name, so it is imported from its folder)."""
    import importlib
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    bench = importlib.import_module("bench_seed_layout")
    assert bench.main(["--steps", "1", "--sync-delay", "8", "--models",
                       "classification/lstm"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines()
            if line.startswith("| classification/lstm | 64 |")]
    assert len(rows) == 1 and float(rows[0].rstrip(" |").rsplit("|", 1)[1]) > 0


def test_gpu_check_prepare_records_the_cores_answers(tmp_path):
    """benchmarks/gpu_check.sh prepare: the stand-in for the C++ core (on a machine without
    its libraries) holds the core's constants and its answers for the calls that building
    the models makes, and raises on any other call; fixtures are packed."""
    import importlib.util
    import os
    import subprocess
    import sys
    from pathlib import Path

    import numpy as np

    from bsp_fast import _core, geometry, skeleton

    root = Path(__file__).resolve().parents[2]
    subprocess.run(["bash", str(root / "benchmarks" / "gpu_check.sh"), "prepare",
                    str(tmp_path)], check=True, capture_output=True,
                   env=dict(os.environ, PYTHON=sys.executable, GPU_CHECK_NO_WHEEL="1"))
    assert (tmp_path / "fixtures.tar.gz").stat().st_size > 0
    spec = importlib.util.spec_from_file_location("stub", tmp_path / "bsp_fast" / "_core.py")
    stub = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stub)
    assert stub.JOINT_NAMES == list(_core.JOINT_NAMES) and stub.PARENTS == list(_core.PARENTS)
    rel = np.ascontiguousarray(skeleton.reference_pose("sk_kid"), dtype=np.float64)
    par = np.asarray(_core.PARENTS, dtype=np.int32)
    np.testing.assert_array_equal(stub.forward_kinematics(rel, None, 1, par),
                                  geometry.forward_kinematics(rel))
    with pytest.raises(RuntimeError, match=r"no C\+\+ core"):
        stub.forward_kinematics(rel + 1.0, None, 1, par)
    with pytest.raises(RuntimeError, match=r"no C\+\+ core"):
        stub.ConvertStage()
