"""bsp-convert end to end on tiny hand-built datasets, read back with h5py in-process.

These datasets have no MP4/APNG files, so they convert with media=False (--no-media);
the media conversion is tested in test_convert_media.py.
"""
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast import conversion as cv
from bsp_testdata import COLUMNS, csv_text, recording, write_dataset

U1 = "094b9fe1-babe-48d5-bd17-3ba3185690c5-0"


def dataset_rows():
    rows = []
    # recording A: frames 0..39 and 45..74 (gap), crossing from frame 60
    rows += recording(U1, list(range(40)) + list(range(45, 75)), crossing_from=60, seed=1)
    for k in range(2, 7):  # five more recordings of 35 frames, two crossing
        rows += recording(f"{k:08x}-0000-4000-8000-000000000000-0", range(35),
                          crossing_from=20 if k % 3 == 0 else None, seed=k,
                          age="child" if k % 2 else "adult", gender="male")
    return rows


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    return write_dataset(tmp_path_factory.mktemp("ds") / "dataset", dataset_rows())


def read_all(path):
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = obj.asstr()[...] if obj.dtype.kind == "O" else obj[...]
        f.visititems(visit)
        out["attrs"] = dict(f.attrs)
    return out


def test_round_trip_values(ds, tmp_path):
    out = tmp_path / "clips.h5"
    rep = cv.convert(ds, out, clip_length=10, val_frac=0.2, test_frac=0.2, media=False)
    # recording A: segments of 40 and 30 frames -> 4 + 3 clips; others 3 clips each = 22
    assert sum(rep["splits"][s]["clips"] for s in ("train", "val", "test")) == 22
    assert rep["rows"] == 70 + 5 * 35 and rep["recordings"] == 6
    table = {}
    for r in dataset_rows():
        table[(r["camera.recording"][:-4], r["frame.idx"])] = r
    with h5py.File(out, "r") as f:
        assert f.attrs["clip_length"] == 10 and f.attrs["fov"] == 90.0
        assert list(f.attrs["class_labels"]) == ["not-crossing", "crossing"]
        seen = 0
        for split in ("train", "val", "test"):
            g = f[split]
            vids = g["meta/video_id"].asstr()[...]
            for i in range(g["labels"].shape[0]):
                frames = g["targets/frame_idx"][i]
                assert np.all(np.diff(frames) == 1)  # never across the gap
                assert g["meta/start_frame"][i] == frames[0] and g["meta/end_frame"][i] == frames[-1] + 1
                last = table[(vids[i], frames[-1])]
                assert g["labels"][i] == int(last["frame.pedestrian.is_crossing"])
                r = table[(vids[i], frames[3])]
                uv = np.array(eval(r["frame.pedestrian.pose.camera"]), np.float32)  # noqa: S307
                np.testing.assert_array_equal(g["projection_2d"][i, 3], uv)
                world = np.array(eval(r["frame.pedestrian.pose.world"]), np.float32)  # noqa: S307
                np.testing.assert_array_equal(g["targets/world_pose_loc"][i, 3], world[:, :3])
                np.testing.assert_allclose(g["targets/world_pose_rot"][i, 3],
                                           bf.rotation_matrix(world[:, 3:].astype(float)), atol=2e-7)
                bb = g["targets/bboxes"][i, 3]
                np.testing.assert_array_equal(bb, [uv.min(0), uv.max(0)])
                seen += 1
        assert seen == 22
        assert f["train/meta/pedestrian_id"].asstr()[0] == "0_0"


def test_cpp_conversion_defaults_equal_python_defaults():
    """The C++ core's defaults (ClipOptions, ConvertOptions, MediaOptions) and
    bsp_fast.defaults.CONVERT are two copies of one set of values: they must not drift."""
    from bsp_fast._native import core
    from bsp_fast.defaults import CONVERT, SEED

    cpp = core.convert_defaults()
    assert set(cpp) == {"clip_length", "val_frac", "test_frac", "seed", "fov", "crop_size",
                        "crop_box", "crop_context"}
    assert cpp == {k: CONVERT[k] for k in cpp}
    assert cpp["seed"] == SEED


