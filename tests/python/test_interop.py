"""Round trips through other tools' formats: our clips -> COCO / VideoPose3D -> back, and
training on imported detections against the native file (bsp_fast.interop)."""
import csv
import json
import shutil

import h5py
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import bsp_fast  # noqa: E402
from bsp_fast import interop as I  # noqa: E402
from bsp_fast.data import camera_intrinsics  # noqa: E402
from bsp_fast.skeleton import skeleton_map  # noqa: E402
from bsp_fast.synth.cli import main as synth_main  # noqa: E402

pytestmark = [pytest.mark.filterwarnings("ignore::UserWarning"),
              pytest.mark.filterwarnings("ignore::DeprecationWarning")]
SPLITS = ("train", "val", "test")


def _sort_data_csv(path):
    """data.csv rows ordered by (recording, camera, pedestrian, frame): the order the
    importer gives its rows, so both plan the same split (row order is not data)."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    head, body = rows[0], rows[1:]
    c = {n: head.index(n) for n in ("camera.recording", "camera.idx", "pedestrian.idx",
                                    "frame.idx")}
    body.sort(key=lambda r: (r[c["camera.recording"]], int(r[c["camera.idx"]]),
                             int(r[c["pedestrian.idx"]]), int(r[c["frame.idx"]])))
    with open(path, "w", newline="", encoding="utf-8") as fh:
        csv.writer(fh, lineterminator="\n").writerows([head] + body)


def _labels_csv(h5_path, out):
    """The per-frame crossing flags of a clip file as the importer's labels CSV."""
    seen = {}
    with h5py.File(h5_path, "r") as f:
        for s in SPLITS:
            g = f[s]
            video, track = g["meta/video_id"].asstr()[()], g["meta/pedestrian_id"].asstr()[()]
            for i in range(len(video)):
                for fr, c in zip(g["targets/frame_idx"][i], g["targets/is_crossing"][i]):
                    seen[(video[i], track[i], int(fr))] = int(c)
    with open(out, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["video", "track", "frame", "crossing"])
        w.writerows([k + (v,) for k, v in sorted(seen.items())])


def _restrict(src, dst, joints="coco17"):
    """A copy of a clip file with the 2D joints through CARLA -> joints -> CARLA (missing:
    (0, 0)), i.e. the native file on the mapped joints only."""
    shutil.copy(src, dst)
    there, back = skeleton_map("carla26", joints), skeleton_map(joints, "carla26")
    with h5py.File(dst, "r+") as f:
        for s in SPLITS:
            uv = f[s]["projection_2d"][()]
            mid, ok = there.apply(uv)
            f[s]["projection_2d"][...] = back.apply(mid, ok, fill=0.0)[0]


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    root = tmp_path_factory.mktemp("interop")
    assert synth_main([str(root / "ds"), "--preset", "sample", "--poses-only", "--workers", "1",
                       "--quiet"]) == 0
    _sort_data_csv(root / "ds" / "data.csv")
    bsp_fast.convert(root / "ds", root / "native.h5", media=False, threads=1, progress=False)
    _labels_csv(root / "native.h5", root / "labels.csv")
    return root


@pytest.fixture(scope="module")
def imported(native):
    r = native
    I.export_coco(r / "native.h5", r / "results.json", kind="results",
                  images_out=r / "images.json")
    report = I.import_coco(r / "results.json", r / "imported.h5", images=r / "images.json",
                           labels=r / "labels.csv")
    _restrict(r / "native.h5", r / "restricted.h5")
    return report


def test_imported_coco_results_are_the_native_clips_on_the_mapped_joints(native, imported):
    assert imported["skipped"] == [] and imported["joints_at_origin"] == 0
    assert len(imported["joints"]) == 17
    with h5py.File(native / "restricted.h5", "r") as a, h5py.File(native / "imported.h5") as b:
        for key in ("clip_length", "clip_stride", "label_rule", "seed", "benchmark"):
            assert a.attrs[key] == b.attrs[key]
        for s in SPLITS:
            ga, gb = a[s], b[s]
            assert len(ga["labels"]) > 0
            for name in ("projection_2d", "labels", "targets/frame_idx", "targets/is_crossing",
                         "meta/start_frame", "meta/end_frame", "meta/clip_width",
                         "meta/tte"):  # -1 in both: no benchmark windows
                assert np.array_equal(ga[name][()], gb[name][()]), (s, name)
            for name in ("meta/video_id", "meta/pedestrian_id"):
                assert list(ga[name].asstr()[()]) == list(gb[name].asstr()[()])
            uv = gb["projection_2d"][()]
            assert np.array_equal(gb["visible"][()] != 0, (uv != 0).any(-1))
            assert (gb["visible"][()].sum(-1) == 17).all()  # 15 direct + hips, neck


