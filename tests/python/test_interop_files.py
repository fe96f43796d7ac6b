"""Importers on small hand-written files: OpenPose and COCO JSON, labels, tracks,
thresholds, and the errors for bad input (file, record, reason; nothing written)."""
import json

import h5py
import numpy as np
import pytest

from bsp_fast import interop as I
from bsp_fast.interop.cli import main
from bsp_fast.skeleton import JOINT_INDEX as J
from bsp_fast.skeleton import joint_set

B25 = {n: i for i, n in enumerate(joint_set("body25").joints)}
W, H = 640, 360


def body25(frame, shift=0.0, low=(), zero=()):
    """(25, 3) BODY_25 joints: distinct pixels per joint and frame, confidence 0.9, 0.1
    for ``low``, 0 (OpenPose's undetected) for ``zero``."""
    kp = np.zeros((25, 3))
    kp[:, 0] = 100 + 7 * np.arange(25) + frame + shift
    kp[:, 1] = 50 + 9 * np.arange(25) + 0.5 * frame
    kp[:, 2] = 0.9
    for n in low:
        kp[B25[n], 2] = 0.1
    for n in zero:
        kp[B25[n]] = 0
    return kp


def write_openpose(folder, video, frames, people_of):
    folder.mkdir(parents=True, exist_ok=True)
    for f in frames:
        people = [{"person_id": [pid], "pose_keypoints_2d": kp.reshape(-1).tolist(),
                   "face_keypoints_2d": []} for pid, kp in people_of(f)]
        (folder / f"{video}_{f:012d}_keypoints.json").write_text(
            json.dumps({"version": 1.3, "people": people}))


def labels_file(path, rows):
    path.write_text("video,track,frame,crossing\n"
                    + "".join(f"{v},{t},{f},{c}\n" for v, t, f, c in rows))
    return path


def test_openpose_import_maps_thresholds_and_labels(tmp_path):
    op = tmp_path / "op"
    write_openpose(op, "vidA", range(8), lambda f: [(3, body25(f, low=["LWrist"],
                                                               zero=["REar"]))])
    write_openpose(op, "vidB", range(8), lambda f: [(1, body25(f, shift=50))])
    labels = labels_file(tmp_path / "l.csv",
                         [("vidA", "3", f, int(f >= 3)) for f in range(8)]
                         + [("vidB", "1", f, 0) for f in range(8)] + [("vidC", "9", 0, 1)])
    rep = I.import_openpose(op, tmp_path / "o.h5", image_size=(W, H), labels=labels,
                            clip_length=4, val_frac=0.0, test_frac=0.0, threshold=0.3)
    assert rep["rows"] == 16 and rep["tracks"] == 2 and len(rep["joints"]) == 21
    with h5py.File(tmp_path / "o.h5") as f:
        uv, vis = np.concatenate([f[s]["projection_2d"][()] for s in ("train", "val", "test")]), \
            np.concatenate([f[s]["visible"][()] for s in ("train", "val", "test")])
        vids = [v for s in ("train", "val", "test") for v in f[s]["meta/video_id"].asstr()[()]]
        starts = np.concatenate([f[s]["meta/start_frame"][()] for s in ("train", "val", "test")])
        labels_out = np.concatenate([f[s]["labels"][()] for s in ("train", "val", "test")])
        assert f.attrs["source_format"] == "body25" and f.attrs["visibility_threshold"] == 0.3
        assert f.attrs["labels_source"] == "csv"
        assert f["train/meta/clip_width"][0] == W
    assert len(vids) == 4  # 2 tracks x 2 clips of 4 frames
    for i, (video, start) in enumerate(zip(vids, starts)):
        kp = body25(start, shift=0.0 if video == "vidA" else 50.0)
        np.testing.assert_array_equal(uv[i, 0, J["crl_hips__C"]], kp[B25["MidHip"], :2]
                                      .astype(np.float32))
        np.testing.assert_array_equal(uv[i, 0, J["crl_toeEnd__L"]],
                                      kp[B25["LSmallToe"], :2].astype(np.float32))
        assert not vis[i, :, J["crl_spine__C"]].any()
        assert (uv[i, :, J["crl_spine__C"]] == 0).all()  # missing: the loaders' (0, 0)
        assert vis[i, :, J["crl_hand__L"]].any() == (video == "vidB")  # 0.1 < 0.3 in vidA
        assert labels_out[i] == int(video == "vidA" and start + 3 >= 3)  # last frame's label


