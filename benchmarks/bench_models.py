"""Training speed of every model on the CPU, the loader in the same run, float32 vs bf16
autocast; the torch FK layer against a per-joint loop like the original; a short bf16 fit.

For each model: clips per second of whole training steps (loader wait + forward + loss +
backward + AdamW step) with a ``ClipDataset`` train loader (2 workers by default, the
report's deformation: noise 5 px, MJP 0.2944 on 2D inputs), the share of the step time
spent waiting for the next batch, in float32 and under ``torch.autocast("cpu",
torch.bfloat16)``. The first ``--warmup`` steps (worker start-up, allocator) are not
timed.

    PYTHONPATH=python python benchmarks/bench_models.py [--steps 2] [--warmup 1]
        [--batch 256] [--clip-length 30] [--workers 2] [--models task/name,...]
        [--precision fp32,bf16] [--bf16-batch N] [--sections speed,fk,fit] [--h5 FILE]

Per-model batch overrides (``--batch-override poseformer=8,pose_cnn=8``) keep the heavy
models to seconds per step; clips/s is per clip either way.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np
import torch

TWO_D_NOISE = dict(noise=5.0, mjp=0.2944)
DEFAULT_OVERRIDES = "poseformer=8,pose_cnn=8"


def cpu_info() -> dict:
    from bsp_fast.training.precision import cpu_flags, cpu_summary

    native = [f for f in cpu_flags() if f in ("avx512_bf16", "amx_bf16")]
    return {"cpu": cpu_summary(), "capability": torch.backends.cpu.get_cpu_capability(),
            "bf16_native": native,
            "threads": torch.get_num_threads(), "cores": os.cpu_count()}


def _rate(v: float) -> str:
    """Clips/s: thousands separators, two significant digits below 10 (PoseFormer: ~1)."""
    return f"{v:,.0f}" if v >= 10 else f"{v:.2g}"


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


# ----------------------------------------------------------------------------- data
def fixture(work: str, clips: int, L: int, media: bool) -> str:
    from bsp_fast.data.testing import write_clip_file

    path = os.path.join(work, f"bench-L{L}-{clips}{'-media' if media else ''}.h5")
    if not os.path.exists(path):
        write_clip_file(path, clips=(clips, 16, 16), clip_length=L, clip_offset=L // 2,
                        frames_per_recording=8 * L, seed=1, rotations=False, media=media,
                        crop_size=128)
    return path


# ----------------------------------------------------------------------------- speed
def time_training(model, loader, steps: int, warmup: int, bf16: bool) -> dict:
    opt = model.configure_optimizers()["optimizer"]
    model.train()
    it = iter(loader)
    wait = comp = 0.0
    clips = 0
    for k in range(warmup + steps):
        t0 = time.perf_counter()
        try:
            batch = next(it)
        except StopIteration:
            it = iter(loader)
            batch = next(it)
        t1 = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = model.forward_batch(batch)
            loss = model.loss(out, batch)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        t2 = time.perf_counter()
        if k >= warmup:
            wait += t1 - t0
            comp += t2 - t1
            clips += len(batch["inputs"])
    total = wait + comp
    return {"clips_s": clips / total, "wait_share": wait / total, "step_s": total / steps,
            "loss": loss.item()}


def speed_section(args, work: str) -> None:
    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    overrides = dict(kv.split("=") for kv in args.batch_override.split(",") if kv)
    wanted = [m.split("/") for m in args.models.split(",")] if args.models else \
        [(t, n) for t in models.TASKS for n in models.available(t)]
    precisions = args.precision.split(",")
    info = cpu_info()
    if args.bf16_batch < 0:
        args.bf16_batch = 0 if info["bf16_native"] else 32
    print(f"\n## Training speed (batch {args.batch}, L = {args.clip_length}, "
          f"{args.workers} loader workers, {args.steps} timed steps after {args.warmup})")
    print(f"CPU capability {info['capability']}, native bf16: {info['bf16_native'] or 'no'}, "
          f"torch threads {info['threads']}, {load()}")
    head = "| model | batch | " + " | ".join(
        f"{p} clips/s | {p} wait %" for p in precisions) + " |"
    print(head)
    print("|" + "---|" * (2 + 2 * len(precisions)))
    for task, name in wanted:
        B = int(overrides.get(name, args.batch))
        media = task == "pose_estimation"
        h5 = args.h5 or fixture(work, args.train_clips if not media else args.media_clips,
                                args.clip_length, media)
        kw = {} if media else dict(TWO_D_NOISE)
        ds = ClipDataset(h5, "train", task, **kw)
        loader = ds.loader(B, num_workers=args.workers, drop_last=True, sampler_seed=0)
        torch.manual_seed(0)
        model = models.create(task, name)
        cells = []
        for p in precisions:
            bf16 = p == "bf16"
            if bf16 and args.bf16_batch and args.bf16_batch < B:
                bl = ds.loader(args.bf16_batch, num_workers=args.workers, drop_last=True,
                               sampler_seed=0)
                r = time_training(model, bl, args.steps, args.warmup, True)
                cells.append(f"{_rate(r['clips_s'])} (B={args.bf16_batch}) | "
                             f"{100 * r['wait_share']:.1f}")
                del bl
            else:
                r = time_training(model, loader, args.steps, args.warmup, bf16)
                cells.append(f"{_rate(r['clips_s'])} | {100 * r['wait_share']:.1f}")
        print(f"| {task}/{name} | {B} | " + " | ".join(cells) + " |", flush=True)
        del loader
    print(load())


# ----------------------------------------------------------------------------- FK
def original_fk(rel_loc, rel_rot_col, parents):
    """The original's algorithm (pedestrians-video-2-carla ``P3dPose``): a recursive walk,
    one joint at a time, 4x4 homogeneous transforms in the row-vector convention,
    ``torch.bmm`` and in-place writes into the output tensors."""
    children = {j: [c for c, p in enumerate(parents) if p == j] for j in range(len(parents))}
    rel_rot = rel_rot_col.transpose(-1, -2)
    n = rel_loc.shape[0]
    absolute_loc = torch.zeros_like(rel_loc)
    absolute_rot = torch.zeros_like(rel_rot)
    eye = torch.eye(4, dtype=rel_loc.dtype).reshape(1, 4, 4)

    def walk(idx, prev):
        pad = torch.nn.functional.pad(rel_loc[:, idx:idx + 1], (0, 1, 0, 0), value=1)
        absolute_loc[:, idx] = torch.bmm(pad, prev)[:, 0, :3]
        absolute_rot[:, idx] = torch.bmm(rel_rot[:, idx], prev[:, :3, :3])
        new = eye.repeat(n, 1, 1)
        new[:, :3, :3] = absolute_rot[:, idx]
        new[:, 3, :3] = absolute_loc[:, idx]
        for c in children[idx]:
            walk(c, new)

    walk(0, eye.repeat(n, 1, 1))
    return absolute_loc


def fk_section(args) -> None:
    from bsp_fast import skeleton as sk
    from bsp_fast.models.kinematics import ForwardKinematics, rotation_6d_to_matrix

    N = args.batch * args.clip_length
    g = torch.Generator().manual_seed(0)
    R = rotation_6d_to_matrix(torch.randn(N, 26, 6, generator=g))
    off = torch.randn(N, 26, 3, generator=g) * 0.2
    fk = ForwardKinematics()
    Rpl, offpl = R.permute(1, 2, 3, 0).contiguous(), off.permute(1, 2, 0).contiguous()
    err = (original_fk(off[:64].double(), R[:64].double(), sk.PARENTS)
           - fk(R[:64].double(), off[:64].double())).abs().max().item()

    def timed(fn, x0):
        best = float("inf")
        for _ in range(args.fk_repeat):
            x = x0.clone().requires_grad_()
            t = time.perf_counter()
            fn(x).sum().backward()
            best = min(best, time.perf_counter() - t)
        return best

    t_orig = timed(lambda x: original_fk(off, x, sk.PARENTS), R)
    t_layer = timed(lambda x: fk(x, off), R)
    t_pl = timed(lambda x: fk(x, offpl, poses_last=True), Rpl)
    print(f"\n## Forward kinematics, {N:,} poses (batch {args.batch} x L {args.clip_length}), "
          f"forward + backward, best of {args.fk_repeat}")
    print(f"max |difference| to the original's algorithm (float64): {err:.1e} m; {load()}")
    print("| implementation | ms | speed-up |")
    print("|---|---|---|")
    print(f"| per-joint loop like the original (4x4 bmm, recursive) | {1e3 * t_orig:.1f} | 1.0x |")
    print(f"| ForwardKinematics, (..., J, 3, 3) inputs | {1e3 * t_layer:.1f} | "
          f"{t_orig / t_layer:.1f}x |")
    print(f"| ForwardKinematics, poses-last (as lstm_relative_rot) | {1e3 * t_pl:.1f} | "
          f"{t_orig / t_pl:.1f}x |")


# ----------------------------------------------------------------------------- bf16 fit
def fit_section(args, work: str) -> None:
    """Same init, same batches, float32 vs bf16 autocast: final training-data metrics."""
    from bsp_fast import models
    from bsp_fast.data import ClipDataset

    h5 = fixture(work, 256, 16, False)
    print(f"\n## Short fit, float32 vs bf16 autocast ({args.fit_steps} steps, 256 train "
          f"clips, L = 16, batch 32, evaluated in float32 on the training clips); {load()}")
    print("| model | metric | float32 | bf16 autocast |")
    print("|---|---|---|---|")
    cases = [("autoencoder", "simple_transformer", dict(TWO_D_NOISE), 1e-3),
             ("lifting", "baseline_3d", {"lifting_target": "camera"}, 1e-3),
             ("lifting", "lstm_relative_rot", {"lifting_target": "camera"}, 3e-3)]
    for task, name, kw, lr in cases:
        ds = ClipDataset(h5, "train", task, augment=False, seed=0, **kw)
        data = [ds[i:i + 32] for i in range(0, len(ds), 32)]
        res = {}
        for p in ("fp32", "bf16"):
            torch.manual_seed(0)
            model = models.create(task, name)
            opt = model.configure_optimizers(lr=lr)["optimizer"]
            model.train()
            for s in range(args.fit_steps):
                b = data[s % len(data)]
                with torch.autocast("cpu", dtype=torch.bfloat16, enabled=p == "bf16"):
                    loss = model.loss(model.forward_batch(b), b)
                opt.zero_grad()
                loss.backward()
                opt.step()
            res[p] = _fit_metrics(model, data, task)
        for metric in res["fp32"]:
            print(f"| {task}/{name} | {metric} | {res['fp32'][metric]:.4f} | "
                  f"{res['bf16'][metric]:.4f} |")


def _fit_metrics(model, data, task) -> dict:
    model.eval()
    loss = n = err = 0.0
    with torch.no_grad():
        for b in data:
            out = model.forward_batch(b)
            loss += model.loss(out, b).item() * len(out)
            n += len(out)
            if task == "lifting":  # MPJPE in mm after de-normalising with the target scale
                t = b["targets"][:, model.frame_slice(b["targets"].shape[1])]
                s = b["target_scale"][:, model.frame_slice(b["targets"].shape[1])]
                err += ((out - t).norm(dim=-1) * s[..., None]).mean().item() * 1000 * len(out)
    out = {"training loss": loss / n}
    if task == "lifting":
        out["MPJPE mm (hips-aligned)"] = err / n
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sections", default="speed,fk,fit", help="speed,fk,fit (all)")
    ap.add_argument("--models", default="", help="task/name,... (default: every model)")
    ap.add_argument("--precision", default="fp32,bf16", help="fp32,bf16")
    ap.add_argument("--steps", type=int, default=2, help="timed training steps (2)")
    ap.add_argument("--warmup", type=int, default=1, help="untimed first steps (1)")
    ap.add_argument("--batch", type=int, default=256, help="clips per batch (256)")
    ap.add_argument("--batch-override", default=DEFAULT_OVERRIDES,
                    help=f"per-model batch sizes name=B,... ({DEFAULT_OVERRIDES})")
    ap.add_argument("--bf16-batch", type=int, default=-1,
                    help="batch of the bf16 runs: 0 = as float32; -1 (default) = 32 on CPUs "
                         "without native bf16 (emulated bf16 is several times slower), else "
                         "as float32")
    ap.add_argument("--clip-length", type=int, default=30, help="frames per clip (30)")
    ap.add_argument("--workers", type=int, default=2, help="DataLoader workers (2)")
    ap.add_argument("--train-clips", type=int, default=1200, help="fixture train clips (1200)")
    ap.add_argument("--media-clips", type=int, default=48,
                    help="fixture train clips with 128x128 crops (48)")
    ap.add_argument("--h5", default=None, help="use this converted file instead of a fixture")
    ap.add_argument("--fk-repeat", type=int, default=3, help="FK timing repeats (3)")
    ap.add_argument("--fit-steps", type=int, default=40, help="steps of the bf16 fit (40)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch default)")
    args = ap.parse_args(argv)
    sys.stdout.reconfigure(line_buffering=True)
    if args.threads:
        torch.set_num_threads(args.threads)
    sections = set(args.sections.split(","))
    bad = sections - {"speed", "fk", "fit"}
    if bad:
        ap.error(f"--sections: unknown {sorted(bad)}; allowed speed, fk, fit")
    print(f"# bench_models: torch {torch.__version__}, {cpu_info()}, {load()}")
    with tempfile.TemporaryDirectory(prefix="bench_models-") as work:
        if "fk" in sections:
            fk_section(args)
        if "speed" in sections:
            speed_section(args, work)
        if "fit" in sections:
            fit_section(args, work)
    print(f"\n# done; {load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
