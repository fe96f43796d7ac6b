"""Prints what a bsp-convert HDF5 file holds: settings, per-split datasets and a sample clip.

    python tools/h5_summary.py out.h5
"""
from __future__ import annotations

import sys

import h5py
import numpy as np


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    with h5py.File(argv[0], "r") as f:
        keys = ("schema_version", "clip_length", "clip_stride", "eval_clip_stride", "label_rule",
                "fov", "seed", "source_crc32")
        print(", ".join(f"{k}={f.attrs[k]}" for k in keys if k in f.attrs))
        for split in ("train", "val", "test"):
            g = f[split]
            n = g["labels"].shape[0]
            counts = g.attrs["class_counts"]
            print(f"/{split}: {n} clips ({counts[0]} not-crossing, {counts[1]} crossing)")
        g = next((f[s] for s in ("train", "val", "test") if f[s]["labels"].shape[0]), None)
        if g is None:
            return 0
        print("datasets:")
        g.visititems(lambda name, obj: print(f"  {name:28s} {obj.shape} {obj.dtype}")
                     if isinstance(obj, h5py.Dataset) else None)
        uv = g["projection_2d"][0]
        loc = g["targets/world_pose_loc"][0]
        print(f"clip 0 of /{g.name.strip('/')}: {g['meta/video_id'].asstr()[0]} frames "
              f"{g['meta/start_frame'][0]}..{g['meta/end_frame'][0] - 1}, label {g['labels'][0]}; "
              f"pixels u {np.nanmin(uv[..., 0]):.0f}..{np.nanmax(uv[..., 0]):.0f}, "
              f"hips height {loc[:, 1, 2].mean():.2f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
