"""The CVAT-style XML of the JAAD and PIE annotations: the root of a file, a video's size,
one ``<box>``, the pedestrians' crossing attributes; every malformed or missing piece is a
:class:`~.readers.BadInput` naming the file (and line, element) with nothing written."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from .readers import BadInput

__all__ = ["parse_xml", "video_size", "box_record", "track_boxes", "check_values",
           "crossing_attributes"]


def parse_xml(path, what: str):
    """The root element of ``path``; a missing or malformed file is a :class:`BadInput`."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{path}: no such {what} file; nothing written")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        line, col = exc.position
        raise BadInput(f"{path}: malformed XML at line {line} column {col + 1}: "
                       f"{str(exc).split(':')[0]}; nothing written") from None


def video_size(root, default=(1920, 1080)) -> tuple:
    """(width, height) from CVAT's ``meta/task/original_size``, else ``default``."""
    w, h = root.findtext("./meta/task/original_size/width"), \
        root.findtext("./meta/task/original_size/height")
    try:
        return (int(w), int(h)) if w and h else default
    except ValueError:
        return default


def box_record(box, where: str) -> tuple:
    """``(frame, [x1, y1, x2, y2], outside, {attribute: text})`` of a CVAT ``<box>``."""
    try:
        frame = int(box.get("frame"))
        xyxy = [float(box.get(k)) for k in ("xtl", "ytl", "xbr", "ybr")]
        outside = int(box.get("outside", "0"))
    except (TypeError, ValueError):
        raise BadInput(f"{where}: a <box> needs integer 'frame' and numeric 'xtl', 'ytl', "
                       f"'xbr', 'ybr' (got {dict(box.attrib)}); nothing written") from None
    attrs = {a.get("name"): (a.text or "").strip() for a in box.findall("./attribute")}
    return frame, xyxy, outside, attrs


def track_boxes(path, n: int, track) -> tuple:
    """``(box records, pedestrian id)`` of the ``n``-th ``<track>`` of ``path``;
    ``([], None)`` for a track without boxes; a track whose boxes carry no ``id``
    attribute is a :class:`BadInput`."""
    boxes = [box_record(b, f"{path}: track[{n}] box[{k}]")
             for k, b in enumerate(track.findall("./box"))]
    if not boxes:
        return [], None
    pid = boxes[0][3].get("id")
    if not pid:
        raise BadInput(f"{path}: track[{n}] (frame {boxes[0][0]}): no <attribute "
                       "name=\"id\">; nothing written")
    return boxes, pid


def check_values(path, n: int, pid: str, boxes: list, allowed: dict, tool: str) -> None:
    """Every box of the ``n``-th track of ``path`` has each attribute of ``allowed``
    (``{name: values}``) with one of its values, as the official ``tool`` maps them
    (its ``_map_text_to_scalar``, which stops with a KeyError on any other value)."""
    for frame, _, _, attrs in boxes:
        for name, values in allowed.items():
            value = attrs.get(name)
            if value not in values:
                got = "no such attribute" if value is None else f"{value!r}"
                raise BadInput(f"{path}: track[{n}] (pedestrian {pid!r}) frame {frame}: "
                               f"{name}: {got}, not one of {', '.join(values)} (as {tool} "
                               "reads it); nothing written")


def crossing_attributes(path, what: str) -> dict:
    """``{pedestrian id: (crossing, crossing_point)}`` of an attributes file (JAAD's
    ``annotations_attributes``, PIE's ``annotations_attributes``)."""
    root = parse_xml(path, what)
    out = {}
    for k, p in enumerate(root.findall("./pedestrian")):
        pid = p.get("id")
        try:
            out[pid] = (int(p.get("crossing")), int(p.get("crossing_point")))
        except (TypeError, ValueError):
            raise BadInput(f"{path}: pedestrian[{k}] (id {pid!r}): needs integer 'crossing' "
                           "and 'crossing_point'; nothing written") from None
    return out
