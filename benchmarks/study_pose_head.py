"""Pose estimation head study: direct regression vs heatmaps + soft-argmax (PoseCNN).

Renders a small bsp-synth dataset, converts it with 128 x 128 crops, trains PoseCNN with
each head for the same number of steps (same seed, same batches: short clips cut at
random from the train split) and reports, on the val split, the mean error in crop
pixels and PCK@0.05 (bounding-box diagonal) over visible joints, next to the mean crop
skeleton. Used to pick the default head (docs/models.md).

    PYTHONPATH=python python benchmarks/study_pose_head.py [--clips 48] [--steps 600]
        [--width 16] [--frames 16] [--batch 2] [--threads 2] [--work DIR]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch


def make_data(work: str, clips: int, seed: int) -> str:
    import bsp_fast
    from bsp_fast.synth import generate

    h5 = os.path.join(work, "clips.h5")
    if not os.path.exists(h5):
        generate(os.path.join(work, "ds"), "sample", clips=clips, frames=150, seed=seed,
                 workers=1, progress=False, force=True)
        bsp_fast.convert(os.path.join(work, "ds"), h5, clip_length=16, clip_offset=4,
                         media=True, crop_size=128, force=True)
    return h5


def pck_and_error(pred, gt, vis, alpha=0.05):
    """PCK@alpha with the gt joint bbox diagonal, and mean pixel error, visible joints."""
    v = vis.bool()
    big = torch.where(v.unsqueeze(-1), gt, torch.full_like(gt, float("nan")))
    lo = torch.from_numpy(np.nanmin(big.numpy(), axis=-2))
    hi = torch.from_numpy(np.nanmax(big.numpy(), axis=-2))
    diag = (hi - lo).norm(dim=-1, keepdim=True)
    err = (pred - gt).norm(dim=-1)
    ok = (err <= alpha * diag) & v
    return ok.sum().item() / v.sum().item(), err[v].mean().item()


def evaluate(model, data):
    model.eval()
    preds, gts, viss = [], [], []
    with torch.no_grad():
        for b in data:
            preds.append(model(b["inputs"]))
            gts.append(b["targets"])
            viss.append(b["visible"])
    return pck_and_error(torch.cat(preds), torch.cat(gts), torch.cat(viss))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=48, help="bsp-synth clips to render (48)")
    ap.add_argument("--steps", type=int, default=600, help="training steps per head (600)")
    ap.add_argument("--width", type=int, default=16, help="PoseCNN width (16)")
    ap.add_argument("--frames", type=int, default=16,
                    help="frames per training clip, cut at random (16: whole clips, as evaluated)")
    ap.add_argument("--batch", type=int, default=2, help="clips per step (2)")
    ap.add_argument("--lr", type=float, default=1e-3, help="AdamW learning rate (1e-3)")
    ap.add_argument("--threads", type=int, default=2, help="torch threads (2)")
    ap.add_argument("--work", default="/tmp/bsp_pose_head", help="work directory")
    ap.add_argument("--seed", type=int, default=5, help="dataset and training seed (5)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    os.makedirs(args.work, exist_ok=True)
    h5 = make_data(args.work, args.clips, args.seed)
    train = ClipDataset(h5, "train", "pose_estimation")
    val = ClipDataset(h5, "val", "pose_estimation")
    val_data = [val[i:i + 8] for i in range(0, len(val), 8)]
    rng = np.random.default_rng(args.seed)
    plan = [(rng.choice(len(train), args.batch, replace=False),
             int(rng.integers(0, train.clip_length - args.frames + 1)))
            for _ in range(args.steps)]
    trivial = models.trivial_baseline("pose_estimation").fit(
        train[i:i + 16] for i in range(0, len(train), 16))
    pck, err = evaluate(trivial, val_data)
    print(f"train {len(train)} clips, val {len(val)} clips, crops 128, load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"{'head':12s} {'val PCK@0.05':>12s} {'val px err':>10s} {'train s':>8s}")
    print(f"{'mean crop':12s} {pck:12.3f} {err:10.2f} {'-':>8s}")
    for head in ("regression", "heatmap"):
        torch.manual_seed(args.seed)
        model = models.create("pose_estimation", "pose_cnn", width=args.width, head=head)
        opt = model.configure_optimizers(lr=args.lr)["optimizer"]
        t0 = time.perf_counter()
        model.train()
        for idx, t in plan:
            b = train[np.sort(idx).tolist()]
            sl = slice(t, t + args.frames)
            batch = {"inputs": b["inputs"][:, sl], "targets": b["targets"][:, sl],
                     "visible": b["visible"][:, sl]}
            loss = model.loss(model(batch["inputs"]), batch)
            opt.zero_grad()
            loss.backward()
            opt.step()
        secs = time.perf_counter() - t0
        pck, err = evaluate(model, val_data)
        print(f"{head:12s} {pck:12.3f} {err:10.2f} {secs:8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
