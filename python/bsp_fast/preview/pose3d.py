"""``bsp-preview pose3d``: one clip's 3D skeleton from two viewpoints."""
from __future__ import annotations

import numpy as np

from .clips import CLASS_NAMES, SPLITS, frame_position
from .output import check_output, output_format, save
from .plot3d import VIEWS, SkeletonFigure, limits

#: Which 3D joint locations of a bsp-convert file to draw.
SPACES = {"component": "targets/absolute_pose_loc", "world": "targets/world_pose_loc"}


def parse_size(size) -> tuple:
    if isinstance(size, str):
        try:
            w, h = (int(x) for x in size.lower().split("x"))
        except ValueError:
            raise ValueError(f"size must be WIDTHxHEIGHT, got {size!r}") from None
    else:
        w, h = (int(x) for x in size)
    if w < 100 or h < 100:
        raise ValueError(f"size must be at least 100x100 pixels, got {w}x{h}")
    return w, h


def read_clip(path, split: str, clip: int, space: str) -> dict:
    from ..conversion.vds import open_clip_file

    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}; got {split!r}")
    if space not in SPACES:
        raise ValueError(f"space must be one of {', '.join(SPACES)}; got {space!r}")
    with open_clip_file(path) as f:
        if split not in f:
            raise ValueError(f"{path} has no split {split!r} (has {', '.join(f.keys())})")
        g = f[split]
        n = g["labels"].shape[0]
        if not 0 <= int(clip) < n:
            raise ValueError(f"clip {clip} outside split {split!r}'s 0..{n - 1}")
        i = int(clip)
        vid = g["meta/video_id"][i]
        return {"pose": g[SPACES[space]][i].astype(np.float64),
                "frame_idx": g["targets/frame_idx"][i], "label": int(g["labels"][i]),
                "video_id": vid.decode() if isinstance(vid, bytes) else str(vid),
                "clip_id": int(g["meta/clip_id"][i])}


def preview_pose3d(clips_h5, clip: int = 0, out=None, *, split: str = "train",
                   space: str = "component", frame="middle", size=(800, 400),
                   fps: float = 30.0, force: bool = False) -> dict:
    """The 3D skeleton of clip ``clip`` of ``split`` (matplotlib), from the front and from
    the side, in metres: ``space="component"`` draws ``targets/absolute_pose_loc`` (the
    actor's frame: the body stays in place and faces +x), ``"world"`` draws
    ``targets/world_pose_loc``. Axis limits are fixed over the clip. ``out``: .png (frame
    ``frame``: first, middle, last or a number) or .mp4 (every frame of the clip, at
    ``fps``); None returns the pictures. The picture is ``size`` = (width, height) pixels.
    """
    w, h = parse_size(size)
    fmt = output_format(out) if out is not None else "png"
    if out is not None:
        check_output(out, force)
    c = read_clip(clips_h5, split, clip, space)
    L = c["pose"].shape[0]
    lo, hi = limits(c["pose"])
    panels = [(f"{name} ({space})", VIEWS[name]) for name in ("front", "side")]
    fig = SkeletonFigure(panels, lo, hi, (w, h))
    head = (f"{c['video_id'].rsplit('/', 1)[-1][:8]}  clip {c['clip_id']}  "
            f"{CLASS_NAMES[c['label']] if c['label'] < 2 else c['label']}")
    ks = [frame_position(frame, L)] if fmt == "png" else list(range(L))

    def pictures():
        for k in ks:
            pose = c["pose"][k]
            yield fig.render([[pose], [pose]], f"{head}  frame {int(c['frame_idx'][k])}")

    info = {"clip": int(clip), "split": split, "space": space}
    if out is None:
        return dict(info, images=list(pictures()), path=None, format=None, frames=len(ks))
    return dict(save(out, pictures(), fps=fps), **info)
