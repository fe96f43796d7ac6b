"""``bsp-preview``: look at the data before trusting it (OpenCV pictures, PNG or MP4).

``preview_frames`` (a recording's video frames with the skeleton, bbox, label and the
segmentation), ``preview_clips`` (a contact sheet of converted clips), ``preview_pose3d``
(a clip's 3D skeleton from two viewpoints, matplotlib) and ``preview_predictions``
(ground truth against ``bsp-predict`` outputs). Each returns {path, format, frames, size,
...}, or the pictures themselves (``images``) when ``out`` is None. See docs/preview.md.
"""
from __future__ import annotations

# Imported on first access, so that ``bsp-preview`` (the cli module of this package) can
# say which extra to install when OpenCV or matplotlib is missing instead of failing here.
_NAMES = {"preview_clips": "clips", "colourise": "draw", "draw_skeleton": "draw",
          "preview_frames": "frames", "preview_pose3d": "pose3d",
          "preview_predictions": "predictions", "read_predictions": "predictions"}

__all__ = ["preview_frames", "preview_clips", "preview_pose3d", "preview_predictions",
           "read_predictions", "draw_skeleton", "colourise"]


def __getattr__(name: str):
    if name in _NAMES:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
