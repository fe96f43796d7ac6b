"""Forward kinematics + projection: bsp_fast's C++ core vs a vectorised NumPy implementation.

Both compute, for N frames of 26 bones: world bones = walker ∘ M ∘ FK(relative), then the
pixels of the 26 world joints through a 1600x600, 90 deg camera. Run side by side in the
same process; the machine is noisy, so the ratio is the number to quote.

    python benchmarks/bench_kinematics.py [--frames 1000000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import bsp_fast as bf
from bsp_fast import skeleton as sk


def np_rot(pyr):
    p, y, r = (np.deg2rad(pyr[..., i]) for i in range(3))
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    R = np.empty(pyr.shape[:-1] + (3, 3))
    R[..., 0, 0] = cp * cy
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = -cy * sp * cr - sy * sr
    R[..., 1, 0] = cp * sy
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = -sy * sp * cr + cy * sr
    R[..., 2, 0] = sp
    R[..., 2, 1] = -cp * sr
    R[..., 2, 2] = cp * cr
    return R


def numpy_fk_project(rel, root, cam, W=1600, H=600, fov=90.0):
    """What a user would write: batched matrices per joint, then a pinhole projection."""
    R = np_rot(rel[..., 3:])
    t = rel[..., :3]
    RR = np_rot(root[:, 3:])
    AR = np.empty_like(R)
    At = np.empty_like(t)
    AR[:, 0] = RR @ R[:, 0]
    At[:, 0] = np.einsum("nab,nb->na", RR, t[:, 0]) + root[:, :3]
    for j in range(1, 26):
        p = sk.PARENTS[j]
        AR[:, j] = AR[:, p] @ R[:, j]
        At[:, j] = np.einsum("nab,nb->na", AR[:, p], t[:, j]) + At[:, p]
    Rc = np_rot(cam[:, 3:])
    c = np.einsum("nba,njb->nja", Rc, At - cam[:, None, :3])
    f = W / (2 * np.tan(np.deg2rad(fov) / 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([W / 2 + f * c[..., 1] / c[..., 0], H / 2 - f * c[..., 2] / c[..., 0]], -1)
    uv[c[..., 0] <= 0] = np.nan
    return uv


def ours_fk_project(rel, root, cam, W=1600, H=600, fov=90.0):
    world = bf.forward_kinematics(rel, root=root)
    return bf.project(world[..., :3], cam, W, H, fov)


def make_inputs(n, seed=0):
    rng = np.random.default_rng(seed)
    ref = sk.reference_pose("sk_female")
    rel = np.empty((n, 26, 6))
    rel[:] = ref
    rel[..., 3:] += rng.normal(0, 8, (n, 26, 3))
    walker = np.zeros((n, 6))
    walker[:, 0] = rng.uniform(5, 20, n)
    walker[:, 1] = rng.uniform(-3, 3, n)
    walker[:, 2] = 0.92
    walker[:, 4] = rng.uniform(-180, 180, n)
    M = np.array([0, 0, -0.92, 0, -90, 0])
    root = bf.compose(walker, M)
    cam = np.zeros((n, 6))
    cam[:, 2] = 1.5
    return rel, root, cam


def best_of(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--chunk", type=int, default=250_000,
                    help="frames per call for both implementations (bounds NumPy's temporaries)")
    args = ap.parse_args(argv)
    rel, root, cam = make_inputs(args.frames)
    chunks = [slice(i, min(i + args.chunk, args.frames)) for i in range(0, args.frames, args.chunk)]

    def run(fn):
        return np.concatenate([fn(rel[s], root[s], cam[s]) for s in chunks])

    t_np, uv_np = best_of(lambda: run(numpy_fk_project), args.repeat)
    t_1, uv_1 = best_of(lambda: (bf.set_num_threads(1), run(ours_fk_project))[1], args.repeat)
    t_2, uv_2 = best_of(lambda: (bf.set_num_threads(2), run(ours_fk_project))[1], args.repeat)
    bf.set_num_threads(0)
    err = max(np.nanmax(np.abs(uv_np - uv_1)), np.nanmax(np.abs(uv_np - uv_2)))
    n = args.frames
    print(f"FK + projection of {n:,} frames x 26 joints (best of {args.repeat}); "
          f"max |Δuv| between implementations {err:.2e} px\n")
    print("| implementation | seconds | frames/s | vs NumPy |")
    print("|---|---:|---:|---:|")
    print(f"| NumPy (vectorised, float64) | {t_np:.2f} | {n / t_np:,.0f} | 1.0× |")
    print(f"| bsp_fast, 1 thread | {t_1:.2f} | {n / t_1:,.0f} | {t_np / t_1:.1f}× |")
    print(f"| bsp_fast, 2 threads | {t_2:.2f} | {n / t_2:,.0f} | {t_np / t_2:.1f}× |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
