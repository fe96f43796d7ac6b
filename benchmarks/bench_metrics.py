"""PA-MPJPE on 1,000,000 frames x 26 joints: bsp_fast.metrics.pa_mpjpe vs plain NumPy.

Both compute the same formula (per frame: centre, scale to unit norm, SVD of the 3x3
cross-covariance, reflection fix, align, mean joint error), in float64, on the same float32
poses (mm), side by side in one process:

* ``bsp_fast``: ``bsp_fast.metrics.pa_mpjpe(pred, gt)`` (batched one-sided Jacobi SVD on
  coordinate planes, blocks of 8192 frames, single thread);
* ``numpy batched``: what a user writes with NumPy: stacked ``matmul`` for the 3x3
  matrices and ``np.linalg.svd``/``np.linalg.det`` on the (N, 3, 3) stack, run in blocks
  of 100,000 frames to bound memory (4 GB at once otherwise; blocking does not slow it);
* ``numpy per-frame loop``: the same with a Python loop over frames, timed on a subset
  (``--loop-frames``) and reported per frame (a 1M-frame loop takes minutes).

The machine may be shared: wall and CPU (process) time are both printed, with the load
average; the ratio is the number to quote.

    python benchmarks/bench_metrics.py [--frames 1000000] [--repeat 2] [--loop-frames 20000]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import bsp_fast as bf
from bsp_fast import metrics
from bsp_fast import skeleton as sk


def make_poses(frames: int, seed: int = 0):
    """float32 (frames, 26, 3) mm: T-pose + per-frame jitter, prediction = rotated, scaled,
    shifted, noisy copy (every tenth frame mirrored)."""
    rng = np.random.default_rng(seed)
    base = (bf.forward_kinematics(sk.reference_pose("sk_male"))[:, :3] * 1000).astype(np.float32)
    gt = np.empty((frames, 26, 3), np.float32)
    pred = np.empty_like(gt)
    step = 100_000
    for s in range(0, frames, step):
        n = min(step, frames - s)
        g = base + rng.normal(0, 60, (n, 26, 3)).astype(np.float32)
        a = rng.uniform(-0.3, 0.3, n)
        c, si = np.cos(a), np.sin(a)
        R = np.zeros((n, 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -si, si, c, 1
        p = 1.1 * np.einsum("njk,nik->nji", g, R) + rng.normal(0, 40, (n, 26, 3)) + [30, 0, 0]
        p[::10, :, 2] *= -1
        gt[s:s + n], pred[s:s + n] = g, p
    return pred, gt


def numpy_batched(pred, gt):
    """The straightforward vectorised NumPy PA-MPJPE (sum of joint errors, count)."""
    X = gt.astype(np.float64)
    Y = pred.astype(np.float64)
    muX, muY = X.mean(1, keepdims=True), Y.mean(1, keepdims=True)
    X0, Y0 = X - muX, Y - muY
    nX = np.sqrt((X0 ** 2).sum(axis=(1, 2), keepdims=True))
    nY = np.sqrt((Y0 ** 2).sum(axis=(1, 2), keepdims=True))
    X0, Y0 = X0 / nX, Y0 / nY
    H = np.matmul(X0.transpose(0, 2, 1), Y0)
    U, s, Vt = np.linalg.svd(H)
    V = Vt.transpose(0, 2, 1)
    R = np.matmul(V, U.transpose(0, 2, 1))
    sign = np.sign(np.linalg.det(R))
    V[:, :, -1] *= sign[:, None]
    s[:, -1] *= sign
    R = np.matmul(V, U.transpose(0, 2, 1))
    a = s.sum(1)[:, None, None] * nX / nY
    aligned = a * np.matmul(Y - muY, R) + muX
    err = np.linalg.norm(aligned - X, axis=-1)
    return err.sum(), err.size


def numpy_loop(pred, gt):
    """The same formula one frame at a time."""
    total = 0.0
    for p, g in zip(pred.astype(np.float64), gt.astype(np.float64)):
        X0, Y0 = g - g.mean(0), p - p.mean(0)
        nX, nY = np.linalg.norm(X0), np.linalg.norm(Y0)
        U, s, Vt = np.linalg.svd((X0 / nX).T @ (Y0 / nY))
        V = Vt.T
        if np.linalg.det(V @ U.T) < 0:
            V[:, -1] *= -1
            s[-1] *= -1
        R = V @ U.T
        total += np.linalg.norm(s.sum() * nX / nY * Y0 @ R - X0, axis=-1).sum()
    return total, pred.shape[0] * pred.shape[1]


def timed(fn, repeat):
    best = None
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        w, c = time.perf_counter() - w, time.process_time() - c
        if best is None or w < best[0]:
            best = (w, c, out)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000, help="frames (default 1e6)")
    ap.add_argument("--repeat", type=int, default=2, help="runs per method; best wall time")
    ap.add_argument("--loop-frames", type=int, default=20_000,
                    help="subset timed with the per-frame Python loop (0: skip)")
    ap.add_argument("--block", type=int, default=100_000,
                    help="frames per block of the batched NumPy baseline")
    args = ap.parse_args(argv)
    if args.frames < 1 or args.repeat < 1 or args.loop_frames < 0 or args.block < 1:
        ap.error("--frames, --repeat and --block must be >= 1, --loop-frames >= 0")
    pred, gt = make_poses(args.frames)
    F = args.frames
    print(f"PA-MPJPE, {F} frames x 26 joints, float32 in, float64 math; "
          f"load average before: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")

    def ours():
        return float(metrics.pa_mpjpe(pred, gt))

    def batched():
        total = count = 0
        for s in range(0, F, args.block):
            t, c = numpy_batched(pred[s:s + args.block], gt[s:s + args.block])
            total, count = total + t, count + c
        return total / count

    rows = []
    for name, fn in (("bsp_fast", ours), ("numpy batched", batched)):
        w, c, value = timed(fn, args.repeat)
        rows.append((name, F, w, c, value))
    if args.loop_frames:
        n = min(args.loop_frames, F)
        w, c, (t, k) = timed(lambda: numpy_loop(pred[:n], gt[:n]), 1)
        rows.append(("numpy per-frame loop", n, w, c, t / k))
    print(f"{'method':<22}{'frames':>9}{'wall s':>9}{'CPU s':>8}{'frames/s':>12}"
          f"{'CPU us/frame':>14}{'PA-MPJPE mm':>14}")
    for name, n, w, c, value in rows:
        print(f"{name:<22}{n:>9}{w:>9.2f}{c:>8.2f}{n / w:>12,.0f}{c / n * 1e6:>14.2f}"
              f"{value:>14.6f}")
    ref = rows[0]
    for name, n, w, c, value in rows[1:]:
        print(f"bsp_fast vs {name}: {(w / n) / (ref[2] / ref[1]):.1f}x (wall), "
              f"{(c / n) / (ref[3] / ref[1]):.1f}x (CPU)")
    subset = float(metrics.pa_mpjpe(pred[: rows[-1][1]], gt[: rows[-1][1]]))
    print(f"|bsp_fast - numpy batched| = {abs(ref[4] - rows[1][4]):.2e} mm"
          + (f"; on the loop's subset {abs(subset - rows[2][4]):.2e} mm" if len(rows) > 2 else ""))
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
