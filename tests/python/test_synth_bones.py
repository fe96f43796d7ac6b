"""bsp-synth --bone-length-variation: each walker's bones scaled by its own seeded factor,
data.csv still self-consistent, nothing else drawn differently."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from bsp_fast import skeleton as sk
from bsp_fast.csvio import read_csv
from bsp_fast.synth import generate
from bsp_fast.synth.cli import main as cli_main

OPTS = dict(clips=4, frames=40, size="320x120", seed=3, progress=False, workers=1,
            poses_only=True)
PARENTS = np.array(sk.PARENTS)


def _bone_ratios(root):
    """Per recording: component-space bone lengths / the reference skeleton's."""
    t = read_csv(root / "data.csv")
    comp = np.asarray(t["frame.pedestrian.pose.component"], float).reshape(-1, 26, 6)[..., :3]
    ref = {}
    out = {}
    for rec in sorted(set(t["camera.recording"])):
        rows = np.flatnonzero(np.asarray(t["camera.recording"]) == rec)
        age, gender = t["pedestrian.age"][rows[0]], t["pedestrian.gender"][rows[0]]
        stem = sk.model_name(age, gender)
        if stem not in ref:
            from bsp_fast.geometry import forward_kinematics
            c0 = forward_kinematics(sk.reference_pose(stem))[:, :3]
            ref[stem] = np.linalg.norm(c0[2:] - c0[PARENTS[2:]], axis=-1)
        bones = np.linalg.norm(comp[rows, 2:] - comp[rows][:, PARENTS[2:]], axis=-1)
        long = ref[stem] > 0.02  # ratios of near-zero bones are noise
        out[rec] = bones[:, long] / ref[stem][long]
    return out


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    root = tmp_path_factory.mktemp("bones")
    plain = generate(root / "plain", "sample", **OPTS)
    varied = generate(root / "varied", "sample", bone_length_variation=0.1, **OPTS)
    return root, plain, varied


def test_each_walker_gets_one_factor_within_the_range(pair):
    root, _, _ = pair
    plain = _bone_ratios(root / "plain")
    factors = []
    for rec, r in _bone_ratios(root / "varied").items():
        # one factor for every bone and frame of a walker (float32 CSV: ~1e-4 relative)
        assert np.allclose(r, r.flat[0], rtol=2e-4), rec
        assert 0.9 - 1e-4 <= r.flat[0] <= 1.1 + 1e-4
        factors.append(r.flat[0])
    assert np.ptp(factors) > 0.01  # walkers differ
    for r in plain.values():  # no variation: the reference skeleton exactly
        assert np.allclose(r, 1.0, rtol=2e-4)


def test_no_other_random_draw_changes(pair):
    root, plain, varied = pair
    assert plain["ids"] == varied["ids"]
    a, b = read_csv(root / "plain" / "data.csv"), read_csv(root / "varied" / "data.csv")
    for col in ("pedestrian.age", "pedestrian.gender", "camera.recording"):
        assert sorted(set(a[col])) == sorted(set(b[col]))
    cam_a = {r: tuple(np.asarray(a["camera.transform"])[i])
             for i, r in enumerate(a["camera.recording"])}
    cam_b = {r: tuple(np.asarray(b["camera.transform"])[i])
             for i, r in enumerate(b["camera.recording"])}
    assert cam_a == cam_b  # same cameras and streets
    cfg = yaml.safe_load((root / "varied" / "config.yaml").read_text())
    assert cfg["bone_length_variation"] == pytest.approx(0.1)


@pytest.mark.filterwarnings("ignore:bsp_fast.convert")
def test_the_varied_dataset_converts_and_verifies(pair, tmp_path):
    from bsp_fast import convert

    root, _, _ = pair
    rep = convert(root / "varied", tmp_path / "v.h5", clip_length=10, media=False,
                  verify=True)
    assert not rep["verify_failed"]


def test_cli_refuses_out_of_range(tmp_path, capsys):
    assert cli_main([str(tmp_path / "o"), "--bone-length-variation", "0.6", "--quiet"]) == 2
    assert "bone_length_variation" in capsys.readouterr().err
