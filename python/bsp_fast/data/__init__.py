"""PyTorch datasets, transforms and a Lightning DataModule over ``bsp-convert`` HDF5 files.

See docs/data.md. The transforms are plain NumPy; the torch-based names (``ClipDataset``,
``ContiguousBatchSampler``, ...) and ``BSPDataModule`` (Lightning) are imported on first
access, because importing torch and Lightning takes seconds.
"""
from __future__ import annotations

from .transforms import (
    Compose,
    Deform,
    GaussianNoise,
    HipsNeckDenormalize,
    HipsNeckNormalize,
    HorizontalFlip,
    MissingJoints,
    NormalizedPose,
    RandomFlipRotate,
    RandomRotation,
    denormalize_hips_neck,
    flip_horizontal,
    flip_rotate,
    joint_bbox,
    normalize_hips_neck,
    normalize_hips_neck_3d,
    rotate,
    visible_joints,
)
from .functional import denormalize_hips_neck_3d
from .camera import camera_intrinsics, carla_to_opencv, focal_length, opencv_to_carla
from ..conversion.vds import MissingShardError, check_virtual_sources, open_clip_file

__all__ = [
    "ClipDataset", "FrameDataset", "BSPDataModule", "ClipData", "ContiguousBatchSampler", "IndexBatch",
    "collate_batch", "ImageAugment", "to_float_images",
    "TASKS", "SPLITS", "LIFTING_TARGETS", "DEFAULT_EVAL_SEED",
    "Compose", "Deform", "GaussianNoise", "MissingJoints", "HorizontalFlip", "RandomRotation",
    "RandomFlipRotate", "HipsNeckNormalize", "HipsNeckDenormalize", "NormalizedPose",
    "normalize_hips_neck",
    "denormalize_hips_neck", "normalize_hips_neck_3d", "flip_horizontal", "flip_rotate", "rotate",
    "joint_bbox", "visible_joints", "denormalize_hips_neck_3d", "camera_intrinsics",
    "focal_length", "carla_to_opencv", "opencv_to_carla",
    "MissingShardError", "open_clip_file", "check_virtual_sources",
]


_LAZY = {"ContiguousBatchSampler": "sampling", "IndexBatch": "sampling",
         "collate_batch": "sampling", "ClipDataset": "datasets", "TASKS": "datasets",
         "SPLITS": "datasets", "LIFTING_TARGETS": "datasets", "DEFAULT_EVAL_SEED": "datasets",
         "FrameDataset": "frames", "ImageAugment": "images", "to_float_images": "images",
         "BSPDataModule": "datamodule", "ClipData": "clip_data"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
