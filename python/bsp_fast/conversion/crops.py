"""The pedestrian crops of bsp-convert's media stage, for one frame: the crop box, mask
statistics and joint visibility (``frame_media``), and the crop itself (``crop_resize``).
Definitions: docs/hdf5-schema.md, "Crop box"."""
from __future__ import annotations

from .._native import core as _core
from ..defaults import CONVERT, CROP_BOXES

__all__ = ["frame_media", "crop_resize", "context_box"]


def frame_media(tags, uv, crop_box: str = CONVERT["crop_box"]) -> dict:
    """The per-frame media values bsp-convert stores, for one segmentation frame.

    ``tags``: (H, W) uint8 class tags (tag 4 = pedestrian); ``uv``: (26, 2) projected
    joints in pixels; ``crop_box``: the policy (``mask``, ``mask+joints``, ``joints``).
    Returns ``crop_box`` (4,) float32 ``[u0, v0, u1, v1]`` (a square with integer edges,
    possibly past the image; all NaN under ``mask`` when no pixel has tag 4: no crop),
    ``mask_bbox`` (4,) int32 ``[u0, v0, u1, v1)`` or all -1, ``visible_pixels`` (tag-4
    pixel count) and ``joint_visible`` (26,) uint8.
    """
    import numpy as np

    tags = np.asarray(tags)
    if tags.dtype != np.uint8 or tags.ndim != 2:
        raise ValueError(f"tags must be an (H, W) uint8 array, got {tags.dtype} {tags.shape}")
    if crop_box not in CROP_BOXES:
        raise ValueError(f"crop_box must be one of {', '.join(CROP_BOXES)}, got {crop_box!r}")
    return _core.frame_media(tags, np.asarray(uv, np.float32), crop_box)


def context_box(box, context: float):
    """The wider box bsp-convert stores as ``frames/context_box`` for crop box ``box``:
    side ``ceil(context * side)``, same centre, corner ``u0 - floor((side' - side) / 2)``."""
    import numpy as np

    return _core.context_box(np.asarray(box, np.float32), float(context))


def crop_resize(image, box, size: int, nearest: bool = False):
    """Cuts ``box`` (``crop_box`` of :func:`frame_media`) out of an (H, W[, C]) uint8 image,
    zero-padding what lies outside, and resizes it to ``size`` x ``size`` the way
    bsp-convert does (OpenCV INTER_AREA for pictures, INTER_NEAREST for class tags)."""
    import numpy as np

    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    if not isinstance(size, int) or isinstance(size, bool) or size <= 0:
        raise ValueError(f"size must be a positive integer, got {size!r}")
    return _core.crop_resize(image, np.asarray(box, np.float32), int(size), bool(nearest))
