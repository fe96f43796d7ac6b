"""bsp-interop import jaad on real JAAD annotations (tests/python/data/jaad_subset: nine
videos, MIT, README there) against the windows the official code computes: every window
the same frames, label, TTE and annotated box, for beh and all; the options that depart
from it (--cut-gaps, --drop-first-frame) and what the official code refuses.

Opt-in, the whole dataset side by side with the official code: BSP_JAAD_ROOT (a checkout
of github.com/ykotseruba/JAAD) and BSP_PAB_ROOT (github.com/ykotseruba/
PedestrianActionBenchmark)."""
import importlib.util
import json
import lzma
import os
import pickle
import shutil
import tarfile
from pathlib import Path

import h5py
import numpy as np
import pytest

from bsp_fast.interop.cli import main

DATA = Path(__file__).parent / "data" / "jaad_subset"
ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("jaad_official_windows",
                                               ROOT / "tools" / "jaad_official_windows.py")
official = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(official)
GAPS = {"0_98_544", "0_149_956b", "0_149_958b", "0_298_2319b"}


@pytest.fixture(scope="module")
def jaad(tmp_path_factory):
    """The subset unpacked, with a pose pickle in the benchmark's format."""
    root = tmp_path_factory.mktemp("jaad")
    with tarfile.open(DATA / "jaad_subset.tar.xz") as tar:
        tar.extractall(root, filter="data")
    official.synthetic_poses(root, root / "pose_set01.pkl")
    return root


@pytest.fixture(scope="module")
def expected():
    return json.loads(lzma.decompress((DATA / "expected_windows.json.xz").read_bytes()))


def _import(jaad, out, *extra):
    return main(["import", "jaad", str(jaad), str(out), "--poses",
                 str(jaad / "pose_set01.pkl"), "--quiet", *extra])


@pytest.mark.parametrize("subset", ["beh", "all"])
def test_windows_equal_the_official_code(jaad, expected, tmp_path, subset):
    out = tmp_path / "clips.h5"
    assert _import(jaad, out, "--subset", subset) == 0
    ours = official.clip_windows(out)
    assert official.compare(expected[subset], ours) == []
    for split in official.SPLITS:  # the same order too
        assert [(w["video"], w["pid"], w["frames"]) for w in ours[split]] == \
            [(w["video"], w["pid"], w["frames"]) for w in expected[subset][split]]
    with h5py.File(out, "r") as f:
        tte = np.concatenate([f[s]["meta/tte"][()] for s in official.SPLITS])
        fte = np.concatenate([f[s]["meta/frames_to_event"][()] for s in official.SPLITS])
        pids = np.concatenate([f[s]["meta/pedestrian_id"].asstr()[()] for s in official.SPLITS])
        assert tte.min() == 30 and tte.max() == 60
        differ = set(pids[fte != tte])  # only where a track has a gap before its event
        assert differ and differ <= GAPS and (fte >= tte).all()
        settings = json.loads(f.attrs["settings_json"])
        assert f.attrs["benchmark"] == 1 and settings["benchmark"] is True
        assert f.attrs["label_rule"] == "video" and settings["label"] == "video"
        assert f.attrs["clip_length"] == settings["clip_length"] == 16
        assert settings["windows_across_gaps"] is True and f.attrs["windows_across_gaps"] == 1


def test_gap_windows_as_the_official_code_and_cut_gaps(jaad, expected, tmp_path, capsys):
    out = tmp_path / "all.h5"
    assert main(["import", "jaad", str(jaad), str(out), "--poses",
                 str(jaad / "pose_set01.pkl"), "--subset", "all"]) == 0
    text = capsys.readouterr().out
    assert "windows across a gap in the frame numbers: 2 (video_0098/0_98_544)" in text
    ours = official.clip_windows(out)["train"]
    gap = [w["frames"] for w in ours if w["pid"] == "0_98_544"]
    assert [list(range(56, 69)) + [202, 203, 204], list(range(59, 69)) + [202, 203, 204, 205,
                                                                            206, 207]] \
        == [g for g in gap if g[-1] > 200]
    cut = tmp_path / "cut.h5"
    assert _import(jaad, cut, "--subset", "all", "--cut-gaps") == 0
    kept = [w for w in expected["all"]["train"] if w["frames"][-1] - w["frames"][0] == 15]
    assert official.compare(dict(train=kept, val=expected["all"]["val"],
                                 test=expected["all"]["test"]),
                            official.clip_windows(cut)) == []


def test_drop_first_frame_is_what_the_models_see(jaad, expected, tmp_path):
    out = tmp_path / "15.h5"
    assert _import(jaad, out, "--drop-first-frame") == 0
    with h5py.File(out, "r") as f:
        assert f.attrs["clip_length"] == 15 and f.attrs["first_frame_dropped"] == 1
        for s in official.SPLITS:
            g, exp = f[s], expected["beh"][s]
            assert g["projection_2d"].shape[1] == 15
            assert g["targets/frame_idx"][()].tolist() == [w["frames"][1:] for w in exp]
            assert g["meta/tte"][()].tolist() == [w["tte"] for w in exp]
            # get_data_sequence's normalised box input: box[1:] - box[0]
            ann = g["targets/annotated_bboxes"][()].reshape(len(exp), 15, 4)
            ref = g["targets/box_reference"][()].reshape(len(exp), 1, 4)
            want = [np.subtract(w["boxes"][1:], w["boxes"][0]) for w in exp]
            np.testing.assert_allclose(ann - ref, want, atol=1e-3)


