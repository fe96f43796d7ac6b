"""The conversion stage: a CARLA-BSP dataset (data.csv + media) -> train/val/test clips in
one HDF5 file (``bsp_fast.convert``, ``bsp-convert``).

Modules: ``api`` (:func:`convert`, :func:`conversion_settings`, the progress thread),
``cli`` (``bsp-convert``), ``inputs`` (where data.csv is, the FOV of config.yaml, outputs
that would overwrite an input), ``report`` (progress bars, the summary, problems),
``crops`` (one frame's crop box and crop, as the media stage computes them), ``sharded``
(the Dask path), ``vds`` (virtual datasets over the shards, written and checked),
``errors``.
"""
from __future__ import annotations

from ..defaults import CONVERT as DEFAULTS
from .api import conversion_settings, convert
from .cli import main
from .crops import context_box, crop_resize, frame_media
from .errors import BadDataset, UnusableConversion
from .inputs import dataset_csv
from .report import format_report

__all__ = ["convert", "conversion_settings", "main", "format_report", "frame_media",
           "crop_resize", "context_box", "DEFAULTS", "UnusableConversion", "BadDataset",
           "dataset_csv"]
