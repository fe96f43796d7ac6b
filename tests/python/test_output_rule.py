"""One output rule for every command (issue 34): no command writes onto one of its own
inputs, with or without --force (real paths: symlinks and hard links too), nor two of its
outputs onto one file. The refusal comes before any work, as one line ``PROG: error: ...``
on stderr with exit code 2, and the input is byte-identical afterwards
(bsp_fast.atomic.check_outputs)."""
import hashlib
import io
import json
import os
from pathlib import Path

import pytest

from bsp_fast.atomic import (DATASET_FILES, OVERLAP_EXIT, OutputOverlapError, check_outputs,
                             refuse)

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]


def _snapshot(*paths) -> dict:
    """sha256 of every file at or below ``paths`` (a missing path maps to None)."""
    out = {}
    for p in map(Path, paths):
        files = [p] if p.is_file() else sorted(q for q in p.rglob("*") if q.is_file()) \
            if p.is_dir() else []
        if not p.exists():
            out[str(p)] = None
        for q in files:
            out[str(q)] = hashlib.sha256(q.read_bytes()).hexdigest()
    return out


def _refused(capsys, rc, prog, *names):
    """Exit 2 and one line ``prog: error: ...`` on stderr naming every path in ``names``."""
    err = capsys.readouterr().err
    assert rc == OVERLAP_EXIT, err
    lines = err.strip("\n").splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"{prog}: error: "), err
    for n in names:
        assert str(n) in lines[0], (n, err)
    return lines[0]


# ---------------------------------------------------------------- the helper


def test_helper_refuses_links_equal_outputs_and_folders_holding_inputs(tmp_path):
    inp = tmp_path / "in.json"
    inp.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(inp)
    hard = tmp_path / "hard.json"
    os.link(inp, hard)
    for out in (inp, link, hard, tmp_path / "sub" / ".." / "in.json"):
        with pytest.raises(OutputOverlapError, match=r"is the input .*in\.json"):
            check_outputs(inputs=[inp], outputs=[out])
    with pytest.raises(OutputOverlapError, match=f"{tmp_path} holds the input"):
        check_outputs(inputs=[inp], outputs=[tmp_path])  # replacing the folder deletes it
    a, b = tmp_path / "a.npz", tmp_path / "x" / ".." / "a.npz"
    with pytest.raises(OutputOverlapError, match="are the same file") as e:
        check_outputs(inputs=[inp], outputs=[("output", a), ("--out-3d", b)])
    assert str(a) in str(e.value) and str(b) in str(e.value) and "\n" not in str(e.value)
    assert isinstance(e.value, ValueError)
    # a folder the command reads: its matching files are inputs, other names are free
    ds = tmp_path / "ds"
    (ds / "clips").mkdir(parents=True)
    with pytest.raises(OutputOverlapError, match=r"would replace the dataset.s \.MP4 file"):
        check_outputs(outputs=[ds / "clips" / "new.MP4"],
                      read_dirs=[("the dataset", ds, DATASET_FILES)])
    check_outputs(outputs=[ds / "clips.h5"], read_dirs=[("the dataset", ds, DATASET_FILES)])
    with pytest.raises(OutputOverlapError, match="is inside the dataset"):
        check_outputs(outputs=[ds / "copy"], read_dirs=[("the dataset", ds, None)])
    # distinct paths (and None) pass
    check_outputs(inputs=[inp, None], outputs=[tmp_path / "o.json", None, tmp_path / "p.json"])


def test_refuse_prints_one_line_and_returns_2():
    buf = io.StringIO()
    assert refuse("bsp-x", OutputOverlapError("output a\nb is the input c"), file=buf) == 2
    assert buf.getvalue() == "bsp-x: error: output a b is the input c\n"


# ---------------------------------------------------------------- bsp-interop


@pytest.fixture(scope="module")
def clips_h5(tmp_path_factory):
    pytest.importorskip("h5py")
    from bsp_fast.data.testing import write_clip_file

    path = tmp_path_factory.mktemp("rule") / "clips.h5"
    write_clip_file(path, clips=(8, 4, 4), clip_length=4, seed=1)
    return path


def _coco_files(tmp_path):
    res = tmp_path / "r.json"
    res.write_text(json.dumps([{"image_id": 1, "category_id": 1, "score": 1.0,
                                "keypoints": [0.0] * 51, "track_id": 1}]))
    images = tmp_path / "images.json"
    images.write_text(json.dumps({"images": [{"id": 1, "video": "v", "frame": 0,
                                              "width": 64, "height": 64}]}))
    return res, images


@pytest.mark.parametrize("case", ["export-coco", "export-videopose3d", "import-coco",
                                  "import-coco-images", "import-coco-labels",
                                  "import-openpose"])
