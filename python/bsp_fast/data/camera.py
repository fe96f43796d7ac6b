"""Camera helpers for 3D work: the pinhole intrinsics of a CARLA camera and the change of
axes between CARLA's camera frame and OpenCV's.

CARLA camera frame (what ``ClipDataset(..., lifting_target="camera")`` returns): x forward
(depth), y right, z up, metres. OpenCV camera frame: x right, y down, z forward. So
``(x_cv, y_cv, z_cv) = (y, -z, x)``, and with ``K`` below, ``K @ p_cv / z_cv`` gives the
pixel ``(u, v)`` that :func:`bsp_fast.project` gives for the same point (no distortion,
pixel origin at the top-left corner, no half-pixel offset).

Both conversions take NumPy arrays or torch tensors of any leading shape ``(..., 3)`` and
return the same kind.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["camera_intrinsics", "carla_to_opencv", "opencv_to_carla", "focal_length"]


def focal_length(width: float, fov: float = 90.0) -> float:
    """Focal length in pixels of a camera ``width`` pixels wide with horizontal field of
    view ``fov`` degrees: ``width / (2 tan(fov / 2))`` (800 for 1600 px at 90 degrees)."""
    if not (isinstance(width, (int, float)) and width > 0):
        raise ValueError(f"width must be a positive number of pixels, got {width!r}")
    if not (isinstance(fov, (int, float)) and 0 < fov < 180):
        raise ValueError(f"fov must lie in (0, 180) degrees, got {fov!r}")
    return width / (2 * math.tan(math.radians(fov) / 2))


def camera_intrinsics(width: float, height: float, fov: float = 90.0) -> np.ndarray:
    """The 3x3 intrinsic matrix ``K = [[f, 0, W/2], [0, f, H/2], [0, 0, 1]]`` (float64) of a
    CARLA camera, for points in the OpenCV camera frame (:func:`carla_to_opencv`). CARLA
    cameras have square pixels, so one focal length serves both axes."""
    if not (isinstance(height, (int, float)) and height > 0):
        raise ValueError(f"height must be a positive number of pixels, got {height!r}")
    f = focal_length(width, fov)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])


def _axes(points, order, signs):
    if type(points).__module__.startswith("torch"):
        import torch

        if points.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {tuple(points.shape)}")
        sign = torch.tensor(signs, dtype=points.dtype, device=points.device)
        return points[..., list(order)] * sign
    p = np.asarray(points)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points must have shape (..., 3), got {p.shape}")
    return p[..., list(order)] * np.asarray(signs, dtype=p.dtype if p.dtype.kind == "f" else None)


def carla_to_opencv(points):
    """CARLA camera axes (x forward, y right, z up) -> OpenCV's (x right, y down, z forward)."""
    return _axes(points, (1, 2, 0), (1, -1, 1))


def opencv_to_carla(points):
    """OpenCV camera axes (x right, y down, z forward) -> CARLA's (x forward, y right, z up)."""
    return _axes(points, (2, 0, 1), (1, 1, -1))