def test_source_crc32_and_bytes_are_those_of_data_csv(ds, tmp_path):
    import zlib

    data = (ds / "data.csv").read_bytes()
    r = cv.convert(ds, tmp_path / "o.h5", clip_length=10, media=False, threads=2)
    assert (r["source_crc32"], r["source_bytes"]) == (zlib.crc32(data), len(data))
    with h5py.File(tmp_path / "o.h5") as f:
        assert f.attrs["source_crc32"] == zlib.crc32(data)
        assert f.attrs["source_bytes"] == len(data)


def test_every_recording_in_one_split_and_class_counts(ds, tmp_path):
    d = read_all(cv.convert(ds, tmp_path / "a.h5", clip_length=10, media=False)["output"])
    owners = {}
    for split in ("train", "val", "test"):
        for v in set(d[f"{split}/meta/video_id"]):
            assert owners.setdefault(v, split) == split
        lab = d[f"{split}/labels"]
        assert list(d["attrs"][f"class_counts_{split}"]) == [(lab == 0).sum(), (lab == 1).sum()]
    assert len(owners) == 6


def test_deterministic_over_threads_and_seed(ds, tmp_path):
    a = read_all(cv.convert(ds, tmp_path / "a.h5", clip_length=10, threads=1, media=False)["output"])
    b = read_all(cv.convert(ds, tmp_path / "b.h5", clip_length=10, threads=2, media=False)["output"])
    c = read_all(cv.convert(ds, tmp_path / "c.h5", clip_length=10, seed=5, media=False)["output"])
    for k in a:
        if k != "attrs":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert any(not np.array_equal(a[k], c[k]) for k in a if k.endswith("frame_idx"))


def test_batches_filled_while_written_give_the_same_values(ds, tmp_path, monkeypatch):
    """With chunk_clips=1 the 22 clips are written in batches of 2 (2+ threads; each filled
    while the previous one is written, pose_write.cpp) or of 4 (1 thread). Every value must
    equal the one-batch, one-thread conversion's."""
    ref = read_all(cv.convert(ds, tmp_path / "ref.h5", clip_length=10, threads=1,
                              media=False)["output"])
    core_convert = cv.api._core.convert_csv
    monkeypatch.setattr(cv.api._core, "convert_csv",
                        lambda csv, tmp, prog, **kw: core_convert(csv, tmp, prog, chunk_clips=1, **kw))
    for threads in (1, 2, 3):
        out = cv.convert(ds, tmp_path / f"t{threads}.h5", clip_length=10, threads=threads,
                         media=False)["output"]
        with h5py.File(out, "r") as f:
            assert f["train/targets/world_pose_rot"].chunks[0] == 1  # the option took effect
        d = read_all(out)
        assert d.keys() == ref.keys()
        for k in ref:
            if k != "attrs":
                np.testing.assert_array_equal(d[k], ref[k], err_msg=f"{k}, {threads} threads")


def test_compressed_chunks_packed_on_worker_threads_read_back_the_same(ds, tmp_path, monkeypatch):
    """--compress: the big fields' chunks are shuffled and deflated by the worker threads
    and written as stored. chunk_clips=3 leaves a partial last chunk in every split. Read
    through h5py (its own libhdf5), every value equals the uncompressed conversion's."""
    ref = read_all(cv.convert(ds, tmp_path / "ref.h5", clip_length=10, threads=1,
                              media=False)["output"])
    core_convert = cv.api._core.convert_csv
    monkeypatch.setattr(cv.api._core, "convert_csv",
                        lambda csv, tmp, prog, **kw: core_convert(csv, tmp, prog, chunk_clips=3, **kw))
    for threads in (1, 2):
        out = cv.convert(ds, tmp_path / f"c{threads}.h5", clip_length=10, threads=threads,
                         compress=True, media=False)["output"]
        with h5py.File(out, "r") as f:
            rot = f["train/targets/world_pose_rot"]
            assert (rot.compression, rot.compression_opts, rot.shuffle) == ("gzip", 1, True)
            assert rot.chunks[0] == 3 and rot.shape[0] % 3 != 0  # a partial last chunk
            assert f["train/projection_2d"].compression is None  # small fields stay plain
        d = read_all(out)
        assert d.keys() == ref.keys()
        for k in ref:
            if k != "attrs":
                np.testing.assert_array_equal(d[k], ref[k], err_msg=f"{k}, {threads} threads")


