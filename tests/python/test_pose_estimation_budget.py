"""experiments/pose_estimation_budget.py (#38): the plateau rule and the budget by hand, CPU
seconds summed over a run's resumes, and its smoke version end to end (curves on a file
whose test split is its val split, the ablation table it writes, bsp-reproduce on it)."""
import importlib.util
import json
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location(
    "pose_estimation_budget", ROOT / "experiments" / "pose_estimation_budget.py")
pb = importlib.util.module_from_spec(spec)
spec.loader.exec_module(pb)


def test_plateau_by_hand():
    u = [10, 20, 30, 40, 50, 60]
    # best 0.653; the running best first within 0.005 of it at 0.650 (index 2), followed by
    # 3 epochs: a plateau at 30 updates with patience 2 or 3, none with patience 4
    v = [0.50, 0.60, 0.650, 0.652, 0.651, 0.653]
    p = pb.plateau(u, v, 0.005, 3)
    assert p == {"reached": True, "index": 2, "updates": 30.0, "value": 0.65, "best": 0.653}
    assert not pb.plateau(u, v, 0.005, 4)["reached"]
    assert pb.plateau(u, v, 0.005, 4)["updates"] == 60.0  # none: the last epoch
    rising = pb.plateau([1, 2, 3], [0.5, 0.6, 0.7], 0.005, 1)
    assert not rising["reached"] and rising["index"] == 2
    assert pb.plateau([], [], 0.005, 1)["reached"] is False


def _log(run, version, rows):
    d = run / "logs" / f"version_{version}"
    d.mkdir(parents=True)
    keys = ["epoch", "step", "cost/cpu_s", "cost/updates", "val/pck_0.05"]
    lines = [",".join(keys)] + [",".join(str(r.get(k, "")) for k in keys) for r in rows]
    (d / "metrics.csv").write_text("\n".join(lines) + "\n")


def test_run_series_adds_the_cpu_of_earlier_resumes(tmp_path):
    """Version 0 ran epochs 0-1 (100 s at its end), the resume epochs 2-3 counting from 0:
    epoch 2's 60 s is 160 s of the run."""
    run = tmp_path / "run"
    _log(run, 0, [{"epoch": 0, "step": 9, "val/pck_0.05": 0.5},
                  {"epoch": 0, "step": 9, "cost/cpu_s": 50, "cost/updates": 10},
                  {"epoch": 1, "step": 19, "val/pck_0.05": 0.6},
                  {"epoch": 1, "step": 19, "cost/cpu_s": 100, "cost/updates": 20}])
    _log(run, 1, [{"epoch": 2, "step": 29, "val/pck_0.05": 0.7},
                  {"epoch": 2, "step": 29, "cost/cpu_s": 60, "cost/updates": 30},
                  {"epoch": 3, "step": 39, "cost/cpu_s": 120, "cost/updates": 40}])
    s = pb.run_series(run)  # epoch 3 has no validation value: left out
    np.testing.assert_array_equal(s["updates"], [10, 20, 30])
    np.testing.assert_array_equal(s["cpu_s"], [50, 100, 160])
    np.testing.assert_array_equal(s["value"], [0.5, 0.6, 0.7])


def _series(values, cpu_per_update, per_epoch=10):
    u = np.arange(1, len(values) + 1) * per_epoch
    return {"updates": u.astype(float), "cpu_s": u * cpu_per_update, "value": np.array(values)}


def test_budget_by_hand():
    """crop64 plateaus at 30 updates, crop96 at 50; the budget is the later, 50 updates
    (5 epochs of 10), unless the costlier crop96 (2 s per update) cannot afford it in the
    cap: 60 s -> 30 updates. The full row: the best validation value at the budget."""
    flat = [0.5, 0.6, 0.70, 0.70, 0.70, 0.70, 0.70, 0.70]
    late = [0.3, 0.4, 0.50, 0.60, 0.75, 0.75, 0.75, 0.75]
    configs = {"crop64": {"crop_size": 64, "width": 16, "series": [_series(flat, 1.0)] * 2},
               "crop96": {"crop_size": 96, "width": 16, "series": [_series(late, 2.0)]}}
    b = pb.fix_budget(configs, cpu_cap_s=1000, tolerance=0.005, patience=2)
    assert b["configs"]["crop64"]["plateau"]["updates"] == 30
    assert b["configs"]["crop96"]["plateau"]["updates"] == 50
    assert (b["updates"], b["epochs"], b["limited_by_cpu"], b["all_plateaued"]) == \
        (50, 5, False, True)
    assert b["chosen"] == "crop96" and b["crop_size"] == 96
    assert b["configs"]["crop96"]["cpu_s_per_update"] == 2.0
    capped = pb.fix_budget(configs, cpu_cap_s=60, tolerance=0.005, patience=2)
    assert (capped["updates"], capped["epochs"], capped["limited_by_cpu"]) == (30, 3, True)
    assert capped["chosen"] == "crop64"  # 0.70 against 0.50 at 30 updates


