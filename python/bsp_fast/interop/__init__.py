"""Other tools' pose data in and out: importers of 2D detections (COCO keypoint JSON from
MMPose / Detectron2, OpenPose per-frame JSON) into clip files in the bsp-convert HDF5
schema, and exporters of clip files to VideoPose3D's ``.npz`` layout and to COCO keypoint
JSON, through the skeleton maps of :mod:`bsp_fast.skeletons`. ``bsp-interop`` is the
command line (docs/interop.md).

Modules: ``readers`` (input files, labels CSV), ``clipfile`` (planning and writing the
clip file), ``exporters``, ``cli``.
"""
from __future__ import annotations

from .clipfile import clip_settings, write_clip_file
from .exporters import export_coco, export_videopose3d, read_clips
from .readers import BadInput, Detections, read_coco, read_labels, read_openpose

__all__ = ["BadInput", "Detections", "read_coco", "read_openpose", "read_labels",
           "write_clip_file", "clip_settings", "export_coco", "export_videopose3d",
           "read_clips", "import_coco", "import_openpose"]


def import_coco(path, out, *, images=None, labels=None, image_size=None, tracks="require",
                joints="coco17", **options) -> dict:
    """:func:`read_coco` then :func:`write_clip_file` (``labels``: a labels CSV path)."""
    det = read_coco(path, images=images, image_size=image_size, tracks=tracks, joints=joints)
    return write_clip_file(det, out, labels=None if labels is None else read_labels(labels),
                           **options)


def import_openpose(folder, out, *, image_size, labels=None, tracks="require",
                    **options) -> dict:
    """:func:`read_openpose` then :func:`write_clip_file`."""
    det = read_openpose(folder, image_size, tracks=tracks)
    return write_clip_file(det, out, labels=None if labels is None else read_labels(labels),
                           **options)
