"""bsp-interop import jaad|pie: official-format annotation folders written here (CVAT XML as
JAAD's jaad_data.py and PIE's pie_data.py read them), OpenPose JSON or the benchmark's pose
pickles, the PedestrianActionBenchmark's windows, splits and labels, training on the
result, the error cases, and the restricted unpickler."""
import json
import os
import pickle

import h5py
import numpy as np
import pytest

from bsp_fast.interop import safe_pickle
from bsp_fast.interop.cli import main

SPLITS = ("train", "val", "test")
FRAMES = 120


def _box(frame, k):
    x = 150.0 + 450.0 * k + 2.0 * frame
    return [x, 400.0, x + 120.0, 760.0]


def _xml_track(label, pid, frames, k, cross=None, outside_last=False):
    boxes = []
    for f in frames:
        x1, y1, x2, y2 = _box(f, k)
        out = int(outside_last and f == frames[-1])
        attrs = f'<attribute name="id">{pid}</attribute><attribute name="occlusion">none</attribute>'
        if cross is not None:
            c = "crossing" if cross and f >= cross else "not-crossing"
            attrs += (f'<attribute name="cross">{c}</attribute><attribute name="action">walking'
                      '</attribute><attribute name="look">not-looking</attribute>'
                      + "".join(f'<attribute name="{n}">__undefined__</attribute>'
                                for n in ("nod", "hand_gesture", "reaction", "gesture")))
        boxes.append(f'<box frame="{f}" keyframe="1" occluded="0" outside="{out}" xtl="{x1}" '
                     f'ytl="{y1}" xbr="{x2}" ybr="{y2}">{attrs}</box>')
    return f'<track label="{label}">{"".join(boxes)}</track>'


def _xml(name, tracks):
    meta = (f"<meta><task><name>{name}</name><size>{FRAMES}</size><original_size><width>1920"
            "</width><height>1080</height></original_size></task></meta>")
    return f"<annotations><version>1.1</version>{meta}{''.join(tracks)}</annotations>"


def _attrs(peds):
    return "<ped_attributes>" + "".join(
        f'<pedestrian age="adult" crossing="{c}" crossing_point="{p}" id="{pid}" '
        'gender="male" />' for pid, c, p in peds) + "</ped_attributes>"


def _pose(frame, k, rng):
    """BODY_25 pixels inside the box of pedestrian ``k`` at ``frame``; feet undetected."""
    x1, y1, x2, y2 = _box(frame, k)
    pts = np.stack([x1 + (x2 - x1) * rng.uniform(0.2, 0.8, 25),
                    y1 + (y2 - y1) * np.linspace(0.05, 0.95, 25)], 1)
    conf = np.full(25, 0.9)
    conf[19:] = 0.0
    return pts, conf


# JAAD: video -> [(label, pid, slot, crossing attr, crossing_point)]
JAAD = {"video_0001": [("pedestrian", "0_1_1b", 0, 1, 100), ("pedestrian", "0_1_2b", 1, 0, 110),
                       ("ped", "0_1_3", 2, None, None), ("people", "0_1_4p", 3, None, None)],
        "video_0002": [("pedestrian", "0_2_1b", 0, 0, -1), ("ped", "0_2_2", 1, None, None)],
        "video_0003": [("pedestrian", "0_3_1b", 0, 1, 90)]}
JAAD_SPLIT = {"train": "video_0001", "val": "video_0002", "test": "video_0003"}
MISSING_POSE = {("video_0001", "0_1_1b"): range(50, 53)}


def _jaad(root, with_splits=True):
    (root / "annotations").mkdir(parents=True)
    (root / "annotations_attributes").mkdir()
    ops = root / "openpose"
    ops.mkdir()
    rng = np.random.default_rng(0)
    frames = list(range(FRAMES))
    for video, peds in JAAD.items():
        tracks = [_xml_track(lab, pid, frames, k, cross=(p if c == 1 else 0)
                             if lab == "pedestrian" else None) for lab, pid, k, c, p in peds]
        (root / "annotations" / f"{video}.xml").write_text(_xml(video, tracks))
        (root / "annotations_attributes" / f"{video}_attributes.xml").write_text(
            _attrs([(pid, c, p) for lab, pid, _, c, p in peds if lab == "pedestrian"]))
        for f in frames:
            people = []
            for _, pid, k, _, _ in peds:
                if f in MISSING_POSE.get((video, pid), ()):
                    continue
                pts, conf = _pose(f, k, rng)
                people.append({"person_id": [-1], "pose_keypoints_2d":
                               np.concatenate([pts, conf[:, None]], 1).ravel().tolist()})
            decoy = np.concatenate([np.full((25, 1), 1800.0), np.linspace(50, 300, 25)[:, None],
                                    np.full((25, 1), 0.8)], 1)
            people.insert(0, {"person_id": [-1], "pose_keypoints_2d": decoy.ravel().tolist()})
            (ops / f"{video}_{f:012d}_keypoints.json").write_text(
                json.dumps({"version": 1.3, "people": people}))
    if with_splits:
        (root / "split_ids" / "default").mkdir(parents=True)
        for s, v in JAAD_SPLIT.items():
            (root / "split_ids" / "default" / f"{s}.txt").write_text(v + "\n")
    return root


