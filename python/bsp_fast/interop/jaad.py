"""JAAD's official annotations -> a clip file (``bsp-interop import jaad``, docs/interop.md).

Read as JAAD's own interface (``jaad_data.py``) reads them: ``ROOT/annotations/VIDEO.xml``
(CVAT tracks of ``<box frame xtl ytl xbr ybr>`` with ``<attribute name="id">``,
``occlusion`` and, for pedestrians with behaviour labels (ids ending in ``b``), ``cross``
etc. per frame), ``ROOT/annotations_attributes/VIDEO_attributes.xml`` (one
``<pedestrian id crossing crossing_point ...>`` per behaviour pedestrian) and the split
files ``ROOT/split_ids/default/{train,val,test}.txt``.

Samples as the PedestrianActionBenchmark's ``crossing`` sequences (``_get_crossing``):
groups (ids with ``p``) are left out; ``subset='beh'`` keeps the behaviour pedestrians
only (``all``: every pedestrian); a behaviour pedestrian's track ends at its
``crossing_point`` (``-1``: 3 frames before its last), the others' 3 frames before their
last; label 1 when the attribute ``crossing`` is 1. Windows: :mod:`.benchmark_windows`.
What jaad_data.py refuses is refused here too, in one line: an attribute value it does
not map (occlusion; a behaviour track's action, nod, look, hand_gesture, reaction,
cross), a crossing point that is not one of the pedestrian's frames.
"""
from __future__ import annotations

from pathlib import Path

from .annotation_xml import (check_values, crossing_attributes, parse_xml, track_boxes,
                             video_size)
from .benchmark_annotations import (BENCHMARK, SPLITS, OpenPoseFrames, PickledPoses, Track,
                                    check_options, import_tracks, refuse_existing)
from .readers import BadInput

__all__ = ["read_jaad", "import_jaad", "SUBSETS"]

SUBSETS = ("beh", "all")


def _split_files(root: Path, split_dir) -> tuple:
    """``({video: split}, folder)`` from ``split_dir`` (or ``ROOT/split_ids/default``
    where it exists), else ``(None, None)``: the seeded split."""
    folder = Path(split_dir) if split_dir is not None else root / "split_ids" / "default"
    if split_dir is None and not folder.is_dir():
        return None, None
    split = {}
    for s in SPLITS:
        path = folder / f"{s}.txt"
        if not path.is_file():
            raise BadInput(f"{path}: no such split file (JAAD's split_ids/<subset>/ holds "
                           "train.txt, val.txt, test.txt); nothing written")
        for line, text in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            video = text.strip()
            if not video:
                continue
            if video in split:
                raise BadInput(f"{path}: line {line}: video {video!r} is also in the "
                               f"{split[video][0]} split; nothing written")
            split[video] = (s, path)
    return split, folder


def _attributes(path: Path) -> dict:
    return crossing_attributes(path, "JAAD attributes")


#: the values jaad_data.py maps (``_map_text_to_scalar``): every box's occlusion, and the
#: behaviour tags of the tracks it reads them for ('pedestrian' in the old id)
OCCLUSION = {"occlusion": ("none", "part", "full")}
BEHAVIOUR = {"action": ("standing", "walking"), "nod": ("__undefined__", "nodding"),
             "look": ("not-looking", "looking"),
             "hand_gesture": ("__undefined__", "greet", "yield", "rightofway", "other"),
             "reaction": ("__undefined__", "clear_path", "speed_up", "slow_down"),
             "cross": ("not-crossing", "crossing", "irrelevant")}


def _event(path: Path, n: int, pid: str, frames: list, attrs: dict) -> tuple:
    """``(label, end)`` of a behaviour pedestrian: its ``crossing`` attribute and the index
    of its ``crossing_point`` (-1: 3 frames before the last); a crossing point that is not
    one of its frames stops the import, as jaad_data.py's ``frames.index`` does."""
    if pid not in attrs:
        raise BadInput(f"{path.parent.parent / 'annotations_attributes'}/"
                       f"{path.stem}_attributes.xml: no <pedestrian id={pid!r}> for the "
                       f"behaviour pedestrian of {path} track[{n}]; nothing written")
    crossing, point = attrs[pid]
    if point == -1:
        return int(crossing > 0), len(frames) - 3
    if point not in frames:
        raise BadInput(f"{path.parent.parent / 'annotations_attributes'}/{path.stem}"
                       f"_attributes.xml: pedestrian {pid!r}: crossing_point {point} is not "
                       f"one of its annotated frames ({frames[0]}..{frames[-1]} in {path}); "
                       "jaad_data.py stops there too; nothing written")
    return int(crossing > 0), frames.index(point)


