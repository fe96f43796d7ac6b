"""Other tools' pose data in and out: importers of 2D detections (COCO keypoint JSON from
MMPose / Detectron2, OpenPose per-frame JSON) into clip files in the bsp-convert HDF5
schema, and exporters of clip files to VideoPose3D's ``.npz`` layout and to COCO keypoint
JSON, through the skeleton maps of :mod:`bsp_fast.skeleton`. ``bsp-interop`` is the
command line (docs/interop.md).

Modules: ``readers`` (input files, labels CSV), ``clipfile`` (planning and writing the
clip file; ``import_coco`` and ``import_openpose``), ``exporters``, ``annotation_xml``,
``jaad``, ``pie`` and ``benchmark_annotations`` (the JAAD and PIE importers),
``safe_pickle``, ``cli``. This file only hands their names on.
"""
from __future__ import annotations

from .clipfile import clip_settings, import_coco, import_openpose, write_clip_file
from .exporters import export_coco, export_videopose3d, read_clips
from .readers import BadInput, Detections, read_coco, read_labels, read_openpose

__all__ = ["BadInput", "Detections", "read_coco", "read_openpose", "read_labels",
           "write_clip_file", "clip_settings", "export_coco", "export_videopose3d",
           "read_clips", "import_coco", "import_openpose"]
