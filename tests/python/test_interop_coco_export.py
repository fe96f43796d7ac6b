"""bsp-interop export coco: the COCO person category (19-edge skeleton), info, licenses,
integer ids, COCOeval of the ground truth as detections (AP 1.0), --write-images."""
import json

import numpy as np
import pytest

from bsp_fast.data.testing import write_clip_file
from bsp_fast.interop import export_coco
from bsp_fast.interop.cli import main

COCO_PERSON_SKELETON = [[16, 14], [14, 12], [17, 15], [15, 13], [12, 13], [6, 12], [7, 13],
                        [6, 7], [6, 8], [7, 9], [8, 10], [9, 11], [2, 3], [1, 2], [1, 3],
                        [2, 4], [3, 5], [4, 6], [5, 7]]


@pytest.fixture
def clips(tmp_path):
    path = tmp_path / "clips.h5"
    write_clip_file(path, clips=(4, 2, 2), clip_length=8, media=True, crop_size=32)
    return path


def test_annotations_are_a_coco_keypoints_file(tmp_path, clips):
    assert main(["export", "coco", str(clips), str(tmp_path / "a.json"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    assert set(doc) >= {"info", "licenses", "images", "annotations", "categories"}
    assert isinstance(doc["info"], dict) and "description" in doc["info"]
    assert isinstance(doc["licenses"], list) and doc["licenses"][0]["id"] == 1
    cat = doc["categories"][0]
    assert cat["id"] == 1 and cat["name"] == "person" and len(cat["keypoints"]) == 17
    assert cat["skeleton"] == COCO_PERSON_SKELETON
    for a in doc["annotations"]:
        assert all(isinstance(a[k], int) and not isinstance(a[k], bool)
                   for k in ("id", "image_id", "category_id", "track_id", "iscrowd",
                             "num_keypoints"))
    assert len({a["id"] for a in doc["annotations"]}) == len(doc["annotations"])
    assert all(isinstance(im["id"], int) for im in doc["images"])


def test_non_numeric_track_names_get_integer_ids_and_come_back(tmp_path, clips):
    import h5py

    from bsp_fast.interop import read_coco

    with h5py.File(clips, "r+") as f:  # JAAD-style pedestrian ids
        for s in ("train", "val", "test"):
            n = len(f[s]["labels"])
            del f[s]["meta/pedestrian_id"]
            f[s].create_dataset("meta/pedestrian_id", data=["0_1_3b"] * n,
                                dtype=h5py.string_dtype())
    export_coco(clips, tmp_path / "a.json")
    doc = json.loads((tmp_path / "a.json").read_text())
    assert {type(a["track_id"]) for a in doc["annotations"]} == {int}
    assert {a["track_name"] for a in doc["annotations"]} == {"0_1_3b"}
    assert set(read_coco(tmp_path / "a.json").track) == {"0_1_3b"}


def test_cocoeval_of_ground_truth_as_detections_is_ap_1(tmp_path, clips, capsys):
    pytest.importorskip("pycocotools")
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gt_path, res_path = tmp_path / "gt.json", tmp_path / "res.json"
    export_coco(clips, gt_path)
    export_coco(clips, res_path, kind="results", images_out=tmp_path / "images.json")
    gt = COCO(str(gt_path))
    dt = gt.loadRes(str(res_path))
    ev = COCOeval(gt, dt, iouType="keypoints")
    ev.evaluate()
    ev.accumulate()
    ev.summarize()
    assert ev.stats[0] == pytest.approx(1.0)  # AP @ OKS 0.50:0.95
    assert ev.stats[5] == pytest.approx(1.0)  # AR


def test_write_images_writes_the_jpegs_file_name_names(tmp_path, clips):
    cv2 = pytest.importorskip("cv2")
    out = tmp_path / "imgs"
    assert main(["export", "coco", str(clips), str(tmp_path / "a.json"), "--write-images",
                 str(out), "--quiet"]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    assert len(list(out.rglob("*.jpg"))) == len(doc["images"])
    for im in doc["images"][:5]:
        pic = cv2.imread(str(out / im["file_name"]))
        assert pic is not None and pic.shape == (im["height"], im["width"], 3)
        assert pic.max() > 0  # the crop is pasted in
    # the person's keypoints fall on the pasted crop, not on the black background
    a = doc["annotations"][0]
    im = next(i for i in doc["images"] if i["id"] == a["image_id"])
    pic = cv2.imread(str(out / im["file_name"]))
    kp = np.array(a["keypoints"]).reshape(-1, 3)
    x, y = kp[kp[:, 2] > 0, :2].mean(0).astype(int)
    assert pic[y, x].max() > 0


def test_write_images_without_media_is_one_clear_error(tmp_path, capsys):
    path = tmp_path / "c.h5"
    write_clip_file(path, clips=(4, 2, 2), clip_length=8)
    rc = main(["export", "coco", str(path), str(tmp_path / "a.json"), "--write-images",
               str(tmp_path / "imgs")])
    err = capsys.readouterr().err.replace(str(tmp_path), "TMP")
    assert rc == 1 and "no media frames" in err and "--write-images" in err
    assert "images_dir" not in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5"]
    # the images folder is an output: it must not be the input or hold it
    rc = main(["export", "coco", str(path), str(tmp_path / "b.json"), "--write-images",
               str(tmp_path)])
    assert rc == 2


def test_area_and_segmentation_from_the_masks(tmp_path, clips):
    """A clip file with media: each annotation's segmentation is the pedestrian's pixels
    of its crop (mask tag 4) put back in the image, as RLE that pycocotools decodes, and
    its area that of the segmentation; the crop's own pixels agree."""
    mask_utils = pytest.importorskip("pycocotools.mask")
    import h5py

    export_coco(clips, tmp_path / "a.json")
    doc = json.loads((tmp_path / "a.json").read_text())
    images = {im["id"]: im for im in doc["images"]}
    with h5py.File(clips, "r") as f:
        g = f["train"]
        box = g["frames/crop_box"][0].astype(int)
        crop = g["frames/mask"][0] == 4
        video = g["meta/video_id"].asstr()[0]
        track, frame = g["meta/pedestrian_id"].asstr()[0], int(g["frames/frame_idx"][0])
    a = next(a for a in doc["annotations"]
             if images[a["image_id"]]["video"] == video and images[a["image_id"]]["frame"]
             == frame and a.get("track_name", str(a["track_id"])) == track)
    im = images[a["image_id"]]
    rle = mask_utils.frPyObjects(a["segmentation"], im["height"], im["width"])
    m = mask_utils.decode(rle)
    assert m.shape == (im["height"], im["width"]) and a["area"] == float(m.sum()) > 0
    assert float(mask_utils.area(rle)) == a["area"]
    u0, v0, u1, v1 = box
    assert not m[:max(v0, 0)].any() and not m[:, :max(u0, 0)].any()  # inside the crop box
    scale = ((min(v1, im["height"]) - max(v0, 0)) * (min(u1, im["width"]) - max(u0, 0))
             / crop.size)
    assert a["area"] == pytest.approx(crop.sum() * scale, rel=0.15)


def test_round_trip_keeps_split_and_labels(tmp_path):
    """export coco then import coco: each video in the split it came from, each frame's
    crossing label back without --labels."""
    import h5py

    path = tmp_path / "c.h5"
    write_clip_file(path, clips=(8, 4, 4), clip_length=8)
    with h5py.File(path, "r+") as f:  # one split per video, as bsp-convert splits
        for s in ("train", "val", "test"):
            v = [f"{s}_{x}" for x in f[s]["meta/video_id"].asstr()[()]]
            del f[s]["meta/video_id"]
            f[s].create_dataset("meta/video_id", data=v, dtype=h5py.string_dtype())
    assert main(["export", "coco", str(path), str(tmp_path / "a.json"), "--quiet"]) == 0
    assert main(["import", "coco", str(tmp_path / "a.json"), str(tmp_path / "b.h5"),
                 "--clip-length", "8", "--quiet"]) == 0

    def frames(p):
        out = {}
        with h5py.File(p, "r") as f:
            for s in ("train", "val", "test"):
                g = f[s]
                for v, t, fr, c in zip(g["meta/video_id"].asstr()[()],
                                       g["meta/pedestrian_id"].asstr()[()],
                                       g["targets/frame_idx"][()], g["targets/is_crossing"][()]):
                    out.update({(s, v, t, int(a)): int(b) for a, b in zip(fr, c)})
            return out, f.attrs.get("labels_source"), json.loads(f.attrs.get("settings_json",
                                                                              "{}"))
    src, _, _ = frames(path)
    back, labels, settings = frames(tmp_path / "b.h5")
    assert labels == "records" and settings["split_rule"] == "source"
    assert back and set(back) <= set(src)
    assert {k: src[k] for k in back} == back and any(back.values())
    assert {k[:2] for k in back} == {k[:2] for k in src}  # every video, in its split
