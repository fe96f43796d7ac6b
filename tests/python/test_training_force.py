"""--force never destroys what bsp-train did not write (issue 24, "Data loss"): the dataset
being trained on, the HDF5 file, any folder that is not a run directory, and bsp-predict's
own checkpoint and input are refused with exit 2 before any work, and nothing is touched;
two runs publishing the same --out do not replace each other."""
import os
from pathlib import Path

import pytest

pytest.importorskip("lightning")

import bsp_fast  # noqa: E402
from bsp_fast.data.testing import write_clip_file  # noqa: E402
from bsp_fast.training.predict import main as predict_main  # noqa: E402
from bsp_fast.training.runs import RunDirectory, RunError, is_run_directory  # noqa: E402
from bsp_fast.training.train import main as train_main  # noqa: E402

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]
TINY = ["--hp", "hidden_size=8", "--hp", "num_layers=1", "--epochs", "1", "--batch-size",
        "8", "--threads", "1", "--quiet"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("force")
    write_clip_file(root / "clips.h5", clips=(24, 8, 8), clip_length=8, seed=3)
    ds = root / "ds"
    ds.mkdir()
    (ds / "data.csv").write_text("frame.idx\n1\n")  # a dataset the run must not delete
    (ds / "config.yaml").write_text("generator: bsp-synth\nseed: 1\n")
    run = root / "run"
    assert train_main(["classification", "lstm", "--data", str(root / "clips.h5"),
                       "--out", str(run)] + TINY) == 0
    return root


def _snapshot(path: Path) -> dict:
    if path.is_file():
        return {path.name: path.read_bytes()}
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("target", ["dataset", "dataset-data.csv", "h5", "plain-folder",
                                    "parent-of-h5"])
def test_force_refuses_what_bsp_train_did_not_write(data, target, tmp_path, capsys):
    h5 = data / "clips.h5"
    plain = tmp_path / "notes"
    plain.mkdir()
    (plain / "thesis.tex").write_text("months of work")
    out, train_on = {"dataset": (data / "ds", data / "ds"),
                     "dataset-data.csv": (data / "ds", data / "ds" / "data.csv"),
                     "h5": (h5, h5),
                     "plain-folder": (plain, h5),
                     "parent-of-h5": (data, h5)}[target]
    before = _snapshot(out if target != "parent-of-h5" else h5)
    rc = train_main(["classification", "lstm", "--data", str(train_on), "--out", str(out),
                     "--force"] + TINY)
    assert rc == 2
    err = capsys.readouterr().err
    assert str(out) in err and ("input" in err or "did not write" in err), err
    assert _snapshot(out if target != "parent-of-h5" else h5) == before


def test_force_replaces_an_earlier_run_directory(data, tmp_path):
    run = tmp_path / "r"
    args = ["classification", "lstm", "--data", str(data / "clips.h5"), "--out", str(run)]
    assert train_main(args + TINY) == 0 and is_run_directory(run)
    assert train_main(args + TINY) == 3  # exists, no --force
    assert train_main(args + TINY + ["--force"]) == 0 and is_run_directory(run)


def test_symlink_to_the_dataset_is_refused(data, tmp_path):
    link = tmp_path / "link"
    link.symlink_to(data / "ds")
    assert train_main(["classification", "lstm", "--data", str(data / "clips.h5"), "--out",
                       str(link), "--force"] + TINY) == 2
    assert (data / "ds" / "data.csv").is_file()


def test_second_run_publishing_the_same_out_is_refused(tmp_path):
    final = tmp_path / "run"
    rd = RunDirectory(final, force=False)
    with pytest.raises(RunError) as e:
        with rd as tmp:
            (tmp / "metrics.json").write_text("{}")
            final.mkdir()  # another run finished first
            (final / "metrics.json").write_text('{"first": 1}')
    assert e.value.code == 3 and "appeared" in str(e.value)
    assert (final / "metrics.json").read_text() == '{"first": 1}'


def test_predict_refuses_its_checkpoint_its_input_and_folders(data, capsys):
    run, h5 = data / "run", data / "clips.h5"
    ckpt = run / "checkpoints" / "best.ckpt"
    keep = {p: p.read_bytes() for p in (ckpt, h5)}
    for out in (ckpt, h5):
        assert predict_main([str(run), "--out", str(out), "--force", "--quiet"]) == 2
        assert "input" in capsys.readouterr().err
    assert predict_main([str(run), "--out", str(run), "--force", "--quiet"]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in keep} == keep
    assert os.path.isdir(run / "checkpoints")
