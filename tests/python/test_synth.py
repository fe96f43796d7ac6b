"""bsp-synth end to end: a small generated dataset checked against docs/dataset-format.md,
"1. Files on disk" to "3. Media", "5. Geometry conventions" and
"6. How the recorder placed cameras and walkers"."""
from __future__ import annotations

import ast
import io
import math
import os
import uuid

import numpy as np
import pytest

import bsp_fast
from bsp_fast import geometry as geo
from bsp_fast.csvio import COLUMNS, read_csv
from bsp_testdata import COLUMNS as SPEC_COLUMN_LIST
from bsp_fast.synth import generate
from bsp_fast.synth import clip as synth_clip
from bsp_fast.synth.cli import main as cli_main
from bsp_fast.synth.config import make_config

pd = pytest.importorskip("pandas")
av = pytest.importorskip("av")
Image = pytest.importorskip("PIL.Image")

SPEC_COLUMNS = tuple(SPEC_COLUMN_LIST)  # the writer order of docs/dataset-format.md, "2. data.csv"
OPTS = dict(clips=3, frames=150, size="320x128", seed=27)  # adults, children, crossings, gaps


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "ds"
    summary = generate(out, "sample", workers=1, progress=False, **OPTS)
    return out, summary


@pytest.fixture(scope="module")
def table(dataset):
    return read_csv(dataset[0] / "data.csv")


def test_layout_and_summary(dataset):
    out, s = dataset
    assert sorted(os.listdir(out)) == ["clips", "config.yaml", "data.csv"]
    names = sorted(os.listdir(out / "clips"))
    assert len(names) == 2 * OPTS["clips"]
    for cid in s["ids"]:
        assert f"{cid}-0.mp4" in names and f"{cid}-1.apng" in names
        u = uuid.UUID(cid[:-2])
        assert cid.endswith("-0") and u.version == 4 and str(u) == cid[:-2]
    assert s["clips"] == 3 and s["frames"] == 3 * OPTS["frames"]
    assert sum(p["clips"] for p in s["per_profile"].values()) == 3
    assert s["annotated_frames"] == len(pd.read_csv(out / "data.csv"))


def test_ids_follow_the_seed():
    ids = [synth_clip.clip_id(synth_clip.clip_rngs(7, i, 1)[1]) for i in range(3)]
    assert ids == [synth_clip.clip_id(synth_clip.clip_rngs(7, i, 1)[1]) for i in range(3)]
    assert len(set(ids)) == 3
    assert ids[0] != synth_clip.clip_id(synth_clip.clip_rngs(8, 0, 1)[1])


def test_header_and_pandas_round_trip(dataset):
    path = dataset[0] / "data.csv"
    raw = path.read_bytes()
    assert raw.split(b"\n", 1)[0].decode() == ",".join(SPEC_COLUMNS)
    assert tuple(COLUMNS) == SPEC_COLUMNS
    assert b"\r" not in raw and raw.endswith(b"\n")
    df = pd.read_csv(path)
    assert tuple(df.columns) == SPEC_COLUMNS
    pose = np.array([ast.literal_eval(c.replace("nan", "None")) for c in
                     df["frame.pedestrian.pose.world"]], dtype=float)
    assert pose.shape == (len(df), 26, 6)
    cam = ast.literal_eval(df["camera.transform"].iloc[0])
    assert len(cam) == 6 and all(isinstance(v, float) for v in cam)
    assert df["frame.pedestrian.is_crossing"].dtype == bool
    assert set(df["pedestrian.age"]) <= {"adult", "child"}


def _cell(v):
    """A Python value as the recorder's DataFrame held it (float32 widened to float)."""
    if isinstance(v, np.ndarray):
        return [_cell(x) for x in v] if v.ndim > 1 else [float(x) for x in v]
    return v.item() if isinstance(v, np.generic) else v


