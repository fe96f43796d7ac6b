"""Default values shared by several stages, in one place (signatures, argparse, the
DataModule, the training options and the docs read them from here).

The C++ core keeps its own copy of the conversion defaults in
``cpp/include/bsp/clips/clips.hpp`` (``ClipOptions``) and
``cpp/include/bsp/conversion/convert.hpp`` (``ConvertOptions``, ``MediaOptions``), returned by
``_core.convert_defaults()``; ``tests/python/test_convert.py`` checks that the two agree.
"""
from __future__ import annotations

__all__ = ["SEED", "CONVERT", "CROP_BOXES", "POSE_CROP_CONTEXT", "experiments_dirs"]

SEED = 22742
"""The original code's seed: the converter's split shuffle, training (weights, noise, batch
order) and the fixed evaluation noise all default to it."""

CONVERT = dict(
    clip_length=30, benchmark_clip_length=16, benchmark_clip_offset=6,
    val_frac=0.2, test_frac=0.2, seed=SEED, fov=90.0, crop_size=128, label="last",
    crop_box="mask", crop_context=1.0,
)
"""bsp-convert's defaults (``bsp_fast.convert``, ``conversion_settings``, ``bsp-convert``,
``BSPDataModule``)."""

CROP_BOXES = ("mask", "mask+joints", "joints")
"""What a crop box is made from (docs/hdf5-schema.md, "Crop box"): the segmentation mask's
box (the default: what a person detector could see), the union of the mask box and the
ground-truth joint box (an upper bound: partly cut from the answer), the joint box."""

POSE_CROP_CONTEXT = 1.25
"""The crop context ``BSPDataModule`` converts with for ``pose_estimation`` (bsp-convert's
default is 1, none): enough for box noise of scale +-10 % and shift +-5 % of the side
(docs/data.md, "Box noise")."""


def experiments_dirs(sub: str = "") -> list:
    """Where the report's table files (``sub`` "": ``experiments/TABLE.yaml``, read by
    bsp-reproduce) and mixing tables (``sub`` "mix") are looked up, in order: each folder
    of ``$BSP_EXPERIMENTS`` (``os.pathsep``-separated), ``./experiments``, the tables
    installed with the package (``bsp_fast/experiments``), the source tree's
    ``experiments/``; each with ``sub`` appended, without repeats."""
    import os
    from importlib import resources
    from pathlib import Path

    dirs = [Path(d) for d in os.environ.get("BSP_EXPERIMENTS", "").split(os.pathsep) if d]
    dirs += [Path.cwd() / "experiments",
             Path(str(resources.files("bsp_fast").joinpath("experiments"))),
             Path(__file__).resolve().parents[2] / "experiments"]
    out = []
    for d in dirs:
        d = d / sub if sub else d
        if d not in out:
            out.append(d)
    return out
