"""bsp-train / bsp-eval / bsp-predict end to end on tiny generated files: every task trains
2 epochs, bsp-eval reproduces metrics.json, --resume continues, --table, predictions,
seeds, a 2-process DDP run, and bad input."""
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
import yaml

import bsp_fast
from bsp_fast.data.testing import write_clip_file
from bsp_fast.skeleton import JOINT_NAMES
from bsp_fast.training.logs import read_logs
from bsp_fast.training.evaluate import main as eval_main
from bsp_fast.training.train import main as train_main

pytestmark = [pytest.mark.usefixtures("one_torch_thread"),
              pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]

# tiny versions of a model of each task (seconds per run on one core)
TINY = {"classification": ("lstm", {"hidden_size": 8, "num_layers": 1}),
        "autoencoder": ("simple_transformer", {"num_layers": 1, "dim_feedforward": 16}),
        "lifting": ("baseline_3d", {"linear_size": 32, "num_blocks": 1}),
        "pose_estimation": ("pose_cnn", {"width": 4, "hidden": 16})}
KEYS = {"classification": {"loss", "f1", "precision", "recall", "accuracy", "auroc", "ap",
                           "normaliser_fallback"},
        "autoencoder": {"loss", "pck_0.05", "pckhn_0.1", "mjr", "normaliser_fallback"},
        "lifting": {"loss", "mpjpe_mm", "n_mpjpe_mm", "pa_mpjpe_mm", "mpjve_mm",
                    "normaliser_fallback"},
        "pose_estimation": {"loss", "pck_0.05", "pckhn_0.1", "pck_0.05_visible",
                            "pck_0.05_occluded", "pck_0.05_hands", "pck_0.05_feet",
                            "pck_0.05_aligned", "pckhn_0.1_aligned",
                            "fully_occluded_frames"} | {f"pck_0.05/{n}" for n in JOINT_NAMES}}
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("training")
    info = write_clip_file(root / "clips.h5", clips=(48, 16, 16), clip_length=8, seed=3)
    write_clip_file(root / "media.h5", clips=(24, 8, 8), clip_length=4, media=True,
                    crop_size=16, seed=4)
    return {"root": root, "clips": info["clips"]}


def _h5(data, task):
    return data["root"] / ("media.h5" if task == "pose_estimation" else "clips.h5")


def _train(data, task, out, **options):
    model, hp = TINY[task]
    options = {"epochs": 2, "batch_size": 8, "hp": hp, "quiet": True, **options}
    return bsp_fast.train(task, model, data=_h5(data, task), out=out, **options)


@pytest.fixture(scope="module")
def runs(data):
    return {task: _train(data, task, data["root"] / "runs" / task) for task in TINY}


