"""Default values shared by several stages, in one place (signatures, argparse, the
DataModule, the training options and the docs read them from here).

The C++ core keeps its own copy of the conversion defaults in
``cpp/include/bsp/clips/clips.hpp`` (``ClipOptions``) and
``cpp/include/bsp/conversion/convert.hpp`` (``ConvertOptions``, ``MediaOptions``), returned by
``_core.convert_defaults()``; ``tests/python/test_convert.py`` checks that the two agree.
"""
from __future__ import annotations

__all__ = ["SEED", "CONVERT"]

SEED = 22742
"""The original code's seed: the converter's split shuffle, training (weights, noise, batch
order) and the fixed evaluation noise all default to it."""

CONVERT = dict(
    clip_length=30, benchmark_clip_length=16, benchmark_clip_offset=6,
    val_frac=0.2, test_frac=0.2, seed=SEED, fov=90.0, crop_size=128, label="last",
)
"""bsp-convert's defaults (``bsp_fast.convert``, ``conversion_settings``, ``bsp-convert``,
``BSPDataModule``)."""