def test_crossing_column_names_reordered_columns_and_crlf(tmp_path):
    rows = recording(U1, range(40), crossing_from=25)
    base = write_dataset(tmp_path / "base", rows)
    cols = COLUMNS[::-1]
    other = write_dataset(tmp_path / "other", rows, columns=cols, newline="\r\n",
                          crossing_name="frame.pedestrian.is_on_driving_lane")
    opts = dict(clip_length=10, val_frac=0, test_frac=0, media=False)
    a = read_all(cv.convert(base, tmp_path / "a.h5", **opts)["output"])
    b = read_all(cv.convert(other, tmp_path / "b.h5", **opts)["output"])
    for k in a:
        if k != "attrs":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert a["train/labels"].sum() + a["val/labels"].sum() + a["test/labels"].sum() >= 1


def test_nan_joints_and_out_of_image_windows_are_rejected(tmp_path):
    rows = recording(U1, range(30), seed=3)
    # joint 0 of frame 12 behind the camera
    uv = np.array(eval(rows[12]["frame.pedestrian.pose.camera"]))  # noqa: S307
    cell = "[" + ", ".join("[nan, nan]" if j == 0 else f"[{repr(float(np.float32(u)))}, {repr(float(np.float32(v)))}]"
                           for j, (u, v) in enumerate(uv)) + "]"
    rows[12]["frame.pedestrian.pose.camera"] = cell
    ds = write_dataset(tmp_path / "ds", rows)
    rep = cv.convert(ds, tmp_path / "o.h5", clip_length=10, val_frac=0, test_frac=0, media=False)
    # windows 0-9, 10-19 (has the NaN frame), 20-29 -> 2 kept
    assert sum(rep["splits"][s]["clips"] for s in ("train", "val", "test")) == 2
    assert rep["clips_rejected_out_of_image"] == 1


def test_benchmark_mode_labels_and_offsets(tmp_path):
    rows = recording(U1, range(120), crossing_from=100, seed=4)
    rows += recording("aaaaaaaa-0000-4000-8000-000000000000-0", range(100), seed=5)
    ds = write_dataset(tmp_path / "ds", rows)
    rep = cv.convert(ds, tmp_path / "o.h5", benchmark=True, val_frac=0, test_frac=0, media=False)
    d = read_all(rep["output"])
    assert d["attrs"]["clip_length"] == 16 and d["attrs"]["clip_stride"] == 6
    assert d["attrs"]["label_rule"] == "video"
    labels = np.concatenate([d[f"{s}/labels"] for s in ("train", "val", "test")])
    vids = np.concatenate([d[f"{s}/meta/video_id"] for s in ("train", "val", "test")])
    starts = np.concatenate([d[f"{s}/meta/start_frame"] for s in ("train", "val", "test")])
    # crosser: keep 100-16-60=24 .. 70 (47 frames) -> starts 24, 30, ..., 54 (6 clips)
    assert sorted(starts[vids == f"clips/{U1}-0"]) == list(range(24, 55, 6))
    assert set(labels[vids == f"clips/{U1}-0"]) == {1}
    assert set(labels[vids != f"clips/{U1}-0"]) == {0}


def test_existing_output_kept_without_force(ds, tmp_path):
    out = tmp_path / "o.h5"
    out.write_bytes(b"precious")
    with pytest.raises(FileExistsError, match="--force"):
        cv.convert(ds, out, media=False)
    assert out.read_bytes() == b"precious"
    assert cv.main(["--no-media", str(ds), str(out), "--quiet"]) == 3
    assert out.read_bytes() == b"precious"
    assert cv.main(["--no-media", str(ds), str(out), "--quiet", "--force", "--clip-length", "10"]) == 0
    assert h5py.is_hdf5(out)