def test_untracked_people_need_a_tracker_or_best(tmp_path):
    op = tmp_path / "op"
    write_openpose(op, "v", range(4), lambda f: [(-1, body25(f)),
                                                 (-1, body25(f, shift=150, low=["Nose"]))])
    with pytest.raises(I.BadInput, match=r"v_000000000000_keypoints.json: people\[0\]: 2 people "
                                         r"without person_id in this frame; run OpenPose with "
                                         r"--tracking 1"):
        I.import_openpose(op, tmp_path / "o.h5", image_size=(W, H), clip_length=4)
    assert not (tmp_path / "o.h5").exists()
    I.import_openpose(op, tmp_path / "o.h5", image_size=(W, H), clip_length=4, tracks="best")
    with h5py.File(tmp_path / "o.h5") as f:
        g = f["train"]
        assert list(g["meta/pedestrian_id"].asstr()[()]) == ["0"]
        assert f.attrs["labels_source"] == "none" and not g["labels"][()].any()
        assert g["projection_2d"][0, 0, J["crl_Head__C"], 0] == body25(0)[0, 0]  # higher score


def coco_files(tmp_path, frames=6, tracks=(("v1", 4),), extra=None):
    images, results = [], []
    for video, track in tracks:
        for f in range(frames):
            iid = len(images) + 1
            images.append({"id": iid, "file_name": f"{video}/{f:06d}.jpg", "width": W,
                           "height": H})
            kp = np.c_[100 + np.arange(17) * 3.0 + f, 40 + np.arange(17) * 5.0,
                       np.full(17, 0.8)]
            results.append({"image_id": iid, "category_id": 1, "score": 0.9,
                            "keypoints": kp.reshape(-1).tolist(), "track_id": track})
    if extra:
        extra(images, results)
    (tmp_path / "images.json").write_text(json.dumps({"images": images}))
    (tmp_path / "res.json").write_text(json.dumps(results))
    return tmp_path / "res.json", tmp_path / "images.json"


def test_coco_results_use_image_names_for_video_and_frame(tmp_path):
    res, images = coco_files(tmp_path, frames=6)
    I.import_coco(res, tmp_path / "o.h5", images=images, clip_length=3)
    with h5py.File(tmp_path / "o.h5") as f:
        g = f["train"]
        frames = g["targets/frame_idx"][()]
        uv = g["projection_2d"][()]
        assert set(g["meta/video_id"].asstr()[()]) == {"v1"}
    assert sorted(frames[:, 0].tolist()) == [0, 3]
    i = int(np.argmin(frames[:, 0]))
    # hips = mid-point of the COCO hips (joints 11, 12): x = 100 + 34.5, y = 40 + 57.5
    np.testing.assert_array_equal(uv[i, 0, J["crl_hips__C"]], [134.5, 97.5])
    np.testing.assert_array_equal(uv[i, 0, J["crl_thigh__R"]], [136.0, 100.0])


def _no_output(tmp_path, name="o.h5"):
    return not (tmp_path / name).exists() and not list(tmp_path.glob(f".{name}.tmp-*"))