def test_interop_never_writes_onto_its_input(case, clips_h5, tmp_path, capsys):
    from bsp_fast.interop.cli import main

    res, images = _coco_files(tmp_path)
    op = tmp_path / "op"
    op.mkdir()
    kp = op / "x_000000000000_keypoints.json"
    kp.write_text(json.dumps({"version": 1.3, "people": []}))
    labels = tmp_path / "labels.csv"
    labels.write_text("video,track,frame,crossing\n")
    argv, victim = {
        "export-coco": (["export", "coco", str(clips_h5), str(clips_h5)], clips_h5),
        "export-videopose3d": (["export", "videopose3d", str(clips_h5), str(clips_h5)],
                               clips_h5),
        "import-coco": (["import", "coco", str(res), str(res)], res),
        "import-coco-images": (["import", "coco", str(res), str(images), "--images",
                                str(images)], images),
        "import-coco-labels": (["import", "coco", str(res), str(labels), "--images",
                                str(images), "--labels", str(labels)], labels),
        "import-openpose": (["import", "openpose", str(op), str(kp), "--image-size",
                             "64x64"], kp),
    }[case]
    before = _snapshot(victim, op, tmp_path)
    _refused(capsys, main(argv + ["--force"]), "bsp-interop", victim)
    assert _snapshot(victim, op, tmp_path) == before


def test_interop_openpose_output_below_the_folder_it_reads(tmp_path, capsys):
    from bsp_fast.interop.cli import main

    op = tmp_path / "op"
    (op / "sub").mkdir(parents=True)
    new = op / "sub" / "later_keypoints.json"  # would be read by the next import
    _refused(capsys, main(["import", "openpose", str(op), str(new), "--image-size", "64x64",
                           "--force"]), "bsp-interop", new)
    assert not new.exists()
    _refused(capsys, main(["import", "openpose", str(op), str(op), "--image-size", "64x64",
                           "--force"]), "bsp-interop", op)
    assert (op / "sub").is_dir()


@pytest.mark.parametrize("case", ["videopose3d", "coco-results"])
def test_interop_two_outputs_that_are_one_file(case, clips_h5, tmp_path, capsys):
    from bsp_fast.interop.cli import main

    out = tmp_path / "out.json"
    out.write_text("earlier output")
    if case == "videopose3d":
        argv = ["export", "videopose3d", str(clips_h5), str(out), "--out-3d",
                str(tmp_path / "x" / ".." / "out.json")]
    else:
        argv = ["export", "coco", str(clips_h5), str(out), "--results", "--images", str(out)]
    before = _snapshot(tmp_path, clips_h5)
    line = _refused(capsys, main(argv + ["--force"]), "bsp-interop", out)
    assert "same file" in line
    assert _snapshot(tmp_path, clips_h5) == before


# ---------------------------------------------------------------- bsp-convert


def test_convert_uses_the_shared_rule(tmp_path, capsys):
    from bsp_fast.conversion.cli import main

    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "data.csv").write_text("not even a header\n")
    link = tmp_path / "out.h5"
    link.symlink_to(ds / "data.csv")
    before = _snapshot(ds)
    line = _refused(capsys, main(["--no-media", "--quiet", str(ds), str(link), "--force"]),
                    "bsp-convert", link)
    assert "is the dataset's input" in line
    assert _snapshot(ds) == before


# ---------------------------------------------------------------- bsp-check


@pytest.fixture
def dataset(tmp_path):
    ds = tmp_path / "ds"
    (ds / "clips").mkdir(parents=True)
    (ds / "data.csv").write_text("a,b\n1,2\n")
    (ds / "config.yaml").write_text("seed: 1\n")
    (ds / "clips" / "r-0.mp4").write_bytes(b"not really a video")
    return ds


@pytest.mark.parametrize("case", ["fix-is-dataset", "fix-inside", "fix-holds", "json-csv",
                                  "json-media", "json-is-fix"])
def test_check_never_writes_onto_the_dataset(case, dataset, tmp_path, capsys):
    from bsp_fast.check.cli import main

    other = tmp_path / "report"
    argv, named = {
        "fix-is-dataset": (["--fix", str(dataset)], dataset),
        "fix-inside": (["--fix", str(dataset / "clean")], dataset / "clean"),
        "fix-holds": (["--fix", str(tmp_path)], tmp_path),
        "json-csv": (["--json", str(dataset / "data.csv")], dataset / "data.csv"),
        "json-media": (["--json", str(dataset / "clips" / "r-0.mp4")],
                       dataset / "clips" / "r-0.mp4"),
        "json-is-fix": (["--fix", str(other), "--json", str(other)], other),
    }[case]
    before = _snapshot(tmp_path)
    force = ["--force"] if "--fix" in argv else []
    _refused(capsys, main([str(dataset), "--quiet", *argv, *force]), "bsp-check", named)
    assert _snapshot(tmp_path) == before


# ---------------------------------------------------------------- bsp-synth