def test_bad_csv_errors_name_file_line_column_and_leave_nothing(tmp_path):
    rows = recording(U1, range(20))
    rows[5]["frame.pedestrian.pose.world"] = rows[5]["frame.pedestrian.pose.world"][:-1] + ", [1.0]]"
    ds = write_dataset(tmp_path / "ds", rows)
    out = tmp_path / "o.h5"
    with pytest.raises(bf.CsvParseError) as e:
        cv.convert(ds, out, media=False)
    msg = str(e.value)
    assert "data.csv" in msg and "7" in msg and "frame.pedestrian.pose.world" in msg
    assert not out.exists() and not list(tmp_path.glob(".o.h5.tmp-*"))
    assert cv.main(["--no-media", str(ds), str(out), "--quiet"]) == 1


def test_missing_column_and_duplicate_rows(tmp_path):
    rows = recording(U1, range(20))
    ds = write_dataset(tmp_path / "ds", rows, columns=[c for c in COLUMNS if c != "frame.pedestrian.pose.relative"])
    with pytest.raises(bf.CsvParseError, match="frame.pedestrian.pose.relative"):
        cv.convert(ds, tmp_path / "o.h5", media=False)
    dup = write_dataset(tmp_path / "dup", rows + rows[3:4])
    with pytest.raises(bf.CsvParseError, match="(?i)duplicate"):
        cv.convert(dup, tmp_path / "o.h5", media=False)


def test_interrupted_conversion_leaves_no_file(ds, tmp_path, monkeypatch):
    out = tmp_path / "o.h5"

    def boom(csv, tmp, progress, **kw):
        open(tmp, "wb").write(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(cv.api._core, "convert_csv", boom)
    with pytest.raises(KeyboardInterrupt):
        cv.convert(ds, out, media=False)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_verify_reports_agreement_and_flags_tampering(tmp_path):
    rows = recording(U1, range(20), seed=7)
    ds = write_dataset(tmp_path / "ds", rows)
    rep = cv.convert(ds, tmp_path / "o.h5", verify=True, clip_length=10, media=False)
    (v,) = rep["verify"]
    assert v["component_mm"] < 0.1 and v["world_mm"] < 0.1 and v["camera_px"] < 0.01
    assert rep["verify_failed"] == []
    comp = np.array(eval(rows[4]["frame.pedestrian.pose.component"]))  # noqa: S307
    comp[7, 2] += 0.05  # left hand 5 cm up
    rows[4]["frame.pedestrian.pose.component"] = "[" + ", ".join(
        "[" + ", ".join(repr(float(np.float32(x))) for x in j) + "]" for j in comp) + "]"
    bad = write_dataset(tmp_path / "bad", rows)
    rep = cv.convert(bad, tmp_path / "b.h5", verify=True, clip_length=10, media=False)
    assert 45 < rep["verify"][0]["component_mm"] < 55
    assert len(rep["verify_failed"]) == 1
    assert cv.main(["--no-media", str(bad), str(tmp_path / "c.h5"), "--verify", "--quiet",
                    "--clip-length", "10"]) == 4


def test_fov_from_config_yaml(tmp_path):
    ds = write_dataset(tmp_path / "ds", recording(U1, range(20)))
    (ds / "config.yaml").write_text("fov: 70\n")
    rep = cv.convert(ds, tmp_path / "o.h5", clip_length=10, media=False)
    assert rep["settings"]["fov"] == 70.0 and rep["settings"]["fov_source"] == "config.yaml"
    with h5py.File(rep["output"]) as f:
        assert f.attrs["fov"] == 70.0


def test_bad_options_are_value_errors(ds, tmp_path):
    with pytest.raises(ValueError, match="any:F"):
        cv.convert(ds, tmp_path / "o.h5", label="first", media=False)
    with pytest.raises(ValueError, match="clip_length"):
        cv.convert(ds, tmp_path / "o.h5", clip_length=0, media=False)
    assert cv.main(["--no-media", str(ds), str(tmp_path / "o.h5"), "--label", "nope", "--quiet"]) == 2


def test_cli_runs_as_a_module(ds, tmp_path):
    out = tmp_path / "o.h5"
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "convert", str(ds), str(out), "--clip-length", "10",
                        "--no-media"],
                       capture_output=True, text=True, env={**os.environ})
    assert p.returncode == 0, p.stderr
    assert "train" in p.stdout and "rows/s" in p.stdout

