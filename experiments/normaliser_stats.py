#!/usr/bin/env python3
"""What the classifiers' inputs look like under noise and missing joints: for each
(σ, MJP) of the classification grid, how often the hips–neck normaliser falls back to the
joint bounding box, over how few joints, and how large the noise is against the scale.

No model is trained: these are properties of the deformed test inputs exactly as
``ClipDataset`` hands them to the models (its fixed evaluation noise, the loaders' batches).
They test two hypotheses of docs/findings.md descriptively (not causally):

* "σ = 5 px noise is 10–25 % of a 20–50 px hips–neck normaliser";
* "at MJP ≥ 0.72 hips or neck is missing in most frames, and the bounding-box fallback over
  one or two joints gives a tiny scale".

    python experiments/normaliser_stats.py CLIPS.h5 --out runs/normaliser
    python experiments/normaliser_stats.py DATASET_DIR --out runs/normaliser   # converts
        (benchmark windows, balanced train split: the classification table's file)

Writes ``normaliser_stats.json`` and ``normaliser_stats.md`` into ``--out``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

GRID_SIGMA = (0.0, 5.0)
GRID_MJP = (0.0, 0.3, 0.7187, 0.9328)


def _clip_file(path: Path, cache: Path) -> Path:
    if path.is_file():
        return path
    from bsp_fast.data import BSPDataModule

    dm = BSPDataModule.benchmark(path, task="classification", cache_dir=cache, verbose=False)
    dm.prepare_data()
    return Path(dm.h5_path)


def cell(h5: Path, split: str, sigma: float, mjp: float, batch_size: int) -> dict:
    """Statistics of one (σ, MJP) over every frame of ``split``."""
    from bsp_fast.data import ClipDataset
    from bsp_fast.skeleton import HIPS, NECK

    ds = ClipDataset(h5, split, "classification", noise=sigma, mjp=mjp)
    fallback, nvis, scale = [], [], []
    for start in range(0, len(ds), batch_size):
        b = ds[start:start + batch_size]
        vis = b["visible"].numpy()
        direct = vis[..., HIPS] & vis[..., NECK]
        fallback.append(~direct.reshape(-1))
        nvis.append(vis.sum(-1).reshape(-1))
        scale.append(b["scale"].numpy().reshape(-1))
    fb, nv, sc = (np.concatenate(x) for x in (fallback, nvis, scale))
    usable = nv > 0  # a frame with no visible joint gets scale 1 (nothing to normalise)
    out = dict(sigma=sigma, mjp=mjp, frames=int(fb.size), clips=len(ds),
               fallback_share=float(fb.mean()),
               no_joint_share=float((~usable).mean()),
               fallback_le2_joints_share=float((fb & usable & (nv <= 2)).sum()
                                               / max(int((fb & usable).sum()), 1)))
    for name, sel in (("direct", ~fb & usable), ("fallback", fb & usable)):
        s = sc[sel]
        out[f"{name}_frames"] = int(sel.sum())
        out[f"{name}_scale_px_median"] = float(np.median(s)) if s.size else float("nan")
        out[f"{name}_scale_px_p10"] = float(np.percentile(s, 10)) if s.size else float("nan")
        out[f"{name}_noise_over_scale_median"] = (float(np.median(sigma / s)) if s.size
                                                  else float("nan"))
    return out


def _table(rows: list) -> str:
    head = ("| σ (px) | MJP | frames | fallback share | of which ≤ 2 joints | no joint | "
            "scale direct (px, median / p10) | scale fallback (px, median / p10) | "
            "σ / scale, direct (median) |\n|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for r in rows:
        lines.append(
            f"| {r['sigma']:g} | {r['mjp']:g} | {r['frames']} | {100 * r['fallback_share']:.1f} % "
            f"| {100 * r['fallback_le2_joints_share']:.1f} % | {100 * r['no_joint_share']:.1f} % "
            f"| {r['direct_scale_px_median']:.1f} / {r['direct_scale_px_p10']:.1f} "
            f"| {r['fallback_scale_px_median']:.1f} / {r['fallback_scale_px_p10']:.1f} "
            f"| {r['direct_noise_over_scale_median']:.3f} |")
    return head + "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="a converted clip file (.h5) or a dataset directory")
    p.add_argument("--out", required=True, help="folder for normaliser_stats.{json,md}")
    p.add_argument("--split", default="test", choices=("train", "val", "test"))
    p.add_argument("--batch-size", type=int, default=64,
                   help="the evaluation batch size (the noise draw is per batch)")
    p.add_argument("--sigma", type=float, nargs="+", default=list(GRID_SIGMA))
    p.add_argument("--mjp", type=float, nargs="+", default=list(GRID_MJP))
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    h5 = _clip_file(Path(args.data), out / "cache")
    rows = [cell(h5, args.split, s, m, args.batch_size) for s in args.sigma for m in args.mjp]
    from bsp_fast.atomic import write_text

    info = dict(data=str(args.data), clip_file=str(h5), split=args.split,
                batch_size=args.batch_size, seconds=time.perf_counter() - t0, rows=rows,
                command="python experiments/normaliser_stats.py " + " ".join(argv or sys.argv[1:]))
    write_text(out / "normaliser_stats.json", json.dumps(info, indent=1))
    write_text(out / "normaliser_stats.md", _table(rows))
    print(_table(rows), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