def test_budget_by_hand_at_equal_cpu():
    """rule cpu: crop64 (1 s per update) and crop96 (2 s) compared at the least CPU any run
    reached, 80 s: crop64 0.70 (80 updates), crop96 0.60 (40 updates); crop64 is chosen and
    the budget is its own plateau, 30 updates, or what it affords in a 20 s cap."""
    flat = [0.5, 0.6, 0.70, 0.70, 0.70, 0.70, 0.70, 0.70]
    late = [0.3, 0.4, 0.50, 0.60, 0.75, 0.75, 0.75, 0.75]
    configs = {"crop64": {"crop_size": 64, "width": 16, "series": [_series(flat, 1.0)]},
               "crop96": {"crop_size": 96, "width": 16, "series": [_series(late, 2.0)]}}
    eq = pb.at_equal_cpu(configs)
    assert eq == {"cpu_s": 80.0, "values": {"crop64": 0.70, "crop96": 0.60}}
    b = pb.fix_budget(configs, cpu_cap_s=1000, tolerance=0.005, patience=2, rule="cpu")
    assert (b["chosen"], b["crop_size"], b["updates"], b["epochs"], b["limited_by_cpu"]) == \
        ("crop64", 64, 30, 3, False)
    capped = pb.fix_budget(configs, cpu_cap_s=20, tolerance=0.005, patience=2, rule="cpu")
    assert (capped["chosen"], capped["updates"], capped["limited_by_cpu"]) == ("crop64", 20, True)
    # the updates rule on the same curves picks crop96 (0.75 against 0.70 at 50 updates)
    assert pb.fix_budget(configs, 1000, 0.005, 2)["chosen"] == "crop96"
    with pytest.raises(ValueError, match="rule must be"):
        pb.fix_budget(configs, 1000, 0.005, 2, rule="wall")


def test_curve_options_pin_the_precision_and_the_flip():
    import argparse

    args = argparse.Namespace(batch_size=4, smoke=False, precision="auto", flip_test=False)
    opts = pb.train_options(args, Path("x.h5"), 64, 16, 0)
    assert (opts["precision"], opts["hp"], opts["early_stop"]) == ("auto", {"width": 16}, 0)
    args.precision, args.flip_test = "bf16-mixed", True  # a curve for pose_temporal_w32
    opts = pb.train_options(args, Path("x.h5"), 64, 32, 3)
    assert (opts["precision"], opts["hp"], opts["seed"]) == (
        "bf16-mixed", {"width": 32, "flip_test": True}, 3)


def test_the_ablation_table_loads_with_one_budget_rule(tmp_path):
    import yaml

    from bsp_fast.reproduction.table_files import load_table

    b = {"crop_size": 64, "width": 16, "crop_sizes": [64, 96, 128], "widths": [16],
         "updates": 1200, "epochs": 8, "batch_size": 4, "limited_by_cpu": False}
    tab = pb.ablation_table(b)
    names = [r["name"] for r in tab["rows"]]
    assert names == ["full", "no_temporal", "dark", "heatmap_dark", "no_box_jitter",
                     "no_image_augment", "crop96", "crop128", "width8", "width32",
                     "pose_cnn", "average_skeleton"]
    rows = {r["name"]: r for r in tab["rows"]}
    assert rows["full"]["options"]["hp"] == {"width": 16}
    assert rows["dark"]["options"]["hp"] == {"width": 16, "decode": "dark"}
    assert rows["no_box_jitter"]["options"]["box_jitter_scale"] == 0.0
    assert rows["crop96"]["options"]["crop_size"] == 96
    assert tab["budgets"]["quick"]["max_steps"] == 1200
    assert "image_augment" not in rows["pose_cnn"]["options"]
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(tab, sort_keys=False))
    loaded = load_table(path)  # rows, findings, metrics and the budget rule checked
    assert [r["name"] for r in loaded["rows"]] == names
    assert set(loaded["metrics"]) == {"pck_0.05", "pck_0.05_visible", "pck_0.05_occluded",
                                      "pck_0.05_hands", "pck_0.05_feet",
                                      "pckhn_0.1", "pck_0.05_noisy"}