def test_synth_out_dir_never_holds_its_config_or_motion(tmp_path, capsys):
    from bsp_fast.synth.cli import main

    out = tmp_path / "out"
    out.mkdir()
    cfg = out / "cfg.yaml"
    cfg.write_text("number_of_clips: 1\n")
    motion = out / "walk.bvh"
    motion.write_text("HIERARCHY\n")
    before = _snapshot(tmp_path)
    _refused(capsys, main([str(out), "--config", str(cfg), "--force", "--quiet"]),
             "bsp-synth", out, cfg)
    _refused(capsys, main([str(out), "--motion", str(motion), "--force", "--quiet"]),
             "bsp-synth", out, motion)
    _refused(capsys, main([str(motion), "--motion", str(motion), "--force", "--quiet"]),
             "bsp-synth", motion)
    assert _snapshot(tmp_path) == before


# ---------------------------------------------------------------- bsp-preview


def test_preview_never_writes_onto_its_input(dataset, clips_h5, tmp_path, capsys):
    from bsp_fast.preview.cli import main

    video = dataset / "clips" / "r-0.mp4"
    before = _snapshot(dataset, clips_h5)
    _refused(capsys, main(["frames", str(dataset), "--recording", "r", "--out", str(video),
                           "--force"]), "bsp-preview", video)
    link = tmp_path / "view.png"
    link.symlink_to(clips_h5)
    _refused(capsys, main(["pose3d", str(clips_h5), "--clip", "0", "--out", str(link),
                           "--force"]), "bsp-preview", link, clips_h5)
    _refused(capsys, main(["clips", str(clips_h5), "--out", str(link), "--force"]),
             "bsp-preview", link)
    _refused(capsys, main(["predictions", str(tmp_path / "p.h5"), "--clips-h5", str(clips_h5),
                           "--out", str(link), "--force"]), "bsp-preview", link)
    assert _snapshot(dataset, clips_h5) == before and link.is_symlink()


# ---------------------------------------------------------------- training commands


@pytest.fixture
def fake_run(tmp_path, clips_h5):
    """A run directory as bsp-eval and bsp-predict resolve it (checkpoint, config.yaml
    naming its data): the output rule is checked before anything is loaded."""
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "best.ckpt").write_bytes(b"weights")
    (run / "config.yaml").write_text(f"task: classification\nmodel: lstm\nresolved:\n"
                                     f"  data: {clips_h5}\n  h5: {clips_h5}\n")
    return run


def test_predict_never_writes_onto_its_inputs(fake_run, clips_h5, dataset, capsys):
    pytest.importorskip("lightning")
    from bsp_fast.training.predict import main

    ckpt = fake_run / "checkpoints" / "best.ckpt"
    before = _snapshot(fake_run, clips_h5, dataset)
    for out in (ckpt, fake_run / "config.yaml", clips_h5):
        _refused(capsys, main([str(fake_run), "--out", str(out), "--force", "--quiet"]),
                 "bsp-predict", out)
    _refused(capsys, main([str(ckpt), "--out", str(dataset / "data.csv"), "--data",
                           str(dataset), "--force", "--quiet"]), "bsp-predict",
             dataset / "data.csv")
    assert _snapshot(fake_run, clips_h5, dataset) == before


def test_eval_json_never_lands_on_its_inputs(fake_run, clips_h5, capsys):
    pytest.importorskip("lightning")
    from bsp_fast.training.evaluate import main

    ckpt = fake_run / "checkpoints" / "best.ckpt"
    before = _snapshot(fake_run, clips_h5)
    for out in (ckpt, clips_h5, fake_run):
        _refused(capsys, main([str(fake_run), "--json", str(out), "--quiet"]), "bsp-eval",
                 out)
    save = fake_run / "test_breakdown.json"
    line = _refused(capsys, main([str(fake_run), "--breakdown", "--save", "--json", str(save),
                                  "--quiet"]), "bsp-eval", save)
    assert "same file" in line
    assert _snapshot(fake_run, clips_h5) == before


def test_train_out_never_is_or_holds_its_inputs(clips_h5, tmp_path, capsys):
    pytest.importorskip("lightning")
    pytest.importorskip("jsonargparse")
    from bsp_fast.training.train import main

    tiny = ["--epochs", "1", "--batch-size", "8", "--threads", "1", "--quiet"]
    before = _snapshot(clips_h5)
    _refused(capsys, main(["classification", "lstm", "--data", str(clips_h5), "--out",
                           str(clips_h5), "--force"] + tiny), "bsp-train", clips_h5)
    assert _snapshot(clips_h5) == before
    cfg = tmp_path / "cfgdir" / "cfg.yaml"
    cfg.parent.mkdir()
    cfg.write_text(f"task: classification\nmodel: lstm\ndata: {clips_h5}\n")
    before = _snapshot(cfg)
    _refused(capsys, main(["--config", str(cfg), "--out", str(cfg.parent), "--force"] + tiny),
             "bsp-train", cfg.parent, cfg)
    assert _snapshot(cfg) == before