@pytest.mark.parametrize("task", list(TINY))
def test_train_writes_a_complete_run(runs, task):
    res = runs[task]
    run = res.run_dir
    assert sorted(p.name for p in run.iterdir()) == ["checkpoints", "config.yaml", "curves.png",
                                                    "logs", "metrics.json",
                                                    "test_per_recording.json"]
    assert not [p for p in run.parent.iterdir() if p.name.startswith(".")]  # no temporaries
    saved = json.loads((run / "metrics.json").read_text())
    assert set(saved["test"]) == KEYS[task] and saved["test"] == res.metrics
    assert all(math.isfinite(v) for v in saved["test"].values())
    assert set(saved["initial"]["val"]) == set(saved["initial"]["test"]) == KEYS[task]
    assert saved["epochs"] == 2 and saved["best_epoch"] in (1, 2)
    assert (run / "checkpoints" / "best.ckpt").is_file()
    assert (run / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    logs = read_logs(run)
    assert sorted(logs["val/loss"]) == [0, 1] and sorted(logs["train/loss"]) == [0, 1]
    assert saved["val"]["loss"] == pytest.approx(min(logs["val/loss"].values()))
    # the resolved config is a valid --config file
    from bsp_fast.training.config import read_yaml

    cfg = read_yaml(run / "config.yaml")
    assert (cfg["task"], cfg["model"], cfg["epochs"], cfg["force"]) == (task, TINY[task][0], 2,
                                                                       False)


def test_a_run_records_the_machine_that_made_it(runs):
    """config.yaml names the CPU (model name and bf16-relevant flags, read here from
    /proc/cpuinfo independently) and core count; bsp-reproduce's tables group runs by it."""
    import os
    from pathlib import Path

    from bsp_fast.reporting.reproduced import machines_note

    info = Path("/proc/cpuinfo").read_text().splitlines()
    name = next(ln.split(":", 1)[1].strip() for ln in info if ln.startswith("model name"))
    flags = set(next(ln.split(":", 1)[1].split() for ln in info if ln.startswith("flags")))
    rec = yaml.safe_load((runs["lifting"].run_dir / "config.yaml").read_text())["machine"]
    assert rec["cpu"] == name and rec["cpus"] == os.cpu_count() and rec["gpu"] is None
    assert set(rec["cpu_flags"]) == flags & {"avx2", "avx512f", "avx512_bf16", "amx_bf16",
                                             "amx_tile"}
    other = dict(rec, cpu="Other CPU", cpu_flags=[], cpus=16, gpu="Some GPU")
    note = machines_note({"a": {"seeds": {"1": {"machine": rec}, "2": {"machine": other}}},
                          "b": {"seeds": {"1": {"machine": rec}, "2": {}}},
                          "trivial": {"source": "initial", "seeds": {"1": {}}}})
    flagged = " ".join(rec["cpu_flags"]) or "no avx2/avx512f"
    assert note == (f"Machines (each run's, from its config.yaml): {name} ({flagged}), "
                    f"{os.cpu_count()} CPUs: 2 runs (a, b); Other CPU (no avx2/avx512f), 16 "
                    "CPUs + Some GPU: 1 run (a); not recorded (made before runs recorded it, "
                    "2026-11-27): 1 run (b).")


def test_initial_metrics_are_the_trivial_baselines(runs, data):
    initial = json.loads((runs["classification"].run_dir / "metrics.json").read_text())["initial"]
    assert initial["baseline"] == "majority class"
    with h5py.File(_h5(data, "classification")) as f:
        train, test = f["train/labels"][()], f["test/labels"][()]
    majority = int(np.bincount(train, minlength=2).argmax())
    assert initial["test"]["accuracy"] == pytest.approx(np.mean(test == majority))
    # identity on clean inputs: every joint within any threshold
    ae = json.loads((runs["autoencoder"].run_dir / "metrics.json").read_text())["initial"]
    assert ae["test"]["pck_0.05"] == 1.0 and ae["test"]["pckhn_0.1"] == 1.0


@pytest.fixture(scope="module")
def scored_apart(runs):
    """bsp-eval's scores of every task's run, one after the other in one fresh process:
    ``{task: {task, split, metrics, per_recording, lightning}}``, ``lightning`` whether
    Lightning had been imported once that run was scored (one process, not four: each
    start imports PyTorch)."""
    code = ("import json, sys\n"
            "from bsp_fast.training.evaluate import evaluate\n"
            "for run in sys.argv[1:]:\n"
            "    r = evaluate(run)\n"
            "    print('scored', json.dumps({'task': r.task, 'split': r.split,\n"
            "          'metrics': r.metrics, 'per_recording': r.per_recording,\n"
            "          'lightning': 'lightning' in sys.modules}), flush=True)")
    out = subprocess.run([sys.executable, "-c", code, *(str(runs[t].run_dir) for t in TINY)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = [ln.split(" ", 1)[1] for ln in out.stdout.splitlines() if ln.startswith("scored ")]
    assert len(lines) == len(TINY), out.stdout
    return dict(zip(TINY, map(json.loads, lines)))


@pytest.mark.parametrize("task", list(TINY))
def test_eval_reproduces_metrics_json(runs, scored_apart, task):
    """bsp-eval scores in plain PyTorch: Trainer.test's numbers (metrics.json and the
    per-recording sums) to the last digit, without importing Lightning."""
    run = runs[task].run_dir
    res = scored_apart[task]
    assert res["task"] == task and res["split"] == "test" and not res["lightning"]
    assert res["metrics"] == json.loads((run / "metrics.json").read_text())["test"]
    saved = json.loads((run / "test_per_recording.json").read_text())["test"]
    assert {k: res["per_recording"][k] for k in saved} == saved


def test_eval_cli_and_table(runs, capsys, tmp_path):
    run = runs["lifting"].run_dir
    assert eval_main([str(run / "checkpoints" / "best.ckpt"), "--quiet",
                      "--json", str(tmp_path / "m.json")]) == 0
    out = json.loads((tmp_path / "m.json").read_text())
    assert out["test"]["mpjpe_mm"] == pytest.approx(runs["lifting"].metrics["mpjpe_mm"])
    capsys.readouterr()
    assert eval_main(["--table"] + [str(r.run_dir) for r in runs.values()]) == 0
    text = capsys.readouterr().out
    for title, header in (
            ("classification", "| model | σ (px) | MJP | F1 | precision | recall | accuracy "
                               "| AUROC | AP |"),
            ("autoencoder", "| model | σ (px) | MJP | MJR | PCK@0.05 (%) | PCKhn@0.1 (%) |"),
            ("lifting", "| model | MPJPE (mm) | N-MPJPE (mm) | PA-MPJPE (mm) | MPJVE (mm/frame) |"),
            ("pose_estimation", "| model | PCK@0.05 (%) | PCKhn@0.1 (%) |")):
        section = text.split(f"### {title} (test)")[1].split("###")[0]
        squeezed = " ".join(section.split())
        assert header in squeezed.replace("| epochs | run |", "|")
        assert "initial: " in section and f"| {TINY[title][0]} " in squeezed
    mm = f"{runs['lifting'].metrics['mpjpe_mm']:.2f}"
    assert mm in text
    assert eval_main(["--table", "--format", "csv", str(run)]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].startswith("task,model,MPJPE (mm),N-MPJPE (mm),PA-MPJPE (mm),MPJVE (mm/frame)")
    assert rows[1].startswith("lifting,initial: mean training pose,") and len(rows) == 3


def test_resume_continues_from_the_last_checkpoint(runs, tmp_path):
    run = tmp_path / "resumed"
    shutil.copytree(runs["classification"].run_dir, run)
    before = read_logs(run)["val/loss"]
    res = bsp_fast.train(resume=run, epochs=3, quiet=True)  # in place
    assert res.run_dir == run and res.epochs == 3
    logs = read_logs(run)
    assert sorted(logs["val/loss"]) == [0, 1, 2]
    assert {e: logs["val/loss"][e] for e in (0, 1)} == before  # continued, not restarted
    assert sorted(p.name for p in (run / "logs").iterdir()) == ["version_0", "version_1"]
    ckpt = torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)
    assert ckpt["epoch"] == 2
    saved = json.loads((run / "metrics.json").read_text())
    assert saved["epochs"] == 3
    assert saved["initial"] == json.loads(
        (runs["classification"].run_dir / "metrics.json").read_text())["initial"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_same_seed_same_metrics(data, tmp_path):
    # noise, missing joints, augmentation, dropout and batch order all come from the seed
    opts = dict(noise=3.0, mjp=0.1, seed=5)
    a = _train(data, "autoencoder", tmp_path / "a", **opts)
    b = _train(data, "autoencoder", tmp_path / "b", **opts)
    c = _train(data, "autoencoder", tmp_path / "c", **dict(opts, seed=6))
    assert a.metrics == b.metrics  # bit-identical on CPU
    assert read_logs(a.run_dir)["train/loss"] == read_logs(b.run_dir)["train/loss"]
    assert a.metrics["loss"] != c.metrics["loss"]
    assert 0.05 < a.metrics["mjr"] < 0.15  # realised missing-joint ratio of mjp 0.1


def test_bf16_mixed_trains_lstm_models_on_any_cpu(data, tmp_path):
    # the models' LSTM layers fall back to float32 inside autocast where oneDNN has no bf16
    # LSTM kernel, so bf16-mixed is an option for every model, not a refusal
    run = _train(data, "classification", tmp_path / "bf16", epochs=1, precision="bf16-mixed")
    cfg = yaml.safe_load((run.run_dir / "config.yaml").read_text())
    assert cfg["resolved"]["precision"] == "bf16-mixed"
    assert 0.0 <= run.metrics["f1"] <= 1.0 and math.isfinite(run.metrics["loss"])
    # scoring it again on this CPU gives the same numbers (float32 where bf16 is slow)
    again = bsp_fast.evaluate(run.run_dir, quiet=True)
    assert again.metrics["loss"] == pytest.approx(run.metrics["loss"], rel=2e-2)


def test_predict_writes_denormalised_outputs(runs, data, tmp_path):
    from bsp_fast.training.predict import main as predict_main

    out = tmp_path / "lifting.h5"
    assert predict_main([str(runs["lifting"].run_dir), "--out", str(out), "--quiet"]) == 0
    with h5py.File(out) as f, h5py.File(_h5(data, "lifting")) as src:
        rows = f["row"][()]
        assert sorted(rows.tolist()) == list(range(src["test/labels"].shape[0]))
        np.testing.assert_array_equal(f["clip_id"][()], src["test/meta/clip_id"][()][rows])
        target = src["test/targets/absolute_pose_loc"][()][rows]
        np.testing.assert_allclose(f["target_metres"][()], target, atol=1e-6)
        # the outputs the run's test metrics scored (float32 sums vs float64: rel ~1e-9)
        err = np.linalg.norm(f["metres_aligned"][()] - target, axis=-1).mean() * 1000
        assert err == pytest.approx(runs["lifting"].metrics["mpjpe_mm"], rel=1e-6)
        pa = bsp_fast.metrics.pa_mpjpe(f["metres_aligned"][()], target) * 1000
        assert pa == pytest.approx(runs["lifting"].metrics["pa_mpjpe_mm"], rel=1e-6)
        assert f.attrs["task"] == "lifting" and f.attrs["units"] == "metres"
    out = tmp_path / "ae.h5"
    assert predict_main([str(runs["autoencoder"].run_dir), "--out", str(out), "--quiet"]) == 0
    assert predict_main([str(runs["autoencoder"].run_dir), "--out", str(out)]) == 3
    with h5py.File(out) as f, h5py.File(_h5(data, "autoencoder")) as src:
        clean = src["test/projection_2d"][()][f["row"][()]]
        np.testing.assert_allclose(f["target_pixels"][()], clean, atol=2e-3)
        assert f["pixels"].shape == clean.shape
        # clean inputs: the input's normalisation is the target's
        np.testing.assert_allclose(f["pixels"][()], f["pixels_scored"][()], atol=1e-3)
        pck = bsp_fast.metrics.pck(f["pixels_scored"][()], f["target_pixels"][()], alpha=0.05)
        assert pck == pytest.approx(runs["autoencoder"].metrics["pck_0.05"], rel=1e-9)
    out = tmp_path / "cls.h5"
    assert predict_main([str(runs["classification"].run_dir), "--out", str(out), "--quiet"]) == 0
    with h5py.File(out) as f:
        assert "units" not in f.attrs  # logits, probabilities, 0/1: no pixels
        acc = np.mean(f["prediction"][()] == f["label"][()])
        assert acc == pytest.approx(runs["classification"].metrics["accuracy"])
        f1 = bsp_fast.metrics.f1_score(f["prediction"][()], f["label"][()])
        assert f1 == pytest.approx(runs["classification"].metrics["f1"])


def test_predict_runs_in_the_precision_and_noise_bsp_eval_scores_in(runs, data, tmp_path,
                                                                     monkeypatch):
    """bsp-predict's outputs are the ones bsp-eval scores: a run trained in bf16-mixed
    (what ``--precision auto`` picks for baseline_3d on a CPU with native bf16) is
    predicted in bf16 too (it was float32: MPJPE 891.586 mm against the scored
    891.425 mm); a --noise override deforms the same clips the same way. The run is
    trained in bf16-mixed here whatever the CPU: on an AVX2-only CPU ``auto`` trains the
    shared runs in float32, and both predictions below would be float32."""
    from bsp_fast.training import precision
    from bsp_fast.training.predict import predict

    monkeypatch.setattr(precision, "native_bf16", lambda accelerator: True)
    run = _train(data, "lifting", tmp_path / "bf16", precision="bf16-mixed").run_dir
    scored = bsp_fast.evaluate(run, quiet=True).metrics
    res = predict(run, tmp_path / "lifting.h5")
    with h5py.File(res.path) as f:
        pred, target = f["metres_aligned"][()], f["target_metres"][()]
    err = np.linalg.norm(pred - target, axis=-1).mean() * 1000
    assert err == pytest.approx(scored["mpjpe_mm"], rel=1e-6)
    monkeypatch.setattr(precision, "native_bf16", lambda accelerator: False)
    f32 = predict(run, tmp_path / "lifting32.h5")
    with h5py.File(f32.path) as f:
        assert np.abs(f["metres_aligned"][()] - pred).max() > 1e-4  # bf16 above was bf16
    run = runs["autoencoder"].run_dir
    scored = bsp_fast.evaluate(run, noise=3.0, quiet=True).metrics
    res = predict(run, tmp_path / "ae.h5", noise=3.0)
    with h5py.File(res.path) as f:
        got, want = f["pixels_scored"][()], f["target_pixels"][()]
        assert np.abs(f["pixels"][()] - got).max() > 1e-3  # noisy input, other normalisation
    for key, alpha, norm in (("pck_0.05", 0.05, "bbox"), ("pckhn_0.1", 0.1, "hips_neck")):
        value = bsp_fast.metrics.pck(got, want, alpha=alpha, norm=norm)
        assert value == pytest.approx(scored[key], rel=1e-9), key


def test_lifting_scores_with_the_reference_skeleton(data):
    """A perfect normalised prediction is scaled by the reference hips-neck length of the
    clip's (age, gender) and put on the target's hips: the MPJPE is the hand-computed
    error of that scale against each clip's true skeleton."""
    from bsp_fast.data import ClipDataset
    from bsp_fast.training.scoring import TaskMetrics

    ds = ClipDataset(_h5(data, "lifting"), "test", "lifting")
    batch = ds[list(range(len(ds)))]

    class Whole:
        def frame_slice(self, L):
            return slice(0, L)

    metrics = TaskMetrics("lifting")
    metrics.update(batch["targets"], batch, Whole())
    got = metrics.compute()["mpjpe_mm"]
    ref = {}
    for age, gender in set(zip(batch["meta"]["age"], batch["meta"]["gender"])):
        comp = bsp_fast.forward_kinematics(bsp_fast.skeleton.reference_pose((age, gender)))
        ref[age, gender] = np.linalg.norm(comp[8, :3] - comp[1, :3])
    hn = np.array([ref[k] for k in zip(batch["meta"]["age"], batch["meta"]["gender"])])
    t = batch["targets"].numpy().astype(np.float64)
    m = batch["targets_m"].numpy().astype(np.float64)
    pred = t * hn[:, None, None, None] + m[:, :, 1:2, :]
    want = np.linalg.norm(pred - m, axis=-1).mean() * 1000
    assert want > 1.0  # children's skeletons are shorter than the recorded female one
    assert got == pytest.approx(want, rel=1e-5)


def test_ddp_two_processes_match_one(data, tmp_path):
    """One 2-process DDP run on CPU (gloo): its test metrics, reduced over both processes,
    equal a single-process evaluation of the same checkpoint."""
    assert data["clips"]["test"] % 2 == 0  # no clip repeated to even out the ranks
    model, hp = TINY["lifting"]
    out = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "bsp_fast", "train", "lifting", model, "--data",
           str(_h5(data, "lifting")), "--out", str(out), "--epochs", "1", "--batch-size", "8",
           "--accelerator", "cpu", "--devices", "2", "--strategy", "ddp", "--quiet"]
    cmd += [a for k, v in hp.items() for a in ("--hp", f"{k}={v}")]
    env = dict(os.environ, OMP_NUM_THREADS="1",
               PYTHONPATH=os.pathsep.join([str(REPO / "python"), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["world_size"] == 2
    single = bsp_fast.evaluate(out)
    assert single.metrics == pytest.approx(saved["test"], rel=1e-6)


def _no_run(path: Path) -> bool:
    return not path.exists() and not [p for p in path.parent.iterdir()
                                      if p.name.startswith(f".{path.name}.")]


def test_bad_input_fails_cleanly(runs, data, tmp_path, capsys):
    out = tmp_path / "bad"
    h5 = str(_h5(data, "lifting"))
    cases = [
        (["lifting", "baseline_3d", "--data", str(tmp_path / "nope.h5")], 1,
         "no such dataset directory or HDF5 file"),
        (["pose_estimation", "pose_cnn", "--data", h5], 1,
         "lacks ['frames/rgb', 'frames/crop_box', 'frames/joint_visible', 'clip_frames']"),
        (["lifting", "resnet", "--data", h5], 2,
         "unknown model 'resnet' for task 'lifting'; allowed: baseline_3d"),
        (["lifting", "baseline_3d", "--data", h5, "--hp", "width=3"], 2,
         "has no hyper-parameter 'width'; allowed: linear_size=1024"),
        (["lifting", "baseline_3d", "--data", h5, "--hp", "linear_size=-1"], 2, "linear_size"),
        (["lifting", "baseline_3d", "--resume", str(runs["classification"].run_dir)], 2,
         "is a 'classification' run of model 'lstm'; it cannot continue as task 'lifting'"),
        (["lifting", "baseline_3d", "--data", h5, "--noise", "-1"], 2, "noise must be >= 0.0"),
    ]
    for argv, code, message in cases:
        assert train_main(argv + ["--out", str(out), "--quiet"]) == code, argv
        assert message in capsys.readouterr().err, argv
        assert _no_run(out), argv
    # an existing run directory is never replaced without --force
    run = runs["lifting"].run_dir
    stamp = (run / "metrics.json").stat().st_mtime_ns
    assert train_main(["lifting", "baseline_3d", "--data", h5, "--out", str(run)]) == 3
    assert "exists; pass --force" in capsys.readouterr().err
    assert (run / "metrics.json").stat().st_mtime_ns == stamp
    # a checkpoint evaluated on a file converted without what its task needs
    assert eval_main([str(runs["pose_estimation"].run_dir), "--data", h5]) == 1
    assert "lacks ['frames/rgb'" in capsys.readouterr().err
    assert eval_main([h5]) == 1
    assert "expected a run directory or a .ckpt" in capsys.readouterr().err


def test_help_lists_tasks_and_models(capsys):
    with pytest.raises(SystemExit) as info:
        train_main(["--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    for task in TINY:
        assert f"  {task}:" in text
    from bsp_fast import models

    for name in models.available("lifting"):
        assert f"    {name} " in text
    for flag in ("--hp KEY=VALUE", "--precision", "--resume", "--config", "--mjp", "--strategy"):
        assert flag in text