@pytest.mark.parametrize("text, match", [
    ('[{"image_id": 1, ', r"res.json: malformed JSON at line 1 column \d+"),
    ('{"foo": 1}', r"res.json: expected a COCO results list"),
])
def test_malformed_json_is_a_clear_error_and_writes_nothing(tmp_path, capsys, text, match):
    res, images = coco_files(tmp_path)
    res.write_text(text)
    assert main(["import", "coco", str(res), str(tmp_path / "o.h5"), "--images", str(images),
                 "--clip-length", "3"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("bsp-interop: ") and __import__("re").search(match, err), err
    assert _no_output(tmp_path)


def test_bad_records_name_the_record(tmp_path):
    def short_keypoints(images, results):
        results[4]["keypoints"] = results[4]["keypoints"][:50]
    res, images = coco_files(tmp_path, extra=short_keypoints)
    with pytest.raises(I.BadInput, match=r"res.json: record 4: keypoints \(coco17\) has 50 "
                                         r"values, expected 51"):
        I.import_coco(res, tmp_path / "o.h5", images=images, clip_length=3)
    res, images = coco_files(tmp_path, extra=lambda i, r: r[2].update(image_id=99))
    with pytest.raises(I.BadInput, match="record 2: image_id 99 is not in the images list"):
        I.import_coco(res, tmp_path / "o.h5", images=images, clip_length=3)
    with pytest.raises(I.BadInput, match="pass the COCO-style JSON of those images"):
        I.import_coco(res, tmp_path / "o.h5", clip_length=3)
    res, images = coco_files(tmp_path, extra=lambda i, r: r.append(dict(r[0])))
    with pytest.raises(I.BadInput, match="video 'v1' track '4' frame 0 appears twice"):
        I.import_coco(res, tmp_path / "o.h5", images=images, clip_length=3)
    assert _no_output(tmp_path)


def test_unknown_joint_sets_are_option_errors(tmp_path, capsys):
    res, images = coco_files(tmp_path)
    assert main(["import", "coco", str(res), str(tmp_path / "o.h5"), "--images", str(images),
                 "--joints", "mpii"]) == 2
    assert "unknown joint set 'mpii'; allowed: carla26, coco17, body25, h36m17, smpl24" in \
        capsys.readouterr().err
    assert _no_output(tmp_path)
    with pytest.raises(ValueError, match="unknown joint set 'foo'"):
        I.export_coco(tmp_path / "x.h5", tmp_path / "x.json", joints="foo")


def test_tracks_shorter_than_a_clip(tmp_path, capsys):
    res, images = coco_files(tmp_path, frames=5, tracks=(("v1", 4), ("v2", 8)),
                             extra=lambda i, r: r.pop(7))  # v2 frame 2: runs of 2 and 2
    argv = ["import", "coco", str(res), str(tmp_path / "o.h5"), "--images", str(images),
            "--clip-length", "3"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "1 track(s) shorter than a clip: video 'v2' track '8': longest run of " \
           "consecutive frames 2 < clip length 3" in err and "nothing written" in err
    assert _no_output(tmp_path)
    assert main(argv + ["--skip-short-tracks", "--quiet"]) == 0
    with h5py.File(tmp_path / "o.h5") as f:
        assert set(f["train/meta/video_id"].asstr()[()]) == {"v1"}
    assert main(argv + ["--skip-short-tracks"]) == 3  # exists: --force


def test_labels_must_cover_every_detection(tmp_path):
    res, images = coco_files(tmp_path, frames=4)
    labels = labels_file(tmp_path / "l.csv", [("v1", "4", f, 0) for f in (0, 1, 3)])
    with pytest.raises(I.BadInput, match=r"labels: no row for video 'v1' track '4' frame 2 "
                                         r"\(.*record 2"):
        I.import_coco(res, tmp_path / "o.h5", images=images, labels=labels, clip_length=3)
    (tmp_path / "bad.csv").write_text("video,track,frame,crossing\nv1,4,zero,1\n")
    with pytest.raises(I.BadInput, match="bad.csv: line 2: expected video,track,frame"):
        I.read_labels(tmp_path / "bad.csv")
    assert _no_output(tmp_path)


def test_options_are_checked(tmp_path):
    res, images = coco_files(tmp_path)
    with pytest.raises(ValueError, match="label must be 'last' or 'any:F'"):
        I.import_coco(res, tmp_path / "o.h5", images=images, label="first")
    with pytest.raises(ValueError, match="tracks must be 'require' or 'best'"):
        I.import_coco(res, tmp_path / "o.h5", images=images, tracks="all")
    with pytest.raises(ValueError, match="image_size .* is needed"):
        I.import_openpose(tmp_path, tmp_path / "o.h5", image_size=None)
    assert _no_output(tmp_path)
