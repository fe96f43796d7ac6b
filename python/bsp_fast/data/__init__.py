"""``bsp_fast.data``: the dataset API under the name the project's issues use.

Everything here is :mod:`bsp_fast.loaders` (PyTorch datasets, transforms, the DataModule);
this folder also carries the package data (``carla_skeleton/*.yaml``).
"""
from __future__ import annotations

from .. import loaders as _loaders

__all__ = list(_loaders.__all__)


def __getattr__(name):  # lazily, like bsp_fast.loaders (torch imports take seconds)
    return getattr(_loaders, name)


def __dir__():
    return sorted(set(globals()) | set(_loaders.__all__))