def test_bytes_equal_pandas_to_csv(dataset, table):
    """Every cell, quote and separator is what pandas to_csv(index=False) writes."""
    data = {name: [_cell(v) for v in table[name]] for name in SPEC_COLUMNS}
    buf = io.StringIO()
    pd.DataFrame(data, columns=list(SPEC_COLUMNS)).to_csv(buf, index=False)
    assert buf.getvalue().encode() == (dataset[0] / "data.csv").read_bytes()


def test_cell_syntax(dataset):
    line = (dataset[0] / "data.csv").read_text().split("\n")[1]
    cells = next(iter(pd.read_csv(io.StringIO(line), header=None, dtype=str).itertuples(
        index=False)))
    assert len(cells) == 24
    tf = cells[3]
    assert tf.startswith("[") and tf.endswith("]") and ", " in tf
    for v in ast.literal_eval(tf):  # float32 values printed with Python's shortest repr
        assert repr(float(np.float32(v))) == repr(v)
    assert cells[17].startswith("[[") and "], [" in cells[17]
    assert cells[20] in ("True", "False") and cells[22] in ("True", "False")
    assert '"[' in line  # list cells are quoted


def test_our_reader_round_trip(dataset, table):
    df = pd.read_csv(dataset[0] / "data.csv")
    assert len(table) == len(df)
    np.testing.assert_array_equal(table["frame.idx"], df["frame.idx"].to_numpy())
    rel = np.array([ast.literal_eval(c) for c in df["frame.pedestrian.pose.relative"]],
                   dtype=np.float32)
    np.testing.assert_array_equal(table["frame.pedestrian.pose.relative"], rel)
    assert list(table["id"]) == list(df["id"])
    np.testing.assert_array_equal(table["frame.pedestrian.pose.in_frame"],
                                  df["frame.pedestrian.pose.in_frame"].to_numpy())


def test_rows_sorted_with_gaps_allowed(table):
    ids, frames = np.asarray(table["id"]), table["frame.idx"]
    for cid in dict.fromkeys(ids):
        f = frames[ids == cid]
        assert np.all(np.diff(f) > 0) and f.min() >= 0 and f.max() < OPTS["frames"]
    np.testing.assert_array_equal(table["world.frame"] - frames,
                                  np.repeat([table["world.frame"][ids == c][0] -
                                             frames[ids == c][0] for c in dict.fromkeys(ids)],
                                            [np.sum(ids == c) for c in dict.fromkeys(ids)]))


def test_pose_columns_consistent_through_fk(table):
    rel = table["frame.pedestrian.pose.relative"].astype(np.float64)
    comp = table["frame.pedestrian.pose.component"].astype(np.float64)
    world = table["frame.pedestrian.pose.world"].astype(np.float64)
    walker = table["frame.pedestrian.transform"].astype(np.float64)
    M = geo.mesh_offset(rel, comp)
    np.testing.assert_allclose(M[:, [0, 1, 3, 5]], 0.0, atol=1e-4)
    np.testing.assert_allclose(M[:, 4], -90.0, atol=1e-3)
    assert np.all((M[:, 2] < -0.5) & (M[:, 2] > -0.95))  # -h: adults 0.92, children less
    adults = np.asarray(table["pedestrian.age"]) == "adult"
    np.testing.assert_allclose(M[adults, 2], -0.92, atol=1e-5)
    fk = geo.forward_kinematics(rel, root=M)
    np.testing.assert_allclose(fk[..., :3], comp[..., :3], atol=1e-4)
    R = geo.rotation_matrix
    np.testing.assert_allclose(R(fk[..., 3:]), R(comp[..., 3:]), atol=1e-5)
    w = geo.to_world(comp, walker)
    np.testing.assert_allclose(w[..., :3], world[..., :3], atol=1e-4)
    np.testing.assert_allclose(R(w[..., 3:]), R(world[..., 3:]), atol=1e-5)
    # The root joint is the actor pivot at the feet: h below the capsule centre.
    np.testing.assert_allclose(world[:, 0, 2], walker[:, 2] + M[:, 2], atol=1e-4)


