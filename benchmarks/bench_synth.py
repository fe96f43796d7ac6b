"""bsp-synth: throughput on this machine and the projected time of the whole full preset.

1. Stages of one full-preset clip (900 frames at 1600x600) in this process, one thread:
   CPU seconds of planning (street, walk, gait, FK, projection), the background ray cast,
   the pedestrian pass, H.264 encoding, APNG encoding and the CSV rows.
2. End to end: ``generate(preset="full", clips=K, workers=W)``; wall and CPU seconds per
   clip, and the projection to the preset's 396 clips with W workers.
3. The full preset's statistics over its first N clips (no rendering needed: they depend
   on the walk and the camera only) next to the published CARLA-BSP numbers.

The machine may be shared: CPU seconds are the stable number, wall seconds what you wait.

    python benchmarks/bench_synth.py [--clips 4] [--workers 2] [--stats-clips 396]
"""
from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time

import numpy as np

from bsp_fast import csvio
from bsp_fast._native import core
from bsp_fast.media import ApngWriter, VideoWriter
from bsp_fast.synth import body, clip, generate
from bsp_fast.synth.config import make_config

PUBLISHED = dict(clips=396, annotated=225_327, crossing=91_864, frames=396 * 900,
                 per_profile={"adult_female": (88, 49_951), "adult_male": (109, 60_775),
                              "child_female": (100, 55_755), "child_male": (99, 58_846)})


class Stopwatch:
    def __init__(self):
        self.cpu: dict = {}

    def __call__(self, name):
        sw = self

        class _T:
            def __enter__(self):
                self.t = time.process_time()

            def __exit__(self, *exc):
                sw.cpu[name] = sw.cpu.get(name, 0.0) + time.process_time() - self.t
        return _T()


def stages(index: int, tmp: str) -> dict:
    """CPU seconds per stage for clip `index` of the full preset (threads = 1)."""
    cfg = make_config("full")
    sw = Stopwatch()
    with sw("plan+poses"):
        cp = clip.plan_clip(cfg, index)
        pf = clip.pose_columns(cp, cfg)
    with sw("background"):
        tabs = clip.build_scene(cp)
        bg = core.render_background(tabs.road, tabs.bands, tabs.boxes, tabs.cylinders,
                                    tabs.spheres, tabs.light, cp.camera, cfg.width,
                                    cfg.height, cfg.camera_fov, 1)
    yaw = np.radians(cp.path.yaw)
    caps = body.body_capsules(pf["world"][..., :3],
                              np.stack([np.cos(yaw), np.sin(yaw), 0 * yaw], -1))
    cols = body.sample_colours(cp.rng_look)
    visible = np.zeros(len(caps), bool)
    with VideoWriter(os.path.join(tmp, "v.mp4"), cfg.width, cfg.height) as vw, \
            ApngWriter(os.path.join(tmp, "s.apng"), cfg.width, cfg.height) as aw:
        for f0 in range(0, len(caps), clip.CHUNK):
            with sw("pedestrian"):
                rgb, tags, vis = core.render_bodies(
                    *bg, cp.camera, cfg.camera_fov, tabs.light,
                    np.ascontiguousarray(caps[f0:f0 + clip.CHUNK]), cols, 1)
            visible[f0:f0 + clip.CHUNK] = vis
            with sw("mp4"):
                vw.write(rgb)
            with sw("apng"):
                aw.write(tags)
        with sw("mp4"):
            vw.close()
        with sw("apng"):
            aw.close()
    with sw("csv"):
        csvio.write_csv(os.path.join(tmp, "part.csv"),
                        clip.csv_columns(cp, cfg, pf, visible), threads=1)
    sw.cpu["annotated_rows"] = int(pf["annotated"].sum())
    return sw.cpu


def statistics(n: int) -> dict:
    cfg = make_config("full", dict(number_of_clips=n))
    tot = dict(frames=0, annotated=0, crossing=0, crossing_clips=0)
    prof: dict = {}
    for i in range(n):
        cp = clip.plan_clip(cfg, i)
        pf = clip.pose_columns(cp, cfg)
        a = pf["annotated"]
        tot["frames"] += len(a)
        tot["annotated"] += int(a.sum())
        tot["crossing"] += int((a & pf["frame.pedestrian.is_crossing"]).sum())
        tot["crossing_clips"] += int(cp.plan.crossing)
        p = prof.setdefault(cp.profile.name, [0, 0])
        p[0] += 1
        p[1] += int(a.sum())
    tot["per_profile"] = prof
    return tot


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=4, help="full-preset clips generated end to "
                    "end (default: %(default)s)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default: "
                    "%(default)s)")
    ap.add_argument("--stats-clips", type=int, default=396, help="clips for the statistics "
                    "(default: the whole preset)")
    ap.add_argument("--skip-stages", action="store_true", help="skip the per-stage run")
    args = ap.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix="bench_synth-")
    try:
        if not args.skip_stages:
            st = stages(0, tmp)
            rows = st.pop("annotated_rows")
            total = sum(st.values())
            print(f"one full-preset clip (900 frames, 1600x600, 1 thread, {rows} rows): "
                  f"{total:.1f} CPU s")
            for k, v in st.items():
                print(f"  {k:11s} {v:7.2f} s  {1000 * v / 900:6.2f} ms/frame  "
                      f"{100 * v / total:5.1f} %")
        t0, c0 = time.perf_counter(), os.times()
        s = generate(os.path.join(tmp, "ds"), "full", clips=args.clips, workers=args.workers,
                     progress=False)
        wall = time.perf_counter() - t0
        c1 = os.times()
        cpu = (c1.children_user + c1.children_system + c1.user + c1.system) - \
            (c0.children_user + c0.children_system + c0.user + c0.system)
        per_clip = wall / args.clips
        print(f"\ngenerate(full, clips={args.clips}, workers={args.workers}): {wall:.1f} s wall, "
              f"{cpu:.1f} s CPU ({per_clip:.1f} s wall / clip, {cpu / args.clips:.1f} s CPU / "
              f"clip, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})")
        print(f"projected full preset (396 clips, {args.workers} workers): "
              f"{396 * per_clip / 3600:.2f} h wall; CPU-bound estimate "
              f"{396 * cpu / args.clips / args.workers / 3600:.2f} h")
        size = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(s["out_dir"])
                   for f in fs)
        print(f"dataset size per clip: {size / args.clips / 1e6:.1f} MB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if args.stats_clips:
        t = statistics(args.stats_clips)
        pub = PUBLISHED
        print(f"\nstatistics over {args.stats_clips} full-preset clips (published in brackets):")
        print(f"  annotated share {t['annotated'] / t['frames']:.3f} "
              f"({pub['annotated'] / pub['frames']:.3f}), crossing share of annotated "
              f"{t['crossing'] / max(t['annotated'], 1):.3f} "
              f"({pub['crossing'] / pub['annotated']:.3f}), crossing clips "
              f"{t['crossing_clips']}/{args.stats_clips}")
        for name, (n, a) in sorted(t["per_profile"].items()):
            pn, pa = pub["per_profile"][name]
            print(f"  {name:13s} {n:4d} clips ({pn}), {a / n:6.1f} annotated frames / clip "
                  f"({pa / pn:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
