"""bsp-check: planted faults in a generated dataset are found, --fix writes a clean copy."""
from __future__ import annotations

import filecmp
import json
import os
import shutil

import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast.check import check_dataset, fix_dataset
from bsp_fast.check.cli import main
from bsp_fast.check.scan import joint_windows
from bsp_fast.media import ApngReader, ApngWriter

IN_SEG = "frame.pedestrian.pose.in_segmentation"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("check") / "ds"
    generate(out, "sample", clips=5, frames=90, size="320x120", seed=21, workers=2,
             progress=False)
    return out


def _recordings(ds):
    t = bf.read_csv(ds / "data.csv", ["id", "frame.idx", "camera.recording",
                                     "camera.semantic_segmentation", IN_SEG])
    recs = {}
    for i, rid in enumerate(t["id"]):
        r = recs.setdefault(rid, {"rows": [], "video": t["camera.recording"][i],
                                  "seg": t["camera.semantic_segmentation"][i]})
        r["rows"].append(i)
    return t, recs


def _mask_out(apng_path, frame):
    """Rewrites an APNG with the pedestrian (tag 4) painted over as sidewalk in `frame`."""
    r = ApngReader(apng_path)
    frames = r.read(np.arange(len(r)))
    assert (frames[frame] == 4).any()
    frames[frame][frames[frame] == 4] = 8
    w, h = r.size
    tmp = str(apng_path) + ".new.apng"
    with ApngWriter(tmp, w, h, palette=r.palette) as wr:
        wr.write(frames)
    os.replace(tmp, apng_path)


