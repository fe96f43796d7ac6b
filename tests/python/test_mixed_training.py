"""Mixed training through bsp-train (``--mix``, ``--mix-data``, ``--test-on``) and the report's
mixed-training table (``experiments/mixed.yaml``), end to end on fixture JAAD and PIE
annotation folders (imported by bsp-interop) and a small CARLA-BSP dataset."""
import json
import re
import shlex
from pathlib import Path

import h5py
import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("lightning")

from bsp_fast.data.mix_tables import check_mix, quotas  # noqa: E402
from bsp_fast.data.testing import write_clip_file  # noqa: E402
from bsp_fast.training import config as C  # noqa: E402
from bsp_fast.training.evaluate import evaluate  # noqa: E402
from bsp_fast.training.setup import make_datamodule, prepare_data  # noqa: E402
from bsp_fast.training.train import main as train_main, train  # noqa: E402
from bsp_fast.defaults import SEED  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_torch_thread")

REPO = Path(__file__).resolve().parents[2]
TINY = {"num_layers": 1, "dim_feedforward": 8}
FAST = dict(epochs=1, batch_size=8, accelerator="cpu", precision="32", quiet=True, hp=TINY)
MIX = {"clip_length": 8, "sources": [{"name": "jaad", "share": 0.25},
                                     {"name": "carla_bsp", "share": 0.75, "data": True}]}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Three clip files of 8 frames (jaad, carla as --data, pie test-only) and one of 4."""
    root = tmp_path_factory.mktemp("mixfiles")
    sizes = {"jaad": (24, 8, 8), "carla": (48, 8, 8), "pie": (16, 8, 12)}
    out = {}
    for k, (name, clips) in enumerate(sizes.items()):
        write_clip_file(root / f"{name}.h5", clips=clips, clip_length=8, seed=k)
        out[name] = root / f"{name}.h5"
    write_clip_file(root / "short.h5", clips=(8, 4, 4), clip_length=4, seed=9)
    out["short"] = root / "short.h5"
    return out


def _clips(path, split):
    with h5py.File(path, "r") as f:
        return len(f[f"{split}/labels"])


def test_a_mix_trains_in_its_shares_tests_on_the_named_source_and_is_recorded(files, tmp_path):
    opts = dict(data=str(files["carla"]), mix=MIX, test_on="pie",
                mix_data={"jaad": str(files["jaad"]), "pie": str(files["pie"])})
    cfg = C.validate(C.defaults() | C.normalise(dict(opts, task="autoencoder",
                                                     model="simple_transformer")))
    dm = make_datamodule(cfg)
    prepare_data(dm)
    # the data: true source reads --data; every epoch draws 25 % / 75 % of 24 + 48 clips
    assert [s["h5_path"] for s in dm.sources] == [str(files["jaad"]), str(files["carla"])]
    sampler = dm.train_sampler()
    for epoch in (0, 1):
        idx = np.concatenate(sampler.batches(epoch))
        source = np.searchsorted(sampler.offsets, idx, side="right") - 1
        assert np.bincount(source, minlength=2).tolist() == [18, 54] == \
            quotas([0.25, 0.75], 72).tolist()
    # validation: both sources' val splits; test: PIE's alone
    assert len(dm.datasets["val"]) == _clips(files["jaad"], "val") + _clips(files["carla"], "val")
    assert len(dm.datasets["test"]) == _clips(files["pie"], "test") == 12

    run = train("autoencoder", "simple_transformer", out=str(tmp_path / "run"), **opts, **FAST)
    saved = C.read_yaml(run.run_dir / "config.yaml")
    assert saved["mix"] == {"clip_length": 8, "sources": [
        {"name": "jaad", "share": 0.25, "data": False},
        {"name": "carla_bsp", "share": 0.75, "data": True}]}
    assert saved["mix_data"] == {"jaad": str(files["jaad"]), "pie": str(files["pie"])}
    assert saved["test_on"] == "pie"
    # bsp-eval rebuilds the same data from the record: the run's own test numbers, on PIE's
    # 12 test clips; --test-on jaad scores JAAD's test split instead
    again = evaluate(run.run_dir, accelerator="cpu")
    assert again.clips == 12 and again.metrics == pytest.approx(run.metrics, rel=1e-6)
    other = evaluate(run.run_dir, accelerator="cpu", test_on="jaad")
    assert other.clips == _clips(files["jaad"], "test") == 8
    assert evaluate(run.run_dir, split="val", accelerator="cpu").clips == 16
    # bsp-eval on a dataset the run never named: its --mix-data adds to the run's files
    from bsp_fast.training.evaluate import main as eval_main

    out = tmp_path / "other.json"
    assert eval_main([str(run.run_dir), "--test-on", "again", "--mix-data",
                      f"again={files['jaad']}", "--mix-data", f"unused={files['pie']}",
                      "--accelerator", "cpu", "--json", str(out), "--quiet"]) == 0
    scored = json.loads(out.read_text())
    assert scored["test"]["pck_0.05"] == pytest.approx(other.metrics["pck_0.05"], rel=1e-6)


def test_without_test_on_every_source_is_tested_and_recordings_stay_apart(files):
    # write_clip_file names recordings alike in every file: clips/rec0000-0, ...
    opts = dict(task="autoencoder", model="simple_transformer", data=str(files["carla"]),
                mix=MIX, mix_data={"jaad": str(files["jaad"])})
    dm = make_datamodule(C.validate(C.defaults() | C.normalise(opts)))
    prepare_data(dm)
    n = {k: _clips(files[k], "test") for k in ("jaad", "carla")}
    batch = dm.datasets["test"][list(range(n["jaad"] + n["carla"]))]
    assert batch["meta"]["source"].tolist() == [0] * n["jaad"] + [1] * n["carla"]
    names = [v.split(":", 1)[0] for v in batch["meta"]["video_id"]]
    assert names == ["jaad"] * n["jaad"] + ["carla_bsp"] * n["carla"]
    with h5py.File(files["jaad"], "r") as f:
        own = f["test/meta/video_id"].asstr()[()].tolist()
    assert [v.split(":", 1)[1] for v in batch["meta"]["video_id"][:n["jaad"]]] == own


def test_a_mixed_run_resumed_mid_epoch_skips_the_batches_it_trained_on():
    from bsp_fast.data.mixed import MixedBatchSampler

    sampler = MixedBatchSampler([10, 20], [0.5, 0.5], 30, 4, seed=3)
    first = [list(b) for b in sampler.batches(1)]
    sampler.set_epoch(1)  # Lightning sets the epoch, bsp-train's Lifecycle the skip
    sampler.skip_batches(1, 3)
    assert [list(b) for b in sampler] == first[3:]
    assert [list(b) for b in sampler] == [list(b) for b in sampler.batches(2)]  # whole again


def test_mix_table_by_name_with_repeated_mix_data_on_the_command_line(files, tmp_path, capsys):
    table = tmp_path / "half.yaml"
    table.write_text("task: autoencoder\nclip_length: 8\nsources:\n"
                     "  - {name: jaad, share: 0.5}\n  - {name: pie, share: 0.5}\n")
    argv = ["autoencoder", "simple_transformer", "--mix", str(table),
            "--mix-data", f"jaad={files['jaad']}", "--mix-data", f"pie={files['pie']}",
            "--print-config"]
    assert train_main(argv) == 0
    doc = capsys.readouterr().out
    assert f"mix_data: {{jaad: {files['jaad']}, pie: {files['pie']}}}" in doc
    assert f"table: {table}" in doc
    # no source reads --data: the run's data is the mix's first file
    assert f"data: {files['jaad']}" in doc


def _config(tmp_path, mix, **extra):
    path = tmp_path / "cfg.yaml"
    import yaml

    path.write_text(yaml.safe_dump(dict(mix=mix, **extra)))
    return path


@pytest.mark.parametrize("mix, extra, code, needles", [
    ({"sources": [{"name": "jaad", "share": 0.5}, {"name": "carla_bsp", "share": 0.4,
                                                   "data": True}]},
     {}, 2, ["shares must add up to 1, got 0.9"]),
    ({"sources": [{"name": "jaad", "share": 0}, {"name": "carla_bsp", "share": 1,
                                                 "data": True}]},
     {}, 2, ["source 'jaad': share must be a number > 0, got 0"]),
    ({"sources": [{"name": "jaad", "share": 0.5, "data": True},
                  {"name": "carla_bsp", "share": 0.5, "data": True}]},
     {}, 2, ["at most one source reads --data", "['jaad', 'carla_bsp']"]),
    ({"sources": [{"name": "jaad", "share": 1.0}], "weights": [1]},
     {}, 2, ["unknown key(s) ['weights']"]),
    ({"sources": [{"name": "amass", "share": 0.5}, {"name": "carla_bsp", "share": 0.5,
                                                    "data": True}]},
     {}, 2, ["mix source(s) ['amass'] have no clip file: give --mix-data amass=FILE"]),
    ({"sources": [{"name": "jaad", "share": 1.0}]},
     {"mix_data": {"jaad": "missing.h5"}}, 1, ["mix source 'jaad':", "missing.h5: no such "
                                               "clip file"]),
    (MIX, {"test_on": "pie2"}, 2, ["test_on 'pie2' has no clip file: give --mix-data "
                                   "pie2=FILE", "jaad, carla_bsp"]),
    (MIX, {"strategy": "ddp"}, 2, ["a mix trains in one process"]),
    (MIX, {"balance": True}, 2, ["--balance"]),
    (MIX, {"test_on": "short"}, 1, ["clip_length 8, but source 'short'", "short.h5) has 4",
                                    "--obs-length 8"]),
    (dict(MIX, clip_length=4), {}, 1, ["clip_length 4, but source 'jaad'", "has 8",
                                       "source 'carla_bsp'"]),
])
def test_bad_mixes_fail_with_one_line_naming_why_and_write_nothing(files, tmp_path, capsys,
                                                                   mix, extra, code, needles):
    extra = dict(extra)
    given = extra.pop("mix_data", {"jaad": str(files["jaad"]), "short": str(files["short"])})
    cfg = _config(tmp_path, mix, mix_data=given, **extra)
    out = tmp_path / "run"
    argv = ["autoencoder", "simple_transformer", "--data", str(files["carla"]), "--config",
            str(cfg), "--out", str(out), "--epochs", "1", "--quiet"]
    assert train_main(argv) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]
    assert not out.exists() and not list(tmp_path.glob(".run*"))


def test_mix_options_need_a_mix_and_a_2d_task(files, capsys):
    base = ["--data", str(files["carla"]), "--print-config"]
    assert train_main(["autoencoder", "simple_transformer", "--mix-data",
                       f"jaad={files['jaad']}"] + base) == 2
    assert "mix_data without a mix: give --mix TABLE" in capsys.readouterr().err
    assert train_main(["lifting", "lstm", "--mix", "autoencoder"] + base) == 2
    assert "not 'lifting'" in capsys.readouterr().err
    assert train_main(["autoencoder", "simple_transformer", "--mix", "nope"] + base) == 2
    assert "no mixing table 'nope'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="mix_data expects NAME=FILE"):
        C.normalise({"mix_data": "jaad"})


# ------------------------------------------------------------------ the table, end to end
def test_the_table_file_holds_the_mixes_and_no_amass_row():
    from bsp_fast.reproduction.table_files import load_table

    tab = load_table("mixed")
    assert list(tab["metrics"]) == list(load_table("autoencoder")["metrics"])
    mixes = {}
    for row in tab["rows"]:
        mix = check_mix(row["options"]["mix"], row["name"])
        shares = {s["name"]: s["share"] for s in mix["sources"]}
        assert "amass" not in shares and "report" not in row
        assert [s["name"] for s in mix["sources"] if s["data"]] in ([], ["carla_bsp"])
        mixes.setdefault(row["options"]["test_on"], []).append(shares)
    # every mix tested on both datasets; the report's 10 : 40 without AMASS is 20 : 80
    assert mixes["jaad"] == mixes["pie"] and len(mixes["jaad"]) == 3
    assert {"jaad": 0.2, "carla_bsp": 0.8} in mixes["jaad"]
    for page in (REPO / "docs" / "interop.md", REPO / "experiments" / "mixed.yaml"):
        assert "AMASS has no importer" in " ".join(page.read_text().split()), page


@pytest.fixture(scope="module")
def table_data(tmp_path_factory):
    """Fixture JAAD and PIE folders imported at 30 frames, and a CARLA-BSP dataset."""
    from bsp_testdata import recording, write_dataset
    from test_interop_jaad_pie import _jaad, _pie

    from bsp_fast.interop.cli import main as interop

    root = tmp_path_factory.mktemp("mixtable")
    jaad, pie = _jaad(root / "JAAD"), _pie(root / "PIE")
    assert interop(["import", "jaad", str(jaad), str(root / "jaad.h5"), "--openpose",
                    str(jaad / "openpose"), "--obs-length", "30", "--quiet"]) == 0
    assert interop(["import", "pie", str(pie), str(root / "pie.h5"), "--poses",
                    str(pie / "poses"), "--obs-length", "30", "--quiet"]) == 0
    rows = [r for i in range(10)  # both classes in every recording: no one-class split
            for r in recording(f"rec{i:02d}", range(96), seed=i, crossing_from=48)]
    write_dataset(root / "carla-bsp", rows)
    return root


def _command() -> str:
    page = (REPO / "docs" / "interop.md").read_text()
    part = page.split("### The report's mixed-training table", 1)[1]
    return re.search(r"^bsp-reproduce mixed .*$", part, re.M).group(0)


def test_the_documented_table_command_runs_on_fixtures(table_data, monkeypatch, capsys):
    from bsp_fast.reproduction import main as reproduce

    monkeypatch.chdir(table_data)
    argv = shlex.split(_command())
    assert argv[:2] == ["bsp-reproduce", "mixed"] and "smoke" in argv
    # without PIE's file: stopped before anything trains, naming the source and the option
    at = next(i for i, a in enumerate(argv) if a.startswith("pie="))
    short = argv[1:at - 1] + argv[at + 1:]
    assert reproduce(short) == 2
    err = capsys.readouterr().err
    assert "give --mix-data pie=FILE" in err
    assert not list(Path("runs").glob("mixed-smoke/*/metrics.json"))
    assert reproduce(argv[1:]) == 0
    text = capsys.readouterr().out
    base = Path("runs") / "mixed-smoke"
    res = json.loads((base / "results.json").read_text())
    assert "smoke budget: plumbing only" in text
    test_video = {"jaad": "video_0003", "pie": "set03/video_0001"}  # the fixtures' test splits
    for row in ("jaad-on-jaad", "carla-on-jaad", "jaad-carla-on-jaad", "jaad-on-pie",
                "carla-on-pie", "jaad-carla-on-pie"):
        assert f"| {row} |" in text
        r = res["results"][row]
        assert r["metrics"]["pck_0.05"] is not None
        per = json.loads((base / row / f"seed-{SEED}" / "test_per_recording.json").read_text())
        videos = {rec.rsplit("/", 1)[0] for rec in per["test"]["recordings"]}
        assert videos == {test_video[row.rsplit("-on-", 1)[1]]}, (row, videos)
    # one mix, two test sets: the same weights (same seed, val on the mix), other numbers
    a, b = (torch.load(base / r / f"seed-{SEED}" / "checkpoints" / "best.ckpt",
                       weights_only=True)["state_dict"] for r in ("jaad-on-jaad", "jaad-on-pie"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    ma, mb = (res["results"][r]["metrics"]["pck_0.05"] for r in ("jaad-on-jaad", "jaad-on-pie"))
    assert ma != mb
    cfg = C.read_yaml(base / "jaad-carla-on-pie" / f"seed-{SEED}" / "config.yaml")
    assert cfg["test_on"] == "pie" and cfg["mix"]["sources"][1] == {
        "name": "carla_bsp", "share": 0.8, "data": True}
