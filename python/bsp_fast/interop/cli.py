"""``bsp-interop``: import other tools' 2D poses into clip files, export clip files to
other tools' formats, list the joint maps (docs/interop.md).

Exit codes: 0 done, 1 bad input file (the message names file, record and reason), 2 bad
option, 3 the output exists (pass --force).
"""
from __future__ import annotations

import argparse
import sys

from ..defaults import CONVERT
from ..skeletons import JOINT_SETS, coverage_table
from . import export_coco, export_videopose3d, import_coco, import_openpose
from .clipfile import clip_settings
from .exporters import FRAMES_3D, SPLIT_CHOICES
from .readers import BadInput

__all__ = ["main", "build_parser"]


def _size(text: str) -> tuple:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 1920x1080, got {text!r}") from None
    return w, h


def _clip_options(p) -> None:
    g = p.add_argument_group("clips (the rules of bsp-convert)")
    g.add_argument("--clip-length", type=int, metavar="L",
                   help=f"frames per clip (default {CONVERT['clip_length']}; "
                        f"{CONVERT['benchmark_clip_length']} with --benchmark)")
    g.add_argument("--clip-offset", type=int, metavar="N", help="frames between train clips "
                   f"(default L; {CONVERT['benchmark_clip_offset']} with --benchmark)")
    g.add_argument("--eval-clip-offset", type=int, metavar="N", help="the same for val/test")
    g.add_argument("--min-video-length", type=int, metavar="N",
                   help="tracks with fewer rows are skipped by the planner (default L)")
    g.add_argument("--label", default=CONVERT["label"], metavar="last|any:F",
                   help="clip label from the per-frame crossing labels")
    g.add_argument("--benchmark", action="store_true",
                   help="time-to-event windows, video-level labels")
    g.add_argument("--val-frac", type=float, default=CONVERT["val_frac"])
    g.add_argument("--test-frac", type=float, default=CONVERT["test_frac"])
    g.add_argument("--seed", type=int, default=CONVERT["seed"], help="split shuffle seed")
    g.add_argument("--balance", action="store_true", help="balance the train split's classes")


def _import_common(p) -> None:
    p.add_argument("out", metavar="OUT.h5", help="clip file to write (HDF5, bsp-convert schema)")
    p.add_argument("--labels", metavar="CSV",
                   help="crossing labels: CSV with columns video,track,frame,crossing "
                        "(every detected frame needs one); without it all labels are 0")
    p.add_argument("--threshold", type=float, default=0.3,
                   help="minimum confidence of a visible joint (default 0.3)")
    p.add_argument("--no-derive", action="store_true",
                   help="no mid-point derivations (COCO: hips and neck stay missing)")
    p.add_argument("--tracks", choices=("require", "best"), default="require",
                   help="detections without a track id: require one per image (default) or "
                        "keep the best-scoring detection of each image")
    p.add_argument("--skip-short-tracks", action="store_true",
                   help="leave out tracks shorter than a clip (default: an error)")
    p.add_argument("--force", action="store_true", help="replace an existing OUT.h5")
    p.add_argument("--quiet", action="store_true")
    _clip_options(p)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bsp-interop", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    imp = sub.add_parser("import", help="2D detections -> clip file").add_subparsers(
        dest="format", required=True)
    c = imp.add_parser("coco", help="COCO keypoint results or annotations JSON "
                                    "(MMPose, Detectron2)")
    c.add_argument("input", metavar="KEYPOINTS.json")
    c.add_argument("--images", metavar="IMAGES.json",
                   help="COCO-style JSON whose images give video, frame and size per image id "
                        "(needed for a results list)")
    c.add_argument("--image-size", type=_size, metavar="WxH",
                   help="image size where the images have none")
    c.add_argument("--joints", default="coco17", help="keypoint layout (default coco17)")
    _import_common(c)
    o = imp.add_parser("openpose", help="OpenPose --write_json folder (BODY_25)")
    o.add_argument("input", metavar="JSON_DIR")
    o.add_argument("--image-size", type=_size, metavar="WxH", required=True)
    _import_common(o)
    exp = sub.add_parser("export", help="clip file -> other formats").add_subparsers(
        dest="format", required=True)
    v = exp.add_parser("videopose3d", help="VideoPose3D .npz (positions_2d, positions_3d)")
    v.add_argument("input", metavar="CLIPS.h5")
    v.add_argument("out", metavar="OUT_2D.npz")
    v.add_argument("--out-3d", metavar="OUT_3D.npz", help="also the 3D joints (metres)")
    v.add_argument("--frame", choices=FRAMES_3D, default="camera",
                   help="3D frame: camera (OpenCV axes), world, absolute (walker)")
    v.add_argument("--joints", default="h36m17", help="joint set (default h36m17)")
    e = exp.add_parser("coco", help="COCO keypoint annotations (or --results) JSON")
    e.add_argument("input", metavar="CLIPS.h5")
    e.add_argument("out", metavar="OUT.json")
    e.add_argument("--results", action="store_true",
                   help="a results list (detector output) instead of annotations")
    e.add_argument("--images", metavar="IMAGES.json", help="with --results: the images JSON")
    e.add_argument("--joints", default="coco17", help="joint set (default coco17)")
    for q in (v, e):
        q.add_argument("--split", choices=SPLIT_CHOICES, default="all")
        q.add_argument("--no-derive", action="store_true", help="no mid-point derivations")
        q.add_argument("--force", action="store_true", help="replace existing outputs")
    j = sub.add_parser("joints", help="which CARLA joint each joint set fills (markdown)")
    j.add_argument("--no-derive", action="store_true")
    p.epilog = "joint sets: " + ", ".join(JOINT_SETS)
    return p