# PIE: set -> [(pid, slot, crossing attr, crossing_point)] (one video_0001 per set)
PIE = {"set01": [("1_1_1", 0, 1, 100), ("1_1_2", 1, 0, 116)],
       "set05": [("5_1_1", 0, -1, 110)], "set03": [("3_1_1", 0, 1, 95)]}


def _pie(root, pickle_bytes=None):
    rng = np.random.default_rng(1)
    frames = list(range(FRAMES))
    poses = root / "poses"
    poses.mkdir(parents=True)
    for set_id, peds in PIE.items():
        for sub in ("annotations", "annotations_attributes"):
            (root / sub / set_id).mkdir(parents=True)
        tracks = [_xml_track("pedestrian", pid, frames, k, cross=p if c == 1 else 0,
                             outside_last=True) for pid, k, c, p in peds]
        tracks.append(_xml_track("vehicle", f"{set_id}_car", frames[:10], 3))
        (root / "annotations" / set_id / "video_0001_annt.xml").write_text(
            _xml("video_0001", tracks))
        (root / "annotations_attributes" / set_id / "video_0001_attributes.xml").write_text(
            _attrs([(pid, c, p) for pid, _, c, p in peds]))
        table = {}
        for pid, k, _, _ in peds:
            for f in frames:
                if f % 10 == 3:
                    continue  # no pose found for this frame
                pts, _ = _pose(f, k, rng)
                coco18 = pts[[0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18]]
                coco18 = coco18 / np.array([1920.0, 1080.0])
                coco18[16:] = 0.0  # ears undetected
                table[f"{f:05d}_{pid}"] = coco18.ravel()
        data = pickle.dumps({"video_0001": table}) if pickle_bytes is None else pickle_bytes
        (poses / f"pose_{set_id}.pkl").write_bytes(data)
    return root


def _read(path):
    with h5py.File(path, "r") as f:
        out = {"attrs": dict(f.attrs)}
        for s in SPLITS:
            g = f[s]
            out[s] = dict(video=g["meta/video_id"].asstr()[()], ped=g["meta/pedestrian_id"].asstr()[()],
                          start=g["meta/start_frame"][()], end=g["meta/end_frame"][()],
                          tte=g["meta/tte"][()], labels=g["labels"][()],
                          frames=g["targets/frame_idx"][()], uv=g["projection_2d"][()],
                          visible=g["visible"][()])
    return out


def _check_windows(data, stride, event_of, label_of):
    for s in SPLITS:
        d = data[s]
        assert d["uv"].shape[1:] == (16, 26, 2)
        assert np.all(np.diff(d["frames"], axis=1) == 1)  # 16 consecutive frames
        assert d["tte"].dtype == np.int32  # as bsp-convert --benchmark writes meta/tte
        for i in range(len(d["labels"])):
            ev = event_of[d["ped"][i]]
            assert d["tte"][i] == ev - (d["end"][i] - 1)
            assert 30 <= d["tte"][i] <= 60
            assert d["labels"][i] == label_of[d["ped"][i]]
        for ped in set(d["ped"]):
            starts = np.sort(d["start"][d["ped"] == ped])
            assert len(starts) == 30 // stride + 1
            assert np.all(np.diff(starts) == stride)
            assert sorted(d["tte"][d["ped"] == ped]) == list(range(60 - stride * (len(starts) - 1),
                                                                    61, stride))


