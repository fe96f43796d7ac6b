"""Issue #57: ``bsp-reproduce TABLE --estimate`` (a timed probe per row, the table's CPU
total against the budget) and the registered independent test sets (what was registered,
recordings disjoint from training, checked by code); every registered quick budget pins
float32."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from bsp_fast.reporting.estimate import format_estimate
from bsp_fast.reproduction import estimate as E
from bsp_fast.reproduction import test_sets as T
from bsp_fast.reproduction.table_files import experiments_dir, load_table

pytestmark = pytest.mark.usefixtures("one_torch_thread")

AVX512 = {"model": "x", "avx512": True, "bf16": True}


# ---------------------------------------------------------------------- the arithmetic
def test_seed_cost_counts_the_capped_updates_every_validation_and_the_test_passes():
    c = E.seed_cost(0.5, 0.1, train_batches=10, val_batches=3, test_batches=4, epochs=40,
                    max_steps=95)
    assert (c["updates"], c["epochs"]) == (95, 10)  # the cap ends it in epoch 10
    # 10 validations + the initial val and test passes + one test pass
    assert c["eval_s"] == pytest.approx((10 * 3 + 3 + 4 + 4) * 0.1)
    assert c["total_s"] == pytest.approx(95 * 0.5 + c["eval_s"] + E.STARTUP_S)
    uncapped = E.seed_cost(0.5, 0.1, train_batches=10, val_batches=3, test_batches=4,
                           epochs=2, max_steps=None, test_passes=2, test_scale=3)
    assert uncapped["updates"] == 20
    assert uncapped["eval_s"] == pytest.approx((2 * 3 + 3 + 4 + 4 * 2 * 3) * 0.1)


def test_avx2_translation_is_float32_only_and_at_least_the_measured_step():
    assert E.avx2_factor("lifting", "lstm", "bf16-mixed", AVX512) is None
    assert E.avx2_factor("lifting", "lstm", "32", {"avx512": False}) == 1.0
    f = E.avx2_factor("lifting", "poseformer", "32", AVX512)
    assert f == pytest.approx(5320.9 / 3789.4)
    # a quiet machine's faster step: the AVX2 core's own measured step is the floor
    assert E.avx2_factor("lifting", "poseformer", "32", AVX512, step_s=1.0,
                         batch=16) == pytest.approx(5.3209)
    assert E.avx2_factor("lifting", "poseformer", "32", AVX512, step_s=1.0, batch=8) == f
    assert E.avx2_factor("x", "unknown", "32", AVX512) == E.AVX2_DEFAULT_FACTOR


# ---------------------------------------------------------------------- the probe
def _tiny_table(tmp_path, data_rows=True) -> Path:
    doc = yaml.safe_load((experiments_dir() / "autoencoder.yaml").read_text())
    doc.pop("power", None)
    doc["table"] = "tiny_estimate"
    doc["budgets"]["quick"] = {"epochs": 3, "max_steps": 5, "batch_size": 8,
                               "accelerator": "cpu", "precision": "32", "threads": 1}
    doc["common"]["hp"] = {"num_layers": 1, "dim_feedforward": 32}
    doc["rows"].append({"name": "moved_row", "label": "moved", "options": {},
                        "moved": {"to": "full", "why": "needs a GPU", "when": "2026-11-29"}})
    doc["design"] = {"seeds": {"quick": 10}}
    path = tmp_path / "tiny_estimate.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def clip_file(tmp_path_factory):
    from bsp_fast.data.testing import write_clip_file

    path = tmp_path_factory.mktemp("est") / "l30.h5"
    write_clip_file(path, clips=(24, 12, 12), clip_length=30, seed=2)
    return path


def test_estimate_probes_every_row_at_its_registered_seeds(tmp_path, clip_file):
    tab = load_table(_tiny_table(tmp_path))
    est = E.estimate_table(tab, clip_file, "quick", steps=2, eval_batches=1,
                           log=lambda s: None)
    assert est["seeds"] == 10 and set(est["rows"]) == {"clean", "noisy"}
    assert est["moved"] == {"moved_row": "needs a GPU"}
    for r in est["rows"].values():
        assert r["precision"] == "32" and r["step_s"] > 0 and r["eval_s"] > 0
        assert r["updates"] == 5 and r["seeds"] == 10
        assert r["total_s"] == pytest.approx(10 * r["per_seed_s"])
    text = format_estimate(est)
    assert "moved to the full budget (GPU): needs a GPU" in text
    assert "against the budget of 8 CPU h" in text


def test_cli_estimate_trains_nothing_and_prints_the_total(tmp_path, clip_file, capsys):
    from bsp_fast.reproduction.cli import main

    path = _tiny_table(tmp_path)
    code = main([str(path), "--data", str(clip_file), "--estimate", "--rows", "clean",
                 "--seeds", "3", "--out", str(tmp_path / "runs")])
    out = capsys.readouterr().out
    assert code == 0 and "| clean | simple_transformer | 32 |" in out
    assert "Total on an AVX2-only core" in out
    assert (tmp_path / "runs" / "tiny_estimate-quick.estimate.json").is_file()
    assert not (tmp_path / "runs" / "tiny_estimate-quick").exists()  # nothing trained


# ---------------------------------------------------------------------- the tables
def _table_files():
    return sorted(p.stem for p in experiments_dir().glob("*.yaml"))


@pytest.mark.parametrize("name", _table_files())
def test_every_registered_quick_budget_trains_in_float32(name):
    tab = load_table(name)
    assert str(tab["budgets"]["quick"].get("precision")) == "32"
    moved = E.moved_rows(tab, "quick")
    for row in tab["rows"]:
        own = ((row.get("budgets") or {}).get("quick") or {}).get("precision")
        assert own in (None, "32") or row["name"] in moved, row["name"]
    for name_, why in moved.items():
        assert why.strip(), name_


@pytest.mark.parametrize("name", _table_files())
def test_registered_test_sets_are_well_formed_and_as_large_as_the_power_table_asks(name):
    tab = load_table(name)
    ts = T.registered_test_set(tab)
    if ts is None:
        return
    seeds = E.registered_seeds(tab, "quick")
    assert seeds is not None, "a test set is registered together with the seed count"
    assert ts["generator"]["seed"] != 22752  # bsp-synth's default: the training data's
    power = tab.get("power") or {}
    key = "recordings_needed_at_10_seeds" if seeds >= 10 else "recordings_needed"
    asked = [f[key] for f in power.get("findings", []) if f.get(key)]
    if asked and ts.get("covers") != "partial":
        assert ts["recordings"] >= max(asked)


# ---------------------------------------------------------------------- independence
def _synth(path: Path, seed: int, clips: int = 10) -> Path:
    from bsp_fast.synth.generate import generate

    generate(path, "sample", clips=clips, frames=150, seed=seed, poses_only=True,
             workers=1, progress=False)
    return path


@pytest.fixture(scope="module")
def two_sets(tmp_path_factory):
    root = tmp_path_factory.mktemp("testsets")
    return _synth(root / "train", 22752), _synth(root / "test", 57001, clips=12)


def _tab(seed=57001, clips=12) -> dict:
    return {"table": "t", "design": {"test_set": {
        "generator": {"preset": "sample", "seed": seed, "clips": clips, "frames": 150,
                      "poses_only": True}, "scale": 1, "recordings": 4}}}


def test_a_registered_test_set_is_checked_independent(two_sets):
    train, test = two_sets
    got = T.check_test_set(_tab(), train, test)
    assert got["test_recordings"] >= 1 and got["seed"] == 57001
    assert T.synth_command(T.registered_test_set(_tab()), "D") == [
        "bsp-synth", "D", "--preset", "sample", "--seed", "57001", "--clips", "12",
        "--frames", "150", "--poses-only"]


def test_the_wrong_seed_or_size_is_refused(two_sets):
    train, test = two_sets
    with pytest.raises(T.TestSetError, match="registered: seed 57002"):
        T.check_test_set(_tab(seed=57002), train, test)
    with pytest.raises(T.TestSetError, match="training data's seed"):
        T.check_test_set(_tab(seed=22752, clips=10), train, train)  # its own seed


def test_a_shared_recording_or_track_is_refused(two_sets, tmp_path):
    train, test = two_sets
    leak = tmp_path / "leak"
    shutil.copytree(test, leak)
    train_rows = (train / "data.csv").read_text().splitlines()
    with open(leak / "data.csv", "a") as fh:  # one training row appended
        fh.write(train_rows[1] + "\n")
    with pytest.raises(T.TestSetError, match="also in"):
        T.check_disjoint(train, leak)
    # the same track under another id
    lines = (train / "data.csv").read_text().splitlines()
    first_id = lines[1].split(",", 1)[0]
    renamed = [lines[0]] + [ln.replace(first_id, "00000000-0000-4000-8000-000000000000-0", 1)
                            for ln in lines[1:] if ln.startswith(first_id)]
    other = tmp_path / "renamed"
    shutil.copytree(test, other)
    with open(other / "data.csv", "a") as fh:
        fh.write("\n".join(renamed[1:]) + "\n")
    with pytest.raises(T.TestSetError, match="repeat a track"):
        T.check_disjoint(train, other)


# ---------------------------------------------------------------------- scoring on it
def test_test_data_scores_the_other_datasets_test_split(two_sets, tmp_path):
    """bsp-train's test_data: train and validate on --data, test on the registered test
    set's test split, converted with the run's own options; the run's config keeps it, so
    bsp-eval scores the same clips."""
    from bsp_fast.training import config as C
    from bsp_fast.training.evaluate import evaluate
    from bsp_fast.training.setup import make_datamodule, prepare_data
    from bsp_fast.training.train import train

    train_dir, test_dir = two_sets
    cfg = C.defaults() | dict(task="autoencoder", model="simple_transformer",
                              data=str(train_dir), test_data=str(test_dir), clip_length=20,
                              batch_size=8, quiet=True)
    dm = make_datamodule(cfg)
    prepare_data(dm, stages=("fit", "test"))
    assert Path(dm.datasets["test"].h5_path).is_relative_to(test_dir)
    assert Path(dm.datasets["train"].h5_path).is_relative_to(train_dir)
    res = train(task="autoencoder", model="simple_transformer", data=str(train_dir),
                out=str(tmp_path / "run"), test_data=str(test_dir), clip_length=20,
                epochs=1, batch_size=8, limit_batches=2, hp={"num_layers": 1},
                precision="32", quiet=True)
    assert res is not None
    again = evaluate(tmp_path / "run")
    assert again.clips == len(dm.datasets["test"])
