"""PIE's official annotations -> a clip file (``bsp-interop import pie``, docs/interop.md).

Read as PIE's own interface (``utilities/pie_data.py``) reads them:
``ROOT/annotations/SET/VIDEO_annt.xml`` (CVAT tracks; the ``pedestrian`` tracks' ``<box
frame xtl ytl xbr ybr outside>`` with ``id``, ``occlusion``, ``action``, ``look``,
``gesture``, ``cross`` attributes per frame; boxes with ``outside="1"`` are left out) and
``ROOT/annotations_attributes/SET/VIDEO_attributes.xml`` (``<pedestrian id crossing
crossing_point critical_point intention_prob ...>``). PIE's split is by set: set01,
set02, set04 train, set05, set06 val, set03 test.

Samples as the PedestrianActionBenchmark's ``crossing`` sequences: every pedestrian's
track ends at its ``crossing_point`` (PIE sets it 3 frames before the last where the
pedestrian does not cross); label 1 when ``crossing`` is 1 (0 and -1, irrelevant: 0).
Videos are named ``SET/VIDEO``. Windows: :mod:`.benchmark_windows`. What pie_data.py
refuses is refused here too, in one line: an occlusion, action, look, gesture or cross
value it does not map, a crossing point that is not one of the pedestrian's frames.
"""
from __future__ import annotations

from pathlib import Path

from .annotation_xml import (check_values, crossing_attributes, parse_xml, track_boxes,
                             video_size)
from .benchmark_annotations import (BENCHMARK, OpenPoseFrames, PickledPoses, Track,
                                    check_options, import_tracks, refuse_existing)
from .readers import BadInput

__all__ = ["SET_SPLIT", "read_pie", "import_pie"]

#: PIE's default split (pie_data.py ``_get_image_set_ids``)
SET_SPLIT = {"set01": "train", "set02": "train", "set04": "train",
             "set05": "val", "set06": "val", "set03": "test"}


def _attributes(path: Path) -> dict:
    return crossing_attributes(path, "PIE attributes")


#: the values pie_data.py maps (``_map_text_to_scalar``) on every box of a pedestrian
#: inside the frame
VALUES = {"occlusion": ("none", "part", "full"), "action": ("standing", "walking"),
          "look": ("not-looking", "looking"),
          "gesture": ("__undefined__", "hand_ack", "hand_yield", "hand_rightofway", "nod",
                      "other"),
          "cross": ("not-crossing", "crossing", "crossing-irrelevant")}


def _tracks(path: Path, attr_path: Path, video: str, split: str) -> list:
    root = parse_xml(path, "PIE annotation")
    tracks, attrs = [], None
    for n, t in enumerate(root.findall("./track")):
        if t.get("label") != "pedestrian":
            continue
        boxes, pid = track_boxes(path, n, t)
        if not boxes:
            continue
        boxes = [b for b in boxes if b[2] != 1]  # outside the frame
        check_values(path, n, pid, boxes, VALUES, "PIE's pie_data.py")
        if attrs is None:
            attrs = _attributes(attr_path)
        if pid not in attrs:
            raise BadInput(f"{attr_path}: no <pedestrian id={pid!r}> for {path} track[{n}]; "
                           "nothing written")
        frames, xyxy = [b[0] for b in boxes], [b[1] for b in boxes]
        crossing, point = attrs[pid]
        if point not in frames:
            raise BadInput(f"{attr_path}: pedestrian {pid!r}: crossing_point {point} is not "
                           "one of its annotated frames inside the image ("
                           f"{_span(frames)} in {path}); pie_data.py stops there too; "
                           "nothing written")
        tracks.append(Track(video, pid, frames, xyxy, int(crossing > 0), frames.index(point),
                            split, str(path), True))
    return tracks


def _span(frames: list) -> str:
    return f"{frames[0]}..{frames[-1]}" if frames else "none"


def read_pie(root) -> tuple:
    """``(tracks, sizes, split_note)`` of every ``annotations/SET/VIDEO_annt.xml``."""
    root = Path(root)
    ann = root / "annotations"
    if not ann.is_dir():
        raise BadInput(f"{root}: no annotations/ folder (PIE's annotations/SET/VIDEO_annt.xml, "
                       "unzipped); nothing written")
    sets = sorted(p for p in ann.iterdir() if p.is_dir())
    if not sets:
        raise BadInput(f"{ann}: no set folder (set01 ... set06) in it; nothing written")
    tracks, sizes = [], {}
    for folder in sets:
        if folder.name not in SET_SPLIT:
            raise BadInput(f"{folder}: {folder.name!r} is not one of PIE's sets "
                           f"({', '.join(sorted(SET_SPLIT))}); nothing written")
        files = sorted(folder.glob("*_annt.xml"))
        if not files:
            raise BadInput(f"{folder}: no VIDEO_annt.xml in it; nothing written")
        for path in files:
            name = path.name[:-len("_annt.xml")]
            video = f"{folder.name}/{name}"
            attr = root / "annotations_attributes" / folder.name / f"{name}_attributes.xml"
            if not attr.is_file():
                raise BadInput(f"{attr}: no such PIE attributes file (for {path}); "
                               "nothing written")
            sizes[video] = video_size(parse_xml(path, "PIE annotation"))
            tracks += _tracks(path, attr, video, SET_SPLIT[folder.name])
    return tracks, sizes, "PIE's sets: set01/02/04 train, set05/06 val, set03 test"


def _key(set_id, video: str) -> str:
    return f"{set_id}/{video}"


def import_pie(root, out, *, openpose=None, poses=None, threshold: float = 0.3,
               derive: bool = True, obs_length: int = BENCHMARK["obs_length"],
               tte=BENCHMARK["tte"], overlap: float = BENCHMARK["overlap"]["pie"],
               cut_gaps: bool = False, drop_first: bool = False, force: bool = False) -> dict:
    """PIE annotations + 2D poses (``openpose``: OpenPose JSON below ``SET/`` folders or
    named ``SET_VIDEO_<frame>_keypoints.json``, matched to the annotated boxes; or
    ``poses``: the benchmark's ``pose_SET.pkl`` file(s), restricted unpickler) -> the clip
    file ``out``; returns the report. ``cut_gaps``, ``drop_first``:
    :mod:`.benchmark_windows`."""
    if (openpose is None) == (poses is None):
        raise ValueError("give the poses: openpose=FOLDER or poses=PICKLE (one of them)")
    check_options(obs_length, tte, overlap, threshold)
    refuse_existing(out, force)
    tracks, sizes, note = read_pie(root)
    source = OpenPoseFrames(openpose, _key) if openpose else PickledPoses(poses, _key, derive)
    r = import_tracks(tracks, out, dataset="pie", source=source, sizes=sizes, root=root,
                      obs_length=obs_length, tte=tte, overlap=overlap, threshold=threshold,
                      derive=derive, cut_gaps=cut_gaps, drop_first=drop_first, force=force,
                      settings=dict(split=note, poses=str(openpose or poses)))
    r["split_note"] = note
    return r