def test_feet_stay_on_the_ground(table):
    world = table["frame.pedestrian.pose.world"].astype(np.float64)
    feet = world[:, [19, 20, 24, 25, 18, 23], 2]  # toes, toe tips, ankles
    ground = world[:, 0, 2]
    lowest = feet.min(axis=1) - ground
    assert np.all(lowest > -0.02) and np.all(lowest < 0.06)
    # a walking gait lifts one foot well above the other at times
    ankles = world[:, [18, 23], 2]
    assert np.max(np.abs(ankles[:, 0] - ankles[:, 1])) > 0.05


def test_pose_camera_is_projection_of_world(table):
    world = table["frame.pedestrian.pose.world"].astype(np.float64)
    cam = table["camera.transform"].astype(np.float64)
    W, H = table["camera.width"][0], table["camera.height"][0]
    uv = geo.project(world[..., :3], cam, W, H, 90.0)
    stored = table["frame.pedestrian.pose.camera"].astype(np.float64)
    np.testing.assert_array_equal(np.isnan(uv), np.isnan(stored))
    np.testing.assert_allclose(stored, uv, atol=1e-3, equal_nan=True)
    assert np.all(geo.in_frame(stored, W, H) == table["frame.pedestrian.pose.in_frame"])
    # only frames where the pedestrian is in view are annotated
    inside = (stored[..., 0] >= 0) & (stored[..., 0] <= W) & (stored[..., 1] >= 0) & \
        (stored[..., 1] <= H)
    assert np.all(inside.any(axis=1))


def test_camera_placement(table, dataset):
    cam = table["camera.transform"].astype(np.float64)
    assert np.all(cam[:, 5] == 0.0)
    assert np.all((cam[:, 2] > -0.5) & (cam[:, 2] < 3.0))
    assert np.all((cam[:, 3] < 5.0) & (cam[:, 3] > -60.0))  # looks down at the lane point
    for cid in dict.fromkeys(table["id"]):
        c = cam[np.asarray(table["id"]) == cid]
        assert np.all(c == c[0])  # static per clip
    spawn = table["pedestrian.spawn_point"]
    assert np.all(spawn[:, 3:] == 0.0)


def _apng_frames(path):
    im = Image.open(path)
    out = []
    for k in range(im.n_frames):
        im.seek(k)
        assert im.mode == "P"
        out.append(np.array(im))
    return np.stack(out)


def test_media_match_columns(dataset, table):
    out, s = dataset
    ids = np.asarray(table["id"])
    for cid in s["ids"]:
        rows = ids == cid
        rec = table["camera.recording"][rows][0]
        seg = table["camera.semantic_segmentation"][rows][0]
        assert rec == f"clips/{cid}-0.mp4" and seg == f"clips/{cid}-1.apng"
        with av.open(str(out / rec)) as c:
            st = c.streams.video[0]
            assert st.codec_context.name == "h264" and st.codec_context.pix_fmt == "yuv420p"
            assert (st.width, st.height) == (320, 128) and st.average_rate == 30
            assert sum(1 for _ in c.decode(video=0)) == OPTS["frames"]
        tags = _apng_frames(out / seg)
        assert tags.shape == (OPTS["frames"], 128, 320)
        has_ped = (tags == 4).any(axis=(1, 2))
        f = table["frame.idx"][rows]
        np.testing.assert_array_equal(table["frame.pedestrian.pose.in_segmentation"][rows],
                                      has_ped[f])
        assert set(np.unique(tags)) <= set(range(23)) and 7 in np.unique(tags)  # road


