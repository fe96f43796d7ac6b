"""bsp-synth --poses-only: the full mode's data.csv, byte for byte, without media files."""
from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

from bsp_fast.csvio import read_csv
from bsp_fast.synth import generate
from bsp_fast.synth.cli import main as cli_main
from bsp_fast.synth.config import make_config

# Small images: a distant pedestrian then covers no pixel centre in some annotated frames,
# so in_segmentation holds both values and the test shows it is computed, not assumed.
OPTS = dict(clips=3, frames=60, size="160x96", seed=0, progress=False)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    root = tmp_path_factory.mktemp("po")
    full = generate(root / "full", "sample", workers=1, **OPTS)
    # Two worker processes (one C++ thread each) against the one-process full run.
    poses = generate(root / "poses", "sample", workers=2, poses_only=True, **OPTS)
    return root, full, poses


def test_data_csv_is_byte_identical_to_the_full_mode(pair):
    root, full, poses = pair
    a = (root / "full" / "data.csv").read_bytes()
    b = (root / "poses" / "data.csv").read_bytes()
    assert len(a) > 10_000 and a == b
    seg = read_csv(root / "poses" / "data.csv")["frame.pedestrian.pose.in_segmentation"]
    assert seg.any() and not seg.all()


def test_no_media_written_but_paths_recorded(pair):
    root, full, poses = pair
    assert sorted(os.listdir(root / "poses")) == ["config.yaml", "data.csv"]
    assert len(os.listdir(root / "full" / "clips")) == 2 * OPTS["clips"]
    t = read_csv(root / "poses" / "data.csv")
    assert sorted(set(t["camera.recording"])) == sorted(f"clips/{i}-0.mp4" for i in poses["ids"])
    assert sorted(set(t["camera.semantic_segmentation"])) == sorted(
        f"clips/{i}-1.apng" for i in poses["ids"])
    for rel in set(t["camera.recording"]):
        assert (root / "full" / rel).is_file() and not (root / "poses" / rel).exists()


def test_config_yaml_records_poses_only(pair):
    root, _, _ = pair
    a = yaml.safe_load((root / "full" / "config.yaml").read_text())
    b = yaml.safe_load((root / "poses" / "config.yaml").read_text())
    assert a.pop("poses_only") is False and b.pop("poses_only") is True
    assert a == b  # every other parameter the same


def test_summary_matches_the_full_mode(pair):
    _, full, poses = pair
    assert full["poses_only"] is False and poses["poses_only"] is True
    drop = ("seconds", "clips_per_second", "poses_only", "out_dir")
    assert {k: v for k, v in full.items() if k not in drop} == \
        {k: v for k, v in poses.items() if k not in drop}


# Three short recordings: the converter rightly warns about its small splits.
@pytest.mark.filterwarnings("ignore:bsp_fast.convert:UserWarning")
def test_converts_without_media_into_pose_datasets(pair, tmp_path):
    import bsp_fast as bf
    from bsp_fast.data import ClipDataset

    root, _, poses = pair
    report = bf.convert(root / "poses", tmp_path / "c.h5", clip_length=8, media=False)
    ref = bf.convert(root / "full", tmp_path / "f.h5", clip_length=8, media=False)
    assert report["splits"] == ref["splits"]
    n = report["splits"]["train"]["clips"]
    assert n > 0
    ds = ClipDataset(tmp_path / "c.h5", "train", "lifting")
    assert len(ds) == n
    batch = next(iter(ds.loader(batch_size=4)))
    assert batch["inputs"].shape[1:] == (8, 26, 2) and batch["targets_m"].shape[1:] == (8, 26, 3)
    assert np.isfinite(batch["targets_m"].numpy()).all()
    cls = ClipDataset(tmp_path / "c.h5", "train", "classification")
    labels = np.concatenate([b["label"].numpy() for b in cls.loader(batch_size=64)])
    assert np.bincount(labels, minlength=2).tolist() == [
        report["splits"]["train"]["not-crossing"], report["splits"]["train"]["crossing"]]
    # Without media= the dataset's config.yaml (poses_only: true) says there is none;
    # asking for it names the file and the way out.
    auto = bf.convert(root / "poses", tmp_path / "a.h5", clip_length=8)
    assert auto["splits"] == report["splits"] and auto["settings"]["media"] is False
    assert auto["media"]["why_none"] == "the dataset's config.yaml says poses_only: true"
    with pytest.raises(ValueError, match=r"config\.yaml says poses_only: true.*--no-media"):
        bf.convert(root / "poses", tmp_path / "m.h5", clip_length=8, media=True)


def test_cli_option_and_checks(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli_main([str(out), "--clips", "1", "--frames", "10", "--size", "64x48",
                     "--poses-only"]) == 0
    assert "poses only" in capsys.readouterr().out
    assert sorted(os.listdir(out)) == ["config.yaml", "data.csv"]
    assert yaml.safe_load((out / "config.yaml").read_text())["poses_only"] is True
    with pytest.raises(SystemExit):
        cli_main(["--help"])
    assert "--poses-only" in capsys.readouterr().out
    with pytest.raises(ValueError, match="poses_only"):
        generate(tmp_path / "x", poses_only="yes")
    with pytest.raises(ValueError, match="poses_only"):
        make_config("sample", dict(poses_only=1))
    cfg = tmp_path / "c.yaml"
    cfg.write_text("poses_only: true\nnumber_of_clips: 1\nclip_length_in_frames: 5\n"
                   "camera_image_size: [64, 48]\n")
    s = generate(tmp_path / "y", config=cfg, workers=1, progress=False)
    assert s["poses_only"] and not (tmp_path / "y" / "clips").exists()


def test_sample_preset_gives_both_classes_in_every_split(tmp_path):
    """`make demo` converts the sample preset with default options (and --strict): every
    split must hold crossing and non-crossing clips. Poses-only writes the same data.csv,
    and the clip counts do not depend on media."""
    import bsp_fast as bf

    generate(tmp_path / "s", "sample", workers=1, poses_only=True, progress=False)
    rep = bf.convert(tmp_path / "s", tmp_path / "s.h5", media=False)
    counts = {k: (rep["splits"][k]["not-crossing"], rep["splits"][k]["crossing"])
              for k in ("train", "val", "test")}
    assert all(n > 0 and c > 0 for n, c in counts.values()), counts


def test_cli_knows_every_preset(tmp_path, capsys):
    from bsp_fast.synth.config import PRESETS

    with pytest.raises(SystemExit):
        cli_main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in PRESETS:
        assert f"{name}: {PRESETS[name]['number_of_clips']} clips" in text
    # --preset medium with its size overridden: a tiny run through the CLI.
    assert cli_main([str(tmp_path / "m"), "--preset", "medium", "--clips", "1", "--frames",
                     "5", "--size", "64x48", "--poses-only", "--quiet"]) == 0
    assert yaml.safe_load((tmp_path / "m" / "config.yaml").read_text())["preset"] == "medium"