def _run(a) -> str:
    if a.command == "joints":
        return coverage_table(derive=not a.no_derive)
    if a.command == "export":
        common = dict(joints=a.joints, split=a.split, derive=not a.no_derive, force=a.force)
        if a.format == "videopose3d":
            r = export_videopose3d(a.input, a.out, a.out_3d, frame_3d=a.frame, **common)
            return f"wrote {a.out}" + (f" and {a.out_3d}" if a.out_3d else "") + \
                f": {r['clips']} clips, {r['joints']} ({len(r['present'])} joints present)"
        r = export_coco(a.input, a.out, kind="results" if a.results else "annotations",
                        images_out=a.images, **common)
        return f"wrote {a.out}: {r['images']} images, {r['records']} records, {r['joints']}"
    clips = dict(clip_length=a.clip_length, clip_offset=a.clip_offset,
                 eval_clip_offset=a.eval_clip_offset, min_video_length=a.min_video_length,
                 label=a.label, benchmark=a.benchmark, val_frac=a.val_frac,
                 test_frac=a.test_frac, seed=a.seed, balance=a.balance)
    clip_settings(**clips)  # options checked before any file is read
    common = dict(labels=a.labels, threshold=a.threshold, derive=not a.no_derive,
                  skip_short=a.skip_short_tracks, force=a.force, tracks=a.tracks, **clips)
    if a.format == "coco":
        r = import_coco(a.input, a.out, images=a.images, image_size=a.image_size,
                        joints=a.joints, **common)
    else:
        r = import_openpose(a.input, a.out, image_size=a.image_size, **common)
    lines = [f"wrote {r['output']}: {r['rows']} rows, {r['tracks']} tracks, clips "
             + ", ".join(f"{s} {n} {r['class_counts'][s]}" for s, n in r["clips"].items()),
             f"CARLA joints filled: {len(r['joints'])} of 26"]
    lines += [f"  skipped {s}" for s in r["skipped"]]
    lines += [f"WARNING: {w}" for w in r["warnings"]]
    return "\n".join(lines)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        text = _run(args)
    except FileExistsError as exc:
        print(f"bsp-interop: {exc}", file=sys.stderr)
        return 3
    except BadInput as exc:
        print(f"bsp-interop: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:
        print(f"bsp-interop: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"bsp-interop: {exc}", file=sys.stderr)
        return 1
    if not getattr(args, "quiet", False):
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
