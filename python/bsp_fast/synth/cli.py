"""Command line of bsp-synth (console script ``bsp-synth``)."""
from __future__ import annotations

import argparse
import sys

from ..command_line import ArgumentParser, run_command


def _preset(name: str) -> str:
    """'N clips x F frames at WxH' of a preset, from the preset table itself."""
    from .config import PRESETS

    p = PRESETS[name]
    w, h = p["camera_image_size"]
    return f"{p['number_of_clips']} clips x {p['clip_length_in_frames']} frames at {w}x{h}"


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-synth",
        description="Generate a CARLA-BSP-format dataset (data.csv, clips/<id>-0.mp4 RGB, "
                    "clips/<id>-1.apng segmentation, config.yaml) without a simulator: a "
                    "procedural street, one walking pedestrian per clip, a static camera "
                    "placed as the original recorder did.",
        epilog="Exit codes (docs/architecture.md): 0 success, 1 a generation error or a "
               "missing or unreadable --config or --motion file, 2 bad option or config "
               "value (or OUT_DIR is or holds the --config or --motion file, --force or "
               "not), 3 OUT_DIR exists (use --force), 130 interrupted.")
    p.add_argument("out_dir", metavar="OUT_DIR", help="output directory (must not exist "
                   "unless --force); built as .OUT_DIR.tmp-* and renamed when complete")
    p.add_argument("--preset", choices=("sample", "medium", "full"), default="sample",
                   help=f"sample: {_preset('sample')} (seconds); medium: {_preset('medium')} "
                        "(the report's experiments on 2 cores, under 10 min); full: "
                        f"{_preset('full')}, the published dataset's shape (default: "
                        "%(default)s)")
    p.add_argument("--clips", type=int, metavar="N", help="number of clips (overrides preset "
                   "and config number_of_clips)")
    p.add_argument("--frames", type=int, metavar="N", help="frames per clip at 30 fps "
                   "(overrides clip_length_in_frames)")
    p.add_argument("--size", metavar="WxH", help="image size, e.g. 1600x600; both even "
                   "(overrides camera_image_size)")
    p.add_argument("--fov", type=float, metavar="DEG", help="horizontal field of view in "
                   "degrees (default 90; overrides camera_fov)")
    p.add_argument("--seed", type=int, metavar="S", help="random seed (default 22752); the "
                   "same seed gives byte-identical output for any --workers")
    p.add_argument("--workers", type=int, metavar="N", help="worker processes, one clip each "
                   "at a time (default: CPU count)")
    p.add_argument("--scheduler", default="threads", metavar="threads|dask|dask:ADDRESS",
                   help="threads: --workers local processes (default); dask: a local Dask "
                        "cluster, one worker process per core; dask:ADDRESS: an existing Dask "
                        "scheduler (OUT_DIR on a filesystem the workers share). One task per "
                        "clip; the output is byte-identical")
    p.add_argument("--config", metavar="cfg.yaml", help="YAML with the original generator's "
                   "keys: number_of_clips, clip_length_in_frames, pedestrian_distributions "
                   "([[age, gender, [walk mean, std], [cross mean, std]], weight] or "
                   "[profile name, weight]), camera_position_distributions, camera_fov, "
                   "camera_image_size, batch_size (clips sharing a street), seed")
    p.add_argument("--motion", metavar="FILE", help="BVH, FBX or glTF animation (read with "
                   "assimp) retargeted onto the CARLA skeleton instead of the procedural gait "
                   "(joint-name map: docs/synth.md)")
    p.add_argument("--apng-drop-duplicates", action="store_true", help="store identical "
                   "consecutive segmentation frames once, like the original writer (default: "
                   "one APNG frame per video frame)")
    p.add_argument("--poses-only", action="store_true", help="write data.csv and config.yaml "
                   "(with poses_only: true) but no MP4/APNG files: data.csv is byte-identical "
                   "to a full run with the same options (media paths kept, in_segmentation "
                   "still ray-cast), several times faster; for the pose tasks (bsp-convert "
                   "--no-media)")
    p.add_argument("--bone-length-variation", type=float, metavar="V", help="scale each "
                   "walker's bone offsets by a seeded factor in [1-V, 1+V], V < 0.5 (default 0: "
                   "the profiles' reference skeletons exactly; overrides "
                   "bone_length_variation); changes no other random draw")
    p.add_argument("--force", action="store_true", help="replace OUT_DIR if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    return p


def _print_summary(s: dict) -> None:
    print(f"wrote {s['clips']} clips to {s['out_dir']} in {s['seconds']:.1f} s "
          f"({s['clips_per_second']:.3f} clips/s)"
          + ("; poses only: no MP4/APNG written" if s.get("poses_only") else ""))
    empty = s["clips"] - s["recordings"]
    if empty:
        print(f"{s['recordings']} recordings: in {empty} clip(s) the walker never enters the "
              "view (no rows, no media files)")
    print(f"annotated frames: {s['annotated_frames']} of {s['frames']} "
          f"({100 * s['annotated_share']:.1f} %), crossing: {s['crossing_frames']} "
          f"({100 * s['crossing_share']:.1f} % of annotated), crossing clips: "
          f"{s['crossing_clips']}")
    for name, p in s["per_profile"].items():
        print(f"  {name:13s} {p['clips']:4d} clips {p['annotated_frames']:8d} annotated frames "
              f"{p['crossing_clips']:4d} crossing")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run_command("bsp-synth", _main, args)


def _main(args) -> int:
    from ..atomic import check_outputs
    from ..dask_cluster import run_on_scheduler

    # before any work: OUT_DIR (replaced whole with --force) holds no input
    check_outputs(inputs=[("the --config file", args.config),
                          ("the --motion file", args.motion)],
                  outputs=[("OUT_DIR", args.out_dir)])
    return run_on_scheduler(args.scheduler, "bsp-synth", lambda c: _generate(args, c))


def _generate(args, client) -> None:
    from .generate import generate

    try:
        summary = generate(args.out_dir, args.preset, clips=args.clips, frames=args.frames,
                           size=args.size, fov=args.fov, seed=args.seed, workers=args.workers,
                           config=args.config, motion=args.motion,
                           apng_drop_duplicates=args.apng_drop_duplicates,
                           poses_only=args.poses_only,
                           bone_length_variation=args.bone_length_variation, force=args.force,
                           progress=not args.quiet, client=client)
    except KeyboardInterrupt:
        raise KeyboardInterrupt("nothing written to OUT_DIR") from None
    if not args.quiet:
        _print_summary(summary)


if __name__ == "__main__":
    sys.exit(main())