def test_classifier_trains_to_the_same_metrics_on_imported_and_native(native, imported):
    torch.set_num_threads(1)
    runs = {}
    for name in ("restricted", "imported"):
        runs[name] = bsp_fast.train(
            "classification", "lstm", data=native / f"{name}.h5", out=native / f"run-{name}",
            epochs=2, batch_size=8, hp={"hidden_size": 8, "num_layers": 1}, seed=5,
            quiet=True, threads=1)
    # identical inputs, labels, order and seed: bit-identical on CPU (tolerance 0)
    assert runs["restricted"].metrics == runs["imported"].metrics
    assert runs["restricted"].val == runs["imported"].val


def test_videopose3d_npz_loads_with_numpy_and_equals_the_clips(native, imported):
    r = native
    out = I.export_videopose3d(r / "native.h5", r / "vp2d.npz", r / "vp3d.npz",
                               joints="h36m17")
    d2 = np.load(r / "vp2d.npz", allow_pickle=True)
    pos2d, meta = d2["positions_2d"].item(), d2["metadata"].item()
    pos3d = np.load(r / "vp3d.npz", allow_pickle=True)["positions_3d"].item()
    assert meta["layout_name"] == "h36m" and meta["num_joints"] == 17
    assert meta["keypoints_symmetry"] == [[4, 5, 6, 11, 12, 13], [1, 2, 3, 14, 15, 16]]
    assert set(pos2d) == set(pos3d) == set(meta["video_metadata"])
    assert all(list(v) == ["custom"] for v in pos2d.values())
    m = skeleton_map("carla26", "h36m17")
    clips = I.read_clips(r / "native.h5")
    src = meta["source"]
    with h5py.File(r / "native.h5", "r") as f:
        fov = float(f.attrs["fov"])
    direct = [0, 1, 2, 3, 4, 5, 6, 8, 9, 11, 12, 13, 14, 15, 16]  # spine, head: approximated
    for s in SPLITS:
        c = clips[s]
        assert out["subjects"][s] == len(meta["subjects"][s]) > 0
        for i in range(len(c["uv"])):
            start = int(c["start"][i])
            subject = [n for n in meta["subjects"][s] if src[n]["video"] == c["video"][i]
                       and src[n]["track"] == c["track"][i]
                       and src[n]["start_frame"] <= start < src[n]["end_frame"]]
            assert len(subject) == 1
            got = pos2d[subject[0]]["custom"]
            assert isinstance(got, list) and len(got) == 1 and np.isfinite(got[0]).all()
            k = start - src[subject[0]]["start_frame"]
            got = got[0][k:k + c["uv"].shape[1]]
            want, ok = m.apply(c["uv"][i], c["present"][i])
            np.testing.assert_array_equal(got[ok], want[ok])  # seen joints: as stored
            # the camera-frame 3D projects back onto the stored 2D (OpenCV pinhole)
            xyz = pos3d[subject[0]]["custom"][k:k + len(got)].astype(np.float64)
            assert np.isfinite(xyz).all()
            K = camera_intrinsics(int(c["width"][i]), int(c["height"][i]), fov)
            uvw = xyz @ K.T
            proj = uvw[..., :2] / uvw[..., 2:]
            seen = ok[:, direct]
            np.testing.assert_allclose(proj[:, direct][seen], got[:, direct][seen], atol=2e-2)


def test_coco_annotations_round_trip(native, imported):
    r = native
    I.export_coco(r / "native.h5", r / "train.json", split="train")
    doc = json.loads((r / "train.json").read_text())
    assert doc["categories"][0]["keypoints"][0] == "nose"
    ann = doc["annotations"][0]
    assert ann["keypoints"][9:15] == [0.0, 0.0, 0, 0.0, 0.0, 0]  # ears: not labelled
    assert set(ann["keypoints"][2::3]) <= {0, 2} and ann["num_keypoints"] == 15
    report = I.import_coco(r / "train.json", r / "train_back.h5", labels=r / "labels.csv",
                           val_frac=0.0, test_frac=0.0)
    def key(g):
        return [(v, s) for v, s in zip(g["meta/video_id"].asstr()[()], g["meta/start_frame"][()])]

    with h5py.File(r / "train_back.h5") as b, h5py.File(r / "restricted.h5") as a:
        uv_a, ka = a["train/projection_2d"][()], key(a["train"])
        uv_b = np.concatenate([b[s]["projection_2d"][()] for s in SPLITS])
        kb = [k for s in SPLITS for k in key(b[s])]
    # the train clips come back (split again: each split takes at least one), joint for joint
    assert sum(report["clips"].values()) == len(ka) == len(kb)
    pos = {k: i for i, k in enumerate(kb)}
    for i, k in enumerate(ka):
        np.testing.assert_array_equal(uv_b[pos[k]], uv_a[i])