def test_apng_holds_the_rendered_tags(dataset):
    """Decoding with Pillow gives exactly the tags the renderer produced."""
    out, s = dataset
    cfg = make_config("sample", dict(number_of_clips=3, clip_length_in_frames=150,
                                     camera_image_size=(320, 128), seed=27))
    cp = synth_clip.plan_clip(cfg, 1)
    assert cp.id == s["ids"][1]
    per_frame = synth_clip.pose_columns(cp, cfg)
    tabs = synth_clip.build_scene(cp)
    core = bsp_fast._core
    bg = core.render_background(tabs.road, tabs.bands, tabs.boxes, tabs.cylinders,
                                tabs.spheres, tabs.light, cp.camera, 320, 128, 90.0, 1)
    from bsp_fast.synth import body
    yaw = np.radians(cp.path.yaw)
    fwd = np.stack([np.cos(yaw), np.sin(yaw), 0 * yaw], -1)
    caps = body.body_capsules(per_frame["world"][..., :3], fwd)
    _, tags, vis = core.render_bodies(*bg, cp.camera, 90.0, tabs.light,
                                      np.ascontiguousarray(caps),
                                      body.sample_colours(cp.rng_look), 2)
    decoded = _apng_frames(out / "clips" / f"{cp.id}-1.apng")
    np.testing.assert_array_equal(decoded, tags)
    np.testing.assert_array_equal(vis, (tags == 4).any(axis=(1, 2)))


def test_segmentation_is_aligned_with_rgb(dataset):
    """Tagged regions have their class's look in the video: grey asphalt, bluish sky, and
    pedestrian pixels that differ from the same pixels in frames without the pedestrian."""
    out, s = dataset
    for cid in s["ids"]:
        tags = _apng_frames(out / "clips" / f"{cid}-1.apng")
        with av.open(str(out / "clips" / f"{cid}-0.mp4")) as c:
            rgb = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)]).astype(float)
        road = rgb[tags == 7]
        assert np.abs(road[:, 0] - road[:, 2]).mean() < 15  # asphalt is grey
        if (tags == 13).sum() > 100:
            sky = rgb[tags == 13]
            assert sky[:, 2].mean() > sky[:, 0].mean() + 20
        ped = tags == 4
        k = int(np.argmax(ped.sum(axis=(1, 2))))
        bg = np.median(rgb, axis=0)  # the pedestrian moves; the street does not
        if ped[k].sum() > 50:
            diff = np.abs(rgb[k][ped[k]] - bg[ped[k]]).sum(axis=-1)
            assert np.median(diff) > 20


def test_same_seed_same_bytes_for_1_and_2_workers(tmp_path):
    opts = dict(clips=2, frames=45, size="160x96", seed=3, progress=False)
    a = generate(tmp_path / "a", "sample", workers=1, **opts)
    b = generate(tmp_path / "b", "sample", workers=2, **opts)
    assert a["ids"] == b["ids"]
    # every file of both trees (a clip whose walker never enters the view has no media)
    names = [sorted(str(p.relative_to(tmp_path / d)) for p in (tmp_path / d).rglob("*")
                    if p.is_file()) for d in ("a", "b")]
    assert names[0] == names[1]
    assert {"data.csv", "config.yaml"} <= set(names[0])
    assert sum(n.endswith((".mp4", ".apng")) for n in names[0]) == 2 * a["recordings"] > 0
    for name in names[0]:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    c = generate(tmp_path / "c", "sample", workers=1, **dict(opts, seed=4))
    assert c["ids"] != a["ids"]


def test_config_yaml_records_parameters(dataset):
    import yaml

    cfg = yaml.safe_load((dataset[0] / "config.yaml").read_text())
    assert cfg["seed"] == 27 and cfg["camera_fov"] == 90.0 and cfg["fps"] == 30
    assert cfg["camera_image_size"] == [320, 128] and cfg["number_of_clips"] == 3
    assert cfg["clip_length_in_frames"] == 150 and cfg["version"] == bsp_fast.__version__
    assert [p[0][:2] for p in cfg["pedestrian_distributions"]] == [
        ["adult", "female"], ["adult", "male"], ["child", "female"], ["child", "male"]]
    assert math.isclose(sum(p[1] for p in cfg["pedestrian_distributions"]), 1.0)