def _tracks(path: Path, video: str, subset: str, split) -> list:
    root = parse_xml(path, "JAAD annotation")
    tracks, attrs = [], None
    for n, t in enumerate(root.findall("./track")):
        boxes, pid = track_boxes(path, n, t)
        if not boxes:
            continue
        old_id = boxes[0][3].get("old_id", t.get("label") or "")
        check_values(path, n, pid, boxes, dict(OCCLUSION, **(BEHAVIOUR if "pedestrian"
                                                             in old_id else {})),
                     "JAAD's jaad_data.py")
        frames, xyxy = [b[0] for b in boxes], [b[1] for b in boxes]
        use = "p" not in pid and (subset == "all" or "b" in pid)
        label, end = 0, len(frames) - 3  # the benchmark's end for pedestrians without event
        if "b" in pid and use:
            if attrs is None:
                attrs = _attributes(path.parent.parent / "annotations_attributes"
                                    / f"{video}_attributes.xml")
            label, end = _event(path, n, pid, frames, attrs)
        tracks.append(Track(video, pid, frames, xyxy, label, end, split, str(path), use))
    return tracks


def read_jaad(root, subset: str = "beh", split_dir=None) -> tuple:
    """``(tracks, sizes, split_note)``: the :class:`Track` of every annotated pedestrian of
    the videos in the split files (every ``annotations/*.xml`` without them), the image
    size per video, and a line saying which split was used."""
    if subset not in SUBSETS:
        raise ValueError(f"subset must be one of {', '.join(SUBSETS)}, got {subset!r}")
    root = Path(root)
    if not (root / "annotations").is_dir():
        raise BadInput(f"{root}: no annotations/ folder (JAAD's annotations/VIDEO.xml); "
                       "nothing written")
    split, folder = _split_files(root, split_dir)
    if split is None:
        videos = {p.stem: None for p in sorted((root / "annotations").glob("*.xml"))}
        if not videos:
            raise BadInput(f"{root / 'annotations'}: no VIDEO.xml in it; nothing written")
        note = "seeded split by video (no split files)"
    else:
        videos = {v: s for v, (s, _) in sorted(split.items())}
        note = f"JAAD's split files in {folder}"
    tracks, sizes = [], {}
    for video, s in videos.items():
        path = root / "annotations" / f"{video}.xml"
        if not path.is_file():
            where = f" (listed in {split[video][1]})" if split else ""
            raise BadInput(f"{path}: no such JAAD annotation file{where}; nothing written")
        sizes[video] = video_size(parse_xml(path, "JAAD annotation"))
        tracks += _tracks(path, video, subset, s)
    return tracks, sizes, note


def import_jaad(root, out, *, openpose=None, poses=None, subset: str = "beh",
                split_dir=None, threshold: float = 0.3, derive: bool = True,
                obs_length: int = BENCHMARK["obs_length"], tte=BENCHMARK["tte"],
                overlap: float = BENCHMARK["overlap"]["jaad"], cut_gaps: bool = False,
                drop_first: bool = False, seed=None, val_frac=None, test_frac=None,
                force: bool = False) -> dict:
    """JAAD annotations + 2D poses (``openpose``: a folder of OpenPose JSON, matched to
    the annotated boxes; or ``poses``: the benchmark's pose pickle(s), read with the
    restricted unpickler) -> the clip file ``out``; returns the report. ``cut_gaps``,
    ``drop_first``: :mod:`.benchmark_windows`."""
    if (openpose is None) == (poses is None):
        raise ValueError("give the poses: openpose=FOLDER or poses=PICKLE (one of them)")
    check_options(obs_length, tte, overlap, threshold)
    refuse_existing(out, force)
    tracks, sizes, note = read_jaad(root, subset, split_dir)
    key = lambda set_id, video: video  # noqa: E731  (JAAD: one set)
    source = OpenPoseFrames(openpose, key) if openpose else PickledPoses(poses, key, derive)
    r = import_tracks(tracks, out, dataset="jaad", source=source, sizes=sizes, root=root,
                      obs_length=obs_length, tte=tte, overlap=overlap, threshold=threshold,
                      derive=derive, cut_gaps=cut_gaps, drop_first=drop_first, seed=seed,
                      val_frac=val_frac, test_frac=test_frac, force=force,
                      settings=dict(sample_type=subset, split=note,
                                    poses=str(openpose or poses)))
    r["split_note"] = note
    return r
