"""PyTorch datasets, transforms and a Lightning DataModule over ``bsp-convert`` HDF5 files.

(``bsp_fast.data`` holds package data, the skeleton YAML files, hence the name ``loaders``.)
See docs/loaders.md. ``BSPDataModule`` is imported on first access, because importing
Lightning takes seconds and the datasets and transforms do not need it.
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
from .sampling import ContiguousBatchSampler, IndexBatch, collate_batch
from .datasets import DEFAULT_EVAL_SEED, LIFTING_TARGETS, SPLITS, TASKS, ClipDataset

__all__ = [
    "ClipDataset", "BSPDataModule", "ContiguousBatchSampler", "IndexBatch", "collate_batch",
    "TASKS", "SPLITS", "LIFTING_TARGETS", "DEFAULT_EVAL_SEED",
    "Compose", "Deform", "GaussianNoise", "MissingJoints", "HorizontalFlip", "RandomRotation",
    "RandomFlipRotate", "HipsNeckNormalize", "HipsNeckDenormalize", "NormalizedPose",
    "normalize_hips_neck",
    "denormalize_hips_neck", "normalize_hips_neck_3d", "flip_horizontal", "flip_rotate", "rotate",
    "joint_bbox", "visible_joints",
]


def __getattr__(name):
    if name == "BSPDataModule":
        from .datamodule import BSPDataModule

        return BSPDataModule
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