def test_jaad_openpose_benchmark_windows_labels_split(tmp_path, capsys):
    root = _jaad(tmp_path / "jaad")
    out = tmp_path / "jaad.h5"
    assert main(["import", "jaad", str(root), str(out), "--openpose", str(root / "openpose"),
                 "--stats"]) == 0
    text = capsys.readouterr().out
    assert "missing joints over the imported windows:" in text and "%" in text
    data = _read(out)
    ends = {pid: (len(range(FRAMES)) - 3 if p in (None, -1) else p)
            for peds in JAAD.values() for _, pid, _, _, p in peds}
    labels = {pid: int(c == 1) for peds in JAAD.values() for _, pid, _, c, _ in peds}
    _check_windows(data, 3, ends, labels)  # overlap 0.8: int(0.2 * 16) = 3
    for s, video in JAAD_SPLIT.items():
        assert set(data[s]["video"]) == {video}
    # beh subset: the behaviour pedestrians only, 11 windows each (TTE 60, 57, ..., 30)
    assert sorted(set(data["train"]["ped"])) == ["0_1_1b", "0_1_2b"]
    assert len(data["train"]["labels"]) == 22 and len(data["val"]["labels"]) == 11
    assert list(data["train"]["labels"]).count(1) == 11
    assert data["attrs"]["dataset"] == "jaad" and data["attrs"]["split_rule"] == "fixed"
    # the decoy person (top right) is never taken; a pedestrian's own pose is
    vis = data["train"]["visible"].astype(bool)
    assert np.all(data["train"]["uv"][..., 0][vis] < 1000)
    # the frames without a pose for 0_1_1b have no visible joint
    sel = data["train"]["ped"] == "0_1_1b"
    gaps = np.isin(data["train"]["frames"][sel], [50, 51, 52])
    assert gaps.any() and not vis[sel][gaps].any() and vis[sel][~gaps].any(-1).all()
    # all: the pedestrians without behaviour labels too (label 0, end 3 frames before last)
    out2 = tmp_path / "jaad_all.h5"
    assert main(["import", "jaad", str(root), str(out2), "--openpose", str(root / "openpose"),
                 "--subset", "all", "--quiet"]) == 0
    d2 = _read(out2)
    assert "0_1_3" in set(d2["train"]["ped"]) and "0_1_4p" not in set(d2["train"]["ped"])
    _check_windows(d2, 3, ends, labels)


def test_jaad_without_split_files_is_a_seeded_split_by_video(tmp_path, capsys):
    root = _jaad(tmp_path / "jaad", with_splits=False)
    out = tmp_path / "jaad.h5"
    assert main(["import", "jaad", str(root), str(out), "--openpose", str(root / "openpose"),
                 "--seed", "3"]) == 0
    assert "seeded split by video" in capsys.readouterr().out
    data = _read(out)
    where = {}
    for s in SPLITS:
        for v in data[s]["video"]:
            where.setdefault(v, set()).add(s)
    assert set(where) == set(JAAD) and all(len(s) == 1 for s in where.values())
    assert data["attrs"]["split_rule"] == "seeded by video"


def test_pie_pickles_set_split_windows_and_training(tmp_path, capsys):
    import bsp_fast

    root = _pie(tmp_path / "pie")
    out = tmp_path / "pie.h5"
    assert main(["import", "pie", str(root), str(out), "--poses", str(root / "poses"),
                 "--stats"]) == 0
    text = capsys.readouterr().out
    assert "every 6 frames" in text and "missing joints" in text
    data = _read(out)
    events = {pid: p for peds in PIE.values() for pid, _, _, p in peds}
    labels = {pid: int(c == 1) for peds in PIE.values() for pid, _, c, _ in peds}
    _check_windows(data, 6, events, labels)  # overlap 0.6: int(0.4 * 16) = 6
    assert set(data["train"]["video"]) == {"set01/video_0001"}
    assert set(data["val"]["video"]) == {"set05/video_0001"}
    assert set(data["test"]["video"]) == {"set03/video_0001"}
    assert [len(data[s]["labels"]) for s in SPLITS] == [12, 6, 6]
    assert list(data["val"]["labels"]) == [0] * 6  # crossing -1 (irrelevant) is 0
    # pickled poses are normalised: scaled back to pixels inside the pedestrian's box
    d = data["train"]
    vis = d["visible"].astype(bool)
    for i in range(len(d["labels"])):
        k = [x[1] for x in PIE["set01"] if x[0] == d["ped"][i]][0]
        for t, f in enumerate(d["frames"][i]):
            x1, y1, x2, y2 = _box(f, k)
            u = d["uv"][i, t][vis[i, t]]
            assert (f % 10 == 3) == (len(u) == 0)
            assert np.all((u[:, 0] >= x1 - 1e-3) & (u[:, 0] <= x2 + 1e-3))
    run = bsp_fast.train("classification", "lstm", data=str(out), epochs=1, batch_size=4,
                         limit_batches=2, quiet=True, hp={"hidden_size": 8, "num_layers": 1},
                         out=str(tmp_path / "run"))
    assert run is not None
    # the report's classification table runs on it too (smoke: plumbing only)
    from bsp_fast.reproduction import main as reproduce

    capsys.readouterr()
    assert reproduce(["classification", "--data", str(out), "--budget", "smoke", "--out",
                      str(tmp_path / "tables"), "--rows", "lstm-perfect,lstm-mjp0.7187"]) == 0
    table = capsys.readouterr().out
    assert "smoke budget: plumbing only" in table and "| lstm-mjp0.7187 |" in table


