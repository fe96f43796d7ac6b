"""``bsp-preview``: look at the data before trusting it (OpenCV pictures, PNG or MP4).

``preview_frames`` (a recording's video frames with the skeleton, bbox, label and the
segmentation), ``preview_clips`` (a contact sheet of converted clips), ``preview_pose3d``
(a clip's 3D skeleton from two viewpoints, matplotlib) and ``preview_predictions``
(ground truth against ``bsp-predict`` outputs). Each returns {path, format, frames, size,
...}, or the pictures themselves (``images``) when ``out`` is None. See docs/preview.md.
"""
from __future__ import annotations

from .clips import preview_clips
from .draw import colourise, draw_skeleton
from .frames import preview_frames
from .pose3d import preview_pose3d
from .predictions import preview_predictions, read_predictions

__all__ = ["preview_frames", "preview_clips", "preview_pose3d", "preview_predictions",
           "read_predictions", "draw_skeleton", "colourise"]