@pytest.fixture(scope="module")
def broken(pristine, tmp_path_factory):
    """A copy with one planted fault per recording A-D (E stays intact)."""
    ds = tmp_path_factory.mktemp("broken") / "ds"
    shutil.copytree(pristine, ds)
    t, recs = _recordings(ds)
    ids = list(recs)
    a, b, c, d = ids[:4]
    os.remove(ds / recs[a]["seg"])                                    # deleted file
    video = ds / recs[b]["video"]
    data = video.read_bytes()
    video.write_bytes(data[: len(data) // 2])                         # truncated video
    rows_c = [i for i in recs[c]["rows"] if t[IN_SEG][i]]
    row_c = rows_c[len(rows_c) // 2]
    _mask_out(ds / recs[c]["seg"], int(t["frame.idx"][row_c]))       # pedestrian masked out
    lines = (ds / "data.csv").read_bytes().split(b"\n")
    row_d = recs[d]["rows"][3]
    dup_line = lines[int(t.lines[row_d]) - 1]
    with open(ds / "data.csv", "ab") as fh:                           # duplicate row
        fh.write(dup_line + b"\n")
    return {"ds": ds, "ids": ids, "recs": recs, "row_c": row_c, "line_c": int(t.lines[row_c]),
            "line_d": int(t.lines[row_d]), "dup_line_no": len(lines), "table": t}


def _kinds(report):
    return {(f["kind"], (f["recording"] or "").split(" ")[0]) for f in report["findings"]}


def test_pristine_sample_is_clean_with_hand_counted_statistics(pristine, capsys):
    assert main([str(pristine), "--quiet"]) == 0
    assert capsys.readouterr().out.strip() == "Result: clean"
    rep = check_dataset(pristine)
    assert rep["clean"] and rep["findings"] == [] and rep["media_files"] == 10
    t = bf.read_csv(pristine / "data.csv")
    st = rep["statistics"]
    assert st["total"]["scenes"] == 5 and st["total"]["frames"] == len(t)
    assert st["total"]["crossing_frames"] == int(t["frame.pedestrian.is_crossing"].sum())
    assert st["video_frames"] == 5 * 90
    assert st["annotated_share"] == pytest.approx(len(t) / 450)
    for p in st["per_profile"]:
        m = (t["pedestrian.age"] == p["age"]) & (t["pedestrian.gender"] == p["gender"])
        assert p["frames"] == m.sum()
        assert p["scenes"] == len(set(t["id"][m]))
    # Every annotated row of the synthetic data shows the pedestrian where in_segmentation says.
    for r in rep["recordings"]:
        assert r["status"] == "ok" and r["video_frames"] == r["segmentation_frames"] == 90


def test_finds_each_planted_fault(broken, tmp_path, capsys):
    ds, (a, b, c, d, e) = broken["ds"], broken["ids"]
    code = main([str(ds), "--json", str(tmp_path / "r.json"), "--quiet"])
    assert code == 1
    rep = json.loads((tmp_path / "r.json").read_text())
    kinds = _kinds(rep)
    assert ("missing_file", a) in kinds
    assert ("unreadable_video", b) in kinds
    assert ("in_segmentation_mismatch", c) in kinds
    assert ("fully_occluded_rows", c) in kinds
    assert ("duplicate_rows", d) in kinds
    assert not any(e in k[1] for k in kinds)
    by = {(f["kind"], f["recording"].split(" ")[0]): f for f in rep["findings"]}
    assert by[("missing_file", a)]["message"] == f"{broken['recs'][a]['seg']} does not exist"
    assert by[("in_segmentation_mismatch", c)]["lines"] == [broken["line_c"]]
    assert by[("fully_occluded_rows", c)]["lines"] == [broken["line_c"]]
    assert by[("duplicate_rows", d)]["lines"] == [broken["dup_line_no"]]
    assert f"repeats line {broken['line_d']}" in by[("duplicate_rows", d)]["message"]
    status = {r["id"]: r["status"] for r in rep["recordings"]}
    assert status == {a: "broken", b: "broken", c: "ok", d: "ok", e: "ok"}
    # The duplicate counts once in the statistics (the table was read before planting it).
    assert rep["statistics"]["total"]["frames"] == len(broken["table"])


def test_fix_writes_a_clean_byte_identical_copy_that_converts(broken, tmp_path):
    ds, (a, b, c, d, e) = broken["ds"], broken["ids"]
    out = tmp_path / "clean"
    rep = fix_dataset(ds, out)
    fix = rep["fix"]
    assert fix["recordings_dropped"] == 2 and fix["recordings_kept"] == 3
    t, recs = broken["table"], broken["recs"]
    n_dropped = len(recs[a]["rows"]) + len(recs[b]["rows"]) + 1 + 1
    assert fix["rows_dropped"] == n_dropped and fix["rows_kept"] == len(t) + 1 - n_dropped
    # data.csv: the original lines of the kept rows, in order, bytes unchanged.
    orig = (ds / "data.csv").read_bytes().split(b"\n")
    gone = {int(t.lines[i]) for r in (a, b) for i in recs[r]["rows"]}
    gone |= {broken["line_c"], broken["dup_line_no"]}
    want = b"\n".join(x for k, x in enumerate(orig, start=1) if k not in gone)
    assert (out / "data.csv").read_bytes() == want
    for rid in (c, d, e):
        for key in ("video", "seg"):
            assert filecmp.cmp(ds / recs[rid][key], out / recs[rid][key], shallow=False)
    for rid in (a, b):
        assert not (out / recs[rid]["video"]).exists()
    assert filecmp.cmp(ds / "config.yaml", out / "config.yaml", shallow=False)
    log = (out / "bsp-check-fix.tsv").read_text().splitlines()
    assert sum(x.startswith("recording\t") for x in log) == 2
    assert any(x.startswith(f"row\tline {broken['dup_line_no']} ") and "duplicate" in x
               for x in log)
    assert any(x.startswith(f"row\tline {broken['line_c']} ") and "occluded" in x for x in log)
    assert any(x == f"file\t{recs[b]['video']}\tits recording was dropped" for x in log)
    # The copy is clean and converts, media included.
    assert check_dataset(out)["clean"]
    conv = bf.convert(out, tmp_path / "clips.h5", clip_length=10)
    assert conv["media"]["enabled"] and conv["media"]["bad"] == []
    assert conv["rows"] == fix["rows_kept"] and conv["recordings"] == 3
    assert sum(conv["splits"][s]["clips"] for s in conv["splits"]) > 0
    # The source is untouched and --fix refuses to write into it or over an existing copy.
    assert main([str(ds), "--fix", str(ds / "x"), "--quiet"]) == 2
    assert main([str(ds), "--fix", str(out), "--quiet"]) == 3  # exists: --force replaces it


def test_unreferenced_and_event_camera_files(pristine, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(pristine, ds)
    rid = bf.read_csv(ds / "data.csv", ["id"])["id"][0]
    (ds / "clips" / f"{rid}-2.npz").write_bytes(b"events")
    (ds / "clips" / "stray-0.mp4").write_bytes(b"x")
    rep = check_dataset(ds)
    assert [f["kind"] for f in rep["findings"]] == ["unreferenced_media"]
    assert rep["findings"][0]["path"] == "clips/stray-0.mp4"
    assert any("event-camera" in x for x in rep["info"])
    fixed = fix_dataset(ds, tmp_path / "out")
    assert (tmp_path / "out" / "clips" / f"{rid}-2.npz").read_bytes() == b"events"
    assert not (tmp_path / "out" / "clips" / "stray-0.mp4").exists()
    assert fixed["fix"]["files_dropped"] == 1


def test_poses_only_dataset_is_not_missing_its_media(pristine, tmp_path):
    ds = tmp_path / "poses"
    ds.mkdir()
    shutil.copy(pristine / "data.csv", ds / "data.csv")
    cfg = (pristine / "config.yaml").read_text().replace("poses_only: false", "")
    (ds / "config.yaml").write_text(cfg + "poses_only: true\n")
    rep = check_dataset(ds)
    assert rep["poses_only"] and rep["clean"], rep["findings"]
    assert any("poses-only" in x for x in rep["info"])
    assert rep["statistics"]["total"]["frames"] == len(bf.read_csv(ds / "data.csv", ["id"]))
    # Frame totals come from config.yaml's clip length when no video is read.
    assert rep["statistics"]["video_frames"] == 5 * 90
    # The same directory without the flag misses every file.
    (ds / "config.yaml").write_text(cfg)
    assert {f["kind"] for f in check_dataset(ds)["findings"]} == {"missing_file"}
    assert main([str(ds), "--quiet"]) == 1


def test_bad_arguments_and_unreadable_csv(tmp_path, capsys):
    assert main([str(tmp_path / "nope")]) == 1  # a missing input, as for every command
    for argv in (["--frobnicate", str(tmp_path)], [str(tmp_path), "--link"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
    (tmp_path / "data.csv").write_text("id,frame.idx\nx,1\n")
    assert main([str(tmp_path), "--quiet"]) == 1
    rep = check_dataset(tmp_path)
    assert [f["kind"] for f in rep["findings"]] == ["csv_unreadable"]
    with pytest.raises(ValueError, match="threads"):
        check_dataset(tmp_path, threads=0)


def test_joint_windows_by_hand():
    uv = np.full((3, 26, 2), np.nan)
    uv[0, :, 0], uv[0, :, 1] = np.linspace(100, 140, 26), np.linspace(50, 70, 26)
    uv[1, 0] = (5.5, 3.2)                 # one finite joint near the corner
    w = joint_windows(uv, 320, 120)
    # bbox 100..140 x 50..70, margin max(8, 0.25 * 40) = 10: [90, 40, 151, 81)
    assert w[0].tolist() == [90, 40, 151, 81]
    assert w[1].tolist() == [0, 0, 14, 12]  # floor(5.5 + 8) + 1, floor(3.2 + 8) + 1
    assert w[2].tolist() == [0, 0, 0, 0]    # nothing finite: empty window


def test_frames_past_the_media_and_a_false_in_segmentation(pristine, tmp_path):
    import re

    ds = tmp_path / "ds"
    shutil.copytree(pristine, ds)
    t, recs = _recordings(ds)
    ids = sorted(recs, key=lambda r: -len(recs[r]["rows"]))  # the longest recordings first
    lines = (ds / "data.csv").read_bytes().split(b"\n")
    flip = int(t.lines[recs[ids[0]]["rows"][5]])
    assert lines[flip - 1].endswith(b",True")
    lines[flip - 1] = lines[flip - 1][: -len(b"True")] + b"False"     # mask shows it
    late = lines[int(t.lines[recs[ids[1]]["rows"][-1]]) - 1]
    late = re.sub(rb'(\]",)(\d+)(,clips/)', rb"\g<1>95\g<3>", late, count=1)
    assert b'",95,clips/' in late
    lines.insert(len(lines) - 1, late)                               # frame 95 of 90
    (ds / "data.csv").write_bytes(b"\n".join(lines))
    rep = check_dataset(ds)
    by = {(f["kind"], f["recording"].split(" ")[0]): f for f in rep["findings"]}
    assert set(by) == {("in_segmentation_mismatch", ids[0]), ("too_few_video_frames", ids[1]),
                       ("too_short_segmentation", ids[1])}
    assert by[("in_segmentation_mismatch", ids[0])]["lines"] == [flip]
    assert "says False" in by[("in_segmentation_mismatch", ids[0])]["message"]
    assert "has 90 frames, data.csv annotates frame 95" in \
        by[("too_few_video_frames", ids[1])]["message"]
    # --fix drops the recording that runs past its media and keeps the flipped row as is.
    fix_dataset(ds, tmp_path / "out")
    kept = (tmp_path / "out" / "data.csv").read_bytes()
    assert lines[flip - 1] + b"\n" in kept and ids[1].encode() not in kept


def test_segmentation_with_dropped_duplicate_frames(tmp_path):
    """An APNG that stores identical consecutive frames once: rows find their mask frame
    by the frame delays, so the check stays clean."""
    from bsp_fast.synth import generate

    generate(tmp_path / "dd", "sample", clips=2, frames=60, size="160x96", seed=21,
             workers=1, progress=False, apng_drop_duplicates=True)
    rep = check_dataset(tmp_path / "dd")
    assert rep["clean"], rep["findings"]
    r = rep["recordings"][0]
    assert r["segmentation_frames"] < r["video_frames"] == 60
    assert r["rows_with_pedestrian_pixels"] == r["rows"] - r["fully_occluded_rows"]