def _copy(jaad, tmp_path) -> Path:
    root = tmp_path / "copy"
    shutil.copytree(jaad, root, ignore=shutil.ignore_patterns("*.pkl"))
    return root


def _fails(capsys, argv, code, *needles):
    assert main(argv) == code
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    for n in needles:
        assert n in err, err
    return err


def test_refused_like_the_official_code(jaad, tmp_path, capsys):
    root = _copy(jaad, tmp_path)
    xml = root / "annotations" / "video_0098.xml"
    text = xml.read_text()
    xml.write_text(text.replace('<attribute name="occlusion">none</attribute>',
                                '<attribute name="occlusion">half</attribute>', 1))
    out = tmp_path / "o.h5"
    argv = ["import", "jaad", str(root), str(out), "--poses", str(jaad / "pose_set01.pkl")]
    _fails(capsys, argv, 1, "video_0098.xml: track[0] (pedestrian '0_98_545b') frame 0",
           "occlusion: 'half', not one of none, part, full", "jaad_data.py")
    xml.write_text(text.replace('<attribute name="cross">not-crossing</attribute>',
                                '<attribute name="cross">maybe</attribute>', 1))
    _fails(capsys, argv, 1, "cross: 'maybe'")
    xml.write_text(text)
    attrs = root / "annotations_attributes" / "video_0098_attributes.xml"
    attrs.write_text(attrs.read_text().replace('crossing_point="54"', 'crossing_point="999"'))
    _fails(capsys, argv, 1, "pedestrian '0_98_544b': crossing_point 999 is not one of its "
           "annotated frames")
    assert not out.exists()


def test_existing_output_refused_before_reading(jaad, tmp_path, capsys):
    root = _copy(jaad, tmp_path)
    (root / "annotations" / "video_0098.xml").write_text("<annotations><broken")
    out = tmp_path / "o.h5"
    out.write_bytes(b"old")
    _fails(capsys, ["import", "jaad", str(root), str(out), "--poses",
                    str(jaad / "pose_set01.pkl")], 3, "exists; pass --force")
    assert out.read_bytes() == b"old"


def _pickle(jaad, tmp_path, edit) -> Path:
    doc = pickle.loads((jaad / "pose_set01.pkl").read_bytes())
    edit(doc)
    path = tmp_path / "pose_set01.pkl"
    path.write_bytes(pickle.dumps(doc))
    return path


def test_pickle_units_per_video_and_all_zero_poses(jaad, tmp_path, capsys):
    size = np.array([1920.0, 1080.0] * 18)

    def edit(doc):
        for key in list(doc["video_0149"])[:3]:  # a few values over 1
            doc["video_0149"][key] = np.where(np.arange(36) == 0, 1.2, doc["video_0149"][key])
        doc["video_0098"] = {k: v * size for k, v in doc["video_0098"].items()}  # pixels
        doc["video_0325"] = {k: np.zeros(36) for k in doc["video_0325"]}
    pkl = _pickle(jaad, tmp_path, edit)
    out = tmp_path / "u.h5"
    assert main(["import", "jaad", str(jaad), str(out), "--poses", str(pkl), "--subset",
                 "all"]) == 0
    text = capsys.readouterr().out
    assert "video 'video_0149': read as normalised coordinates;" in text
    assert "lie outside the image" in text and "video_0098': read as" not in text
    assert "poses with every value 0: " in text and "every joint missing" in text
    ref = tmp_path / "ref.h5"
    assert _import(jaad, ref, "--subset", "all") == 0
    with h5py.File(out, "r") as f, h5py.File(ref, "r") as g:
        t, r = f["train"], g["train"]
        video = t["meta/video_id"].asstr()[()]
        px = video == "video_0098"  # pixels read as pixels: the same joints
        np.testing.assert_allclose(t["projection_2d"][px], r["projection_2d"][px], atol=0.05)
        assert not t["visible"][video == "video_0325"].any()  # zeros: missing joints
        assert t["visible"][video == "video_0149"].any()


@pytest.mark.skipif(not (os.environ.get("BSP_JAAD_ROOT") and os.environ.get("BSP_PAB_ROOT")),
                    reason="opt-in: BSP_JAAD_ROOT and BSP_PAB_ROOT (the official code)")
@pytest.mark.parametrize("subset", ["beh", "all"])
def test_full_jaad_against_the_official_code(tmp_path, subset):
    root, pab = Path(os.environ["BSP_JAAD_ROOT"]), Path(os.environ["BSP_PAB_ROOT"])
    want = official.official_windows(root, root / "jaad_data.py", pab / "action_predict.py",
                                     subset)
    official.synthetic_poses(root, tmp_path / "pose_set01.pkl")
    out = tmp_path / "clips.h5"
    assert main(["import", "jaad", str(root), str(out), "--poses",
                 str(tmp_path / "pose_set01.pkl"), "--subset", subset, "--quiet"]) == 0
    assert official.compare(want, official.clip_windows(out)) == []
