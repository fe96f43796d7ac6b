"""3D skeletons with matplotlib (object API and the Agg canvas: no pyplot, no global
backend change), rendered to RGB arrays.

CARLA's axes are left-handed (x forward, y right, z up). Matplotlib draws right-handed
axes, so the y axis is shown reversed (its values grow to the left of the x axis when
seen from above): the skeleton is never mirrored and the left arm stays the left arm.
"""
from __future__ import annotations

import numpy as np

from .. import skeleton as sk
from . import draw

#: Viewpoints (elevation, azimuth in degrees) of the two panels of pose3d: in the actor's
#: frame (component space) the pedestrian faces +x, so "front" looks at its face and
#: "side" at its right side.
VIEWS = {"front": (12.0, 0.0), "side": (12.0, -90.0)}


def _rgb01(c) -> tuple:
    return tuple(float(x) / 255 for x in c)


def depth_axis(azim: float) -> str:
    """``"x"`` or ``"y"``: the horizontal axis closer to the line of sight of a view from
    azimuth ``azim`` degrees (matplotlib's convention: 0 looks along -x, -90 along +y)."""
    a = np.radians(azim)
    return "x" if abs(np.cos(a)) >= abs(np.sin(a)) else "y"


def limits(points, pad: float = 0.1) -> tuple:
    """Equal-range cube (lo (3,), hi (3,)) around all finite (..., 3) points."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(1)]
    if not len(p):
        return -np.ones(3), np.ones(3)
    lo, hi = p.min(0), p.max(0)
    half = max(float((hi - lo).max()) / 2 * (1 + pad), 0.05)
    mid = (lo + hi) / 2
    return mid - half, mid + half


class SkeletonFigure:
    """A figure of side-by-side 3D panels whose skeletons are updated frame by frame.

    ``panels``: list of (title, (elev, azim)); ``skeletons_per_panel``: how many
    skeletons each panel shows, each drawn in its side colours or in one colour given
    to :meth:`render`. ``size``: (width, height) of the picture in pixels.
    """

    def __init__(self, panels, lo, hi, size=(800, 400), n_skeletons: int = 1,
                 colours=None, suptitle: str = ""):
        from .._extras import require

        require("matplotlib", "bsp-preview (3D views)")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.ticker import NullFormatter

        w, h = int(size[0]), int(size[1])
        self.size = (w, h)
        self.fig = Figure(figsize=(w / 100, h / 100), dpi=100)
        self.canvas = FigureCanvasAgg(self.fig)
        self.title = self.fig.suptitle(suptitle, fontsize=9)
        self.lines = []
        self.axes = []
        for k, (name, (elev, azim)) in enumerate(panels):
            ax = self.fig.add_subplot(1, len(panels), k + 1, projection="3d")
            ax.view_init(elev=elev, azim=azim)
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(hi[1], lo[1])  # reversed: left-handed CARLA axes, not mirrored
            ax.set_zlim(lo[2], hi[2])
            ax.set_box_aspect((1, 1, 1), zoom=1.25)
            ax.set_xlabel("x (m)", fontsize=7, labelpad=-8)
            ax.set_ylabel("y (m)", fontsize=7, labelpad=-8)
            ax.set_zlabel("z (m)", fontsize=7, labelpad=-1)
            ax.tick_params(labelsize=6, pad=-2)
            # The horizontal axis along the line of sight is seen end-on: its tick labels
            # would pile up on each other, so it shows none (the other two carry the scale).
            depth = depth_axis(azim)
            getattr(ax, f"{depth}axis").set_major_formatter(NullFormatter())
            getattr(ax, f"set_{depth}label")("")
            ax.set_title(name, fontsize=9)
            per = []
            for s in range(n_skeletons):
                one = None if colours is None else colours[s]
                bones = []
                for p, c in sk.EDGES:
                    col = _rgb01(one if one is not None else draw.JOINT_COLOURS[c])
                    (ln,) = ax.plot([0, 0], [0, 0], [0, 0], color=col, lw=2)
                    bones.append(ln)
                per.append(bones)
            self.lines.append(per)
            self.axes.append(ax)
        self.fig.subplots_adjust(left=0.0, right=1.0, bottom=0.02, top=0.9, wspace=0.05)

    def render(self, skeletons, suptitle: str | None = None) -> np.ndarray:
        """``skeletons[panel][k]`` is a (26, 3) pose; returns (H, W, 3) uint8 RGB."""
        for per, poses in zip(self.lines, skeletons):
            for bones, pose in zip(per, poses):
                pose = np.asarray(pose, np.float64)
                for ln, (p, c) in zip(bones, sk.EDGES):
                    seg = pose[[p, c]]
                    ln.set_data_3d(seg[:, 0], seg[:, 1], seg[:, 2])
        if suptitle is not None:
            self.title.set_text(suptitle)
        self.canvas.draw()
        rgba = np.asarray(self.canvas.buffer_rgba())
        return np.ascontiguousarray(rgba[..., :3])