class Custom:
    def __init__(self):
        self.x = 1


class Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _fails(capsys, argv, out, *needles):
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]
    assert not out.exists() and not list(out.parent.glob(f".{out.name}*"))


def test_errors_name_the_file_and_write_nothing(tmp_path, capsys):
    root = _jaad(tmp_path / "jaad")
    out = tmp_path / "x.h5"
    ops = ["--openpose", str(root / "openpose")]
    bad = root / "annotations" / "video_0002.xml"
    good = bad.read_text()
    bad.write_text(good[:500])
    _fails(capsys, ["import", "jaad", str(root), str(out)] + ops, out, str(bad), "malformed XML")
    bad.write_text(good)
    (root / "split_ids" / "default" / "test.txt").write_text("video_0003\nvideo_0009\n")
    _fails(capsys, ["import", "jaad", str(root), str(out)] + ops, out,
           str(root / "annotations" / "video_0009.xml"), "test.txt")
    marker = tmp_path / "pwned"
    proot = _pie(tmp_path / "pie", pickle_bytes=pickle.dumps({"video_0001": Evil(marker)}))
    _fails(capsys, ["import", "pie", str(proot), str(out), "--poses", str(proot / "poses")],
           out, "pose_set01.pkl", "refused class", "system")
    assert not marker.exists()


def test_pie_refuses_what_pie_data_refuses(tmp_path, capsys):
    """An attribute value pie_data.py does not map, a crossing point that is not one of
    the pedestrian's frames inside the image: one line each, exit 1, as the official
    code stops (KeyError, ValueError) instead of importing without them."""
    root = _pie(tmp_path / "pie")
    out = tmp_path / "x.h5"
    argv = ["import", "pie", str(root), str(out), "--poses", str(root / "poses")]
    xml = root / "annotations" / "set03" / "video_0001_annt.xml"
    good = xml.read_text()
    xml.write_text(good.replace('<attribute name="look">not-looking</attribute>',
                                '<attribute name="look">glancing</attribute>', 1))
    _fails(capsys, argv, out, str(xml), "pedestrian '3_1_1'", "frame 0",
           "look: 'glancing', not one of not-looking, looking", "pie_data.py")
    xml.write_text(good)
    attrs = root / "annotations_attributes" / "set03" / "video_0001_attributes.xml"
    attrs.write_text(attrs.read_text().replace('crossing_point="95"',
                                               f'crossing_point="{FRAMES - 1}"'))
    _fails(capsys, argv, out, str(attrs), f"crossing_point {FRAMES - 1} is not one of its "
           "annotated frames inside the image")  # the last box is outside="1"


def test_restricted_unpickler(tmp_path):
    data = {"video_0001": {"00001_1_1_1": np.arange(36.0), "s": np.float64(2.5)},
            "o": [np.zeros((2, 3), np.float32), (1, "a"), {1, 2}]}
    for protocol in (2, 4, 5):
        back = safe_pickle.loads(pickle.dumps(data, protocol=protocol))
        assert np.array_equal(back["video_0001"]["00001_1_1_1"], np.arange(36.0))
        assert back["o"][0].dtype == np.float32 and back["o"][2] == {1, 2}
    marker = tmp_path / "pwned"
    with pytest.raises(safe_pickle.RefusedPickle, match=r"refused class (posix|os|nt)\.system"):
        safe_pickle.loads(pickle.dumps(Evil(marker)))
    assert not marker.exists()
    with pytest.raises(safe_pickle.RefusedPickle, match=r"refused class .*Custom"):
        safe_pickle.loads(pickle.dumps({"a": Custom()}))
    path = tmp_path / "p.pkl"
    path.write_bytes(pickle.dumps([Custom()]))
    with pytest.raises(safe_pickle.RefusedPickle, match="p.pkl: refused class"):
        safe_pickle.load_file(path)
    with pytest.raises(safe_pickle.RefusedPickle, match="not a valid pickle"):
        safe_pickle.loads(b"\x80\x04garbage")