@pytest.fixture(scope="module")
def c32(tmp_path_factory):
    from bsp_fast import conversion as cv
    from bsp_fast.synth import generate

    root = tmp_path_factory.mktemp("pose_budget")
    generate(root / "ds", "sample", clips=3, frames=90, size="480x180", seed=2, workers=1,
             progress=False)
    h5 = root / "c32.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a tiny split's class counts
        cv.convert(root / "ds", h5, clip_length=8, clip_offset=8, crop_size=32,
                   val_frac=0.3, test_frac=0.3, threads=1, crop_context=1.25)
    return h5


def _cmdline(pid: int) -> str:
    """A process's command line, "" once it has exited (a pool's helpers come and go)."""
    try:
        return (Path("/proc") / str(pid) / "cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return ""


def _children(pid: int) -> list:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _gone(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state == "Z"


def test_sigterm_to_the_curves_parent_alone_stops_its_workers(c32, tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen([sys.executable, str(ROOT / "experiments" / "pose_estimation_budget.py"),
                             "curves", "--data", str(c32), "--out", str(tmp_path / "out"),
                             "--crop-sizes", "32", "--widths", "4", "--seeds", "2",
                             "--jobs", "2", "--max-epochs", "50"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        workers = []
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            # the pool's two workers (spawned interpreters), not its resource tracker
            workers = [c for c in _children(proc.pid) if "spawn_main" in _cmdline(c)]
            time.sleep(0.1)
        assert len(workers) == 2, proc.stderr.read().decode()[-2000:]
        os.kill(proc.pid, signal.SIGTERM)  # the parent only, as a scheduler may do
        assert proc.wait(timeout=120) == 143
        deadline = time.monotonic() + 30
        while not all(_gone(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert all(_gone(w) for w in workers)
    finally:
        if proc.poll() is None:
            proc.kill()


def test_smoke_curves_then_the_table_runs(c32, tmp_path):
    import bsp_fast
    from bsp_fast.reproduction.table_files import load_table

    h5 = c32
    out = tmp_path / "out"
    assert pb.main(["curves", "--data", str(h5), "--out", str(out), "--smoke",
                    "--crop-sizes", "32"]) == 0
    b = json.loads((out / "budget.json").read_text())
    (c,) = b["configs"].values()
    assert len(c["updates"]) == 2 and c["updates"][1] == 2 * c["updates"][0]  # 2 chunks
    assert b["smoke"] and b["crop_size"] == 32 and b["width"] == 4
    with h5py.File(out / "data" / "crop32-val-as-test.h5", "r") as f:  # no test clip seen
        np.testing.assert_array_equal(f["test/labels"][()], f["val/labels"][()])
    run = out / "runs" / "crop32-w4" / "seed-0"
    assert len(list(run.glob("logs/version_*"))) == 2  # trained, then resumed
    assert (out / "budget_curves.png").read_bytes()[:4] == b"\x89PNG"
    assert "SMOKE" in (out / "budget.md").read_text()
    tab = load_table(out / "ablation_pose_temporal.yaml")
    assert tab["budgets"]["quick"]["max_steps"] == b["updates"]
    res = bsp_fast.reproduction.cli.main(
        [str(out / "ablation_pose_temporal.yaml"), "--data", str(h5), "--budget",
         "smoke", "--out", str(tmp_path / "repro"), "--rows", "full,pose_cnn,average_skeleton"])
    assert res == 0
    md = (tmp_path / "repro" / "ablation_pose_temporal-smoke" / "results.md").read_text()
    assert "| full | pose_temporal (crop 32, width 4) |" in md