def test_yaml_config_with_original_keys(tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(
        "number_of_clips: 2\nclip_length_in_frames: 20\ncamera_fov: 70\n"
        "camera_image_size: [96, 64]\nbatch_size: 2\n"
        "pedestrian_distributions:\n  - [[child, male, [0.9, 0.21], [1.0, 0.0]], 1.0]\n"
        "  - [adult_female, 0.0]\n"
        "camera_position_distributions:\n  - [[-5.0, 0.0], [0.0, 0.0], [1.5, 0.0]]\n")
    s = generate(tmp_path / "out", config=cfg, workers=1, progress=False, seed=1)
    t = read_csv(tmp_path / "out" / "data.csv")
    assert s["clips"] == 2 and set(s["per_profile"]) == {"child_male"}
    if len(t):
        assert set(t["pedestrian.age"]) == {"child"} and t["camera.width"][0] == 96
        cam = t["camera.transform"].astype(np.float64)
        assert np.all(np.abs(cam[:, 2] - 1.5) < 1e-5)  # offset z 1.5 above the lane point
        speed = np.linalg.norm(t["frame.pedestrian.velocity"][:, :2], axis=1)
        assert np.median(speed) == pytest.approx(1.0, abs=0.05)  # crossing speed N(1.0, 0)


def test_cli_exit_codes(tmp_path, capsys):
    out = tmp_path / "o"
    args = [str(out), "--clips", "1", "--frames", "10", "--size", "64x48", "--quiet"]
    assert cli_main(args) == 0
    assert cli_main(args) == 3  # exists
    assert "exists" in capsys.readouterr().err
    assert cli_main(args + ["--force"]) == 0
    assert cli_main([str(tmp_path / "p"), "--size", "63x48", "--quiet"]) == 2
    assert "even" in capsys.readouterr().err
    assert cli_main([str(tmp_path / "q"), "--motion", str(tmp_path / "none.bvh")]) == 1
    with pytest.raises(SystemExit) as e:
        cli_main(["--help"])
    assert e.value.code == 0
    assert "--apng-drop-duplicates" in capsys.readouterr().out
    assert not [p for p in os.listdir(tmp_path) if ".tmp-" in p]


def test_drop_duplicates_option(tmp_path):
    # seed 6: the walker is in view (seed 5's never enters it: no rows, so no media)
    s = generate(tmp_path / "d", clips=1, frames=30, size="64x48", seed=6, workers=1,
                 apng_drop_duplicates=True, progress=False)
    assert s["recordings"] == 1
    im = Image.open(tmp_path / "d" / "clips" / f"{s['ids'][0]}-1.apng")
    assert 1 <= im.n_frames <= 30


def test_joints_behind_the_camera_are_nan(tmp_path):
    """A camera just behind the hips, looking along the walk: some joints fall behind it."""
    from bsp_fast.csvio import write_csv

    cfg = make_config("sample", dict(number_of_clips=1, clip_length_in_frames=30, seed=27,
                                     camera_image_size=(320, 128)))
    cp = synth_clip.plan_clip(cfg, 0)
    yaw = np.radians(cp.path.yaw[0])
    hips = cp.path.xyz[0]
    cp.camera = np.array([hips[0] + 0.12 * np.cos(yaw), hips[1] + 0.12 * np.sin(yaw),
                          hips[2], 0.0, np.degrees(yaw), 0.0])
    per_frame = synth_clip.pose_columns(cp, cfg)
    cols = synth_clip.csv_columns(cp, cfg, per_frame, np.zeros(30, bool))
    uv = cols["frame.pedestrian.pose.camera"]
    assert len(uv) > 0 and np.isnan(uv).any()
    partial = np.isnan(uv).any(axis=(1, 2))
    assert not cols["frame.pedestrian.pose.in_frame"][partial].any()
    write_csv(tmp_path / "d.csv", cols)
    text = (tmp_path / "d.csv").read_text()
    assert "[nan, nan]" in text and "False" in text
    back = read_csv(tmp_path / "d.csv")
    np.testing.assert_array_equal(np.isnan(back["frame.pedestrian.pose.camera"]), np.isnan(uv))
