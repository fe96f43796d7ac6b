"""bsp_fast: fast, complete toolkit for the CARLA-BSP pedestrian dataset."""
from __future__ import annotations

from ._version import __version__  # noqa: F401

from ._native import core as _core  # the C++ module (_native says where from)
from .geometry import (
    compose,
    forward_kinematics,
    in_frame,
    invert,
    mesh_offset,
    project,
    rotation_matrix,
    rotation_to_euler,
    to_world,
    transform_points,
)
from . import skeleton
from .csvio import read_csv, write_csv
from .conversion import convert
from . import media, synth
from .media import ApngReader, VideoReader

Error = _core.Error
CsvParseError = _core.CsvParseError
VideoDecodeError = _core.VideoDecodeError
VideoEncodeError = _core.VideoEncodeError
ApngError = _core.ApngError
Hdf5Error = _core.Hdf5Error
MotionError = _core.MotionError
set_num_threads = _core.set_num_threads
num_threads = _core.num_threads


def diagnostics() -> dict:
    """Package version, Python and NumPy versions, and the linked C/C++ library versions."""
    import platform

    import numpy

    info = {"bsp_fast": __version__, "python": platform.python_version(),
            "numpy": numpy.__version__, "threads": _core.num_threads()}
    info.update(dict(_core.library_versions()))
    return info


__all__ = [
    "compose", "forward_kinematics", "in_frame", "invert", "mesh_offset", "project",
    "rotation_matrix", "rotation_to_euler", "to_world", "transform_points", "skeleton",
    "diagnostics", "Error", "CsvParseError", "VideoDecodeError", "VideoEncodeError",
    "ApngError", "Hdf5Error", "MotionError", "set_num_threads", "num_threads", "convert",
    "media", "synth", "VideoReader", "ApngReader", "train", "evaluate", "predict",
]

_TRAINING = {"train": "train", "evaluate": "evaluate", "predict": "predict"}


def __getattr__(name):
    # bsp_fast.train/evaluate/predict import torch and Lightning (seconds): on first use only
    if name in _TRAINING:
        import importlib

        return getattr(importlib.import_module(f".training.{_TRAINING[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
