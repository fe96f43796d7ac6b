"""``bsp-interop``: import other tools' 2D poses into clip files, export clip files to
other tools' formats, list the joint maps (docs/interop.md).

Exit codes: 0 done, 1 bad input file (the message names file, record and reason), 2 bad
option or an output that is one of the inputs (or two outputs that are one file; refused
with --force too), 3 the output exists (pass --force).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..command_line import ArgumentParser, run_command
from .._extras import require
from ..atomic import check_outputs
from ..defaults import CONVERT
from ..skeleton import JOINT_SETS, coverage_table
from . import export_coco, export_videopose3d, import_coco, import_openpose
from .clipfile import clip_settings
from .exporters import FRAMES_3D, SPLIT_CHOICES
from .benchmark_annotations import BENCHMARK
from .benchmark_annotations import stats_lines as benchmark_stats
from .jaad import SUBSETS as JAAD_SUBSETS
from .jaad import import_jaad
from .pie import import_pie
from .readers import BadInput, cli_wording

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
                   help="people without a track id: require a track id wherever a frame "
                        "holds several (default), or follow one person per video: the one "
                        "nearest where the followed pose was heading; a far jump, a sudden "
                        "change of size, or another person about as near (those frames are "
                        "not followed) starts a new track, listed as an identity switch "
                        "with its frame")
    p.add_argument("--skip-short-tracks", action="store_true",
                   help="leave out tracks shorter than a clip (default: an error)")
    p.add_argument("--force", action="store_true", help="replace an existing OUT.h5")
    p.add_argument("--quiet", action="store_true")
    _clip_options(p)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="bsp-interop", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    imp = sub.add_parser("import", help="2D detections -> clip file").add_subparsers(
        dest="format", required=True)
    c = imp.add_parser("coco", help="COCO keypoint results or annotations JSON "
                                    "(MMPose, Detectron2)")
    c.add_argument("input", metavar="KEYPOINTS.json")
    c.add_argument("--images", metavar="IMAGES.json",
                   help="input: a COCO-style JSON file whose images give video, frame and size "
                        "per image id (needed for a results list)")
    c.add_argument("--image-size", type=_size, metavar="WxH",
                   help="image size where the images have none")
    c.add_argument("--joints", default="coco17", help="keypoint layout (default coco17)")
    _import_common(c)
    o = imp.add_parser("openpose", help="OpenPose --write_json folder (BODY_25)")
    o.add_argument("input", metavar="JSON_DIR")
    o.add_argument("--image-size", type=_size, metavar="WxH", required=True)
    _import_common(o)
    _benchmark_parsers(imp)
    _export_parsers(sub)
    j = sub.add_parser("joints", help="which CARLA joint each joint set fills (markdown)")
    j.add_argument("--no-derive", action="store_true")
    p.epilog = "joint sets: " + ", ".join(JOINT_SETS)
    return p


def _export_parsers(sub) -> None:
    """``export videopose3d`` and ``export coco`` (bsp_fast.interop.exporters)."""
    exp = sub.add_parser("export", help="clip file -> other formats").add_subparsers(
        dest="format", required=True)
    v = exp.add_parser("videopose3d", help="VideoPose3D data_2d_custom_NAME.npz "
                       "(run.py -d custom -k NAME) and optionally the 3D joints")
    v.add_argument("input", metavar="CLIPS.h5")
    v.add_argument("out", metavar="OUT_2D.npz", help="e.g. data_2d_custom_NAME.npz")
    v.add_argument("--out-3d", metavar="OUT_3D.npz",
                   help="also the H36M-17 3D joints (metres), e.g. data_3d_custom_NAME.npz; "
                        "an error for a 2D-only (imported) file")
    v.add_argument("--frame", choices=FRAMES_3D,
                   help="3D frame: camera (OpenCV axes; the default), world, absolute "
                   "(walker), ground (z up, on the ground under the camera; with each "
                   "subject's camera)")
    v.add_argument("--viewer", action="store_true",
                   help="what VideoPose3D's render draws as it is: every subject starts at "
                   "its video's frame 0 (the first pose held before it; render with "
                   "--viz-video VIDEO --viz-skip START_FRAME --viz-limit END_FRAME) and the 3D "
                   "in the ground frame")
    v.add_argument("--joints", default="coco17",
                   help="2D joint set (default coco17, what VideoPose3D's in-the-wild models "
                        "take; h36m17)")
    e = exp.add_parser("coco", help="COCO keypoint annotations (or --results) JSON")
    e.add_argument("input", metavar="CLIPS.h5")
    e.add_argument("out", metavar="OUT.json")
    e.add_argument("--results", action="store_true",
                   help="a results list (detector output) instead of annotations")
    e.add_argument("--images", metavar="IMAGES.json",
                   help="output, with --results: also write the images JSON here (what "
                        "import coco --images reads back)")
    e.add_argument("--joints", default="coco17", help="joint set (default coco17)")
    e.add_argument("--write-images", metavar="DIR",
                   help="also write the frames as the JPEGs file_name names, below DIR "
                        "(from the clip file's media crops)")
    for q in (v, e):
        q.add_argument("--split", choices=SPLIT_CHOICES, default="all")
        q.add_argument("--no-derive", action="store_true", help="no mid-point derivations")
        q.add_argument("--force", action="store_true", help="replace existing outputs")
        q.add_argument("--quiet", action="store_true")


def _refuse_existing(a) -> None:
    """An existing output without --force: exit 3 before anything is read (a full dataset
    takes minutes to read)."""
    if a.force:
        return
    outs = [a.out] + [getattr(a, k, None) for k in ("out_3d", "write_images")]
    if a.command == "export" and a.format == "coco" and a.results:
        outs.append(a.images)
    for out in outs:
        if out is not None and Path(out).exists():
            raise FileExistsError(f"{out} exists; pass --force to replace it")


def _check_outputs(a) -> None:
    """The output rule (bsp_fast.atomic.check_outputs) for every sub-command, before any
    file is read: no output is an input, no two outputs are one file."""
    if a.command == "export":
        outputs = [("output", a.out)]
        if a.format == "videopose3d":
            outputs.append(("--out-3d", a.out_3d))
        else:
            if a.results:
                outputs.append(("--images", a.images))
            outputs.append(("--write-images", a.write_images))
        check_outputs(inputs=[("the input", a.input)], outputs=outputs)
        return
    if a.format in ("jaad", "pie"):  # annotations, split files, poses below the inputs
        check_outputs(inputs=[("the dataset folder", a.input), ("--poses", a.poses),
                              ("--split-dir", getattr(a, "split_dir", None))],
                      outputs=[("output", a.out)],
                      read_dirs=[("the dataset folder", a.input, ("*.xml", "*.txt")),
                                 ("the --openpose folder", a.openpose, ("*_keypoints.json",)),
                                 ("the --poses folder", a.poses, ("*.pkl",))])
        return
    inputs = [("the input", a.input), ("the --labels file", a.labels)]
    read_dirs = []
    if a.format == "coco":
        inputs.append(("the --images file", a.images))
    else:  # every *_keypoints.json below the folder is read
        read_dirs.append(("the OpenPose folder", a.input, ("*_keypoints.json",)))
    check_outputs(inputs=inputs, outputs=[("output", a.out)], read_dirs=read_dirs)


def _check_inputs(a) -> None:
    """Every input named on the line exists, and what a sub-command needs is installed,
    before anything is read or written."""
    named = [("the input", getattr(a, "input", None))]
    if a.command == "import":
        named += [(f"--{k.replace('_', '-')}", getattr(a, k, None))
                  for k in ("images", "labels", "poses", "openpose", "split_dir")]
    for what, path in named:
        if path is not None and not Path(path).exists():
            raise BadInput(f"{path}: no such file or folder ({what})")
    if a.command == "export" and not Path(a.input).is_file():
        raise BadInput(f"{a.input}: not a clip file (bsp-convert or bsp-interop import "
                       "writes one)")
    if a.command == "export" and a.format == "coco" and a.write_images:
        require("cv2", "bsp-interop export coco --write-images")


def _run(a) -> str:
    if a.command == "joints":
        return coverage_table(derive=not a.no_derive)
    _check_inputs(a)
    _check_outputs(a)
    _refuse_existing(a)
    if a.command == "export":
        common = dict(joints=a.joints, split=a.split, derive=not a.no_derive, force=a.force)
        if a.format == "videopose3d":
            r = export_videopose3d(a.input, a.out, a.out_3d, frame_3d=a.frame,
                                   viewer=a.viewer, **common)
            lines = [f"wrote {a.out}" + (f" and {a.out_3d}" if a.out_3d else "")
                     + ": subjects (one per video/track run) "
                     + ", ".join(f"{s} {n}" for s, n in r["subjects"].items())
                     + f"; 2D layout {r['layout_name']!r}, {len(r['present'])} of "
                     f"{r['num_joints']} joints from CARLA joints", f"joints approximated: {r['filled_joints'] or 'none'}; "
                     f"joint positions interpolated over time: {r['interpolated']}"]
            lines += [f"  left out {d}" for d in r["dropped"]]
            return "\n".join(lines)
        r = export_coco(a.input, a.out, kind="results" if a.results else "annotations",
                        images_out=a.images, images_dir=a.write_images, **common)
        return (f"wrote {a.out}: {r['images']} images, {r['records']} records, {r['joints']}"
                + (f"; {r['images_written']} JPEGs below {a.write_images}"
                   if a.write_images else ""))
    if a.format in ("jaad", "pie"):
        return _run_benchmark(a)
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
    lines = [f"wrote {r['output']}: {r['rows']} rows, {r['tracks']} tracks; clips: "
             + ", ".join(_split_counts(s, n, r["class_counts"][s])
                         for s, n in r["clips"].items()),
             f"CARLA joints filled: {len(r['joints'])} of 26"]
    if r["settings"]["labels"] == "records":
        lines.append("labels: the records' own crossing values (as export coco writes them)")
    if r["settings"]["split_rule"] == "source":
        lines.append("split: kept from the images' split (as export coco writes it)")
    elif (r.get("frames") or {}).get("split_note"):
        lines.append(f"split: {r['frames']['split_note']}")
    lines += [f"  skipped {s}" for s in r["skipped"]]
    lines += _frame_lines(r.get("frames") or {})
    lines += [f"WARNING: {w}" for w in r["warnings"]]
    return "\n".join(lines)


def _benchmark_parsers(imp) -> None:
    """``import jaad`` and ``import pie``: official annotations + 2D poses, cut into the
    PedestrianActionBenchmark's windows (bsp_fast.interop.jaad / .pie)."""
    for name, what in (("jaad", "JAAD folder (annotations/, annotations_attributes/, "
                                "split_ids/)"),
                       ("pie", "PIE folder (annotations/SET/, annotations_attributes/SET/)")):
        q = imp.add_parser(name, help=f"{name.upper()} annotations + OpenPose JSON or the "
                           "benchmark's pose pickles (time-to-event windows)")
        q.add_argument("input", metavar="ROOT", help=what)
        q.add_argument("out", metavar="OUT.h5", help="clip file to write")
        src = q.add_mutually_exclusive_group(required=True)
        src.add_argument("--openpose", metavar="DIR", help="OpenPose --write_json output "
                         "(every person; each track takes the one fitting its box)")
        src.add_argument("--poses", metavar="PKL", help="the benchmark's pose_SET.pkl (a "
                         "file or a folder of them; read with a restricted unpickler)")
        if name == "jaad":
            q.add_argument("--subset", choices=JAAD_SUBSETS, default="beh",
                           help="beh: pedestrians with behaviour labels (default); all")
            q.add_argument("--split-dir", metavar="DIR", help="folder with train/val/test.txt "
                           "(default ROOT/split_ids/default; without one: a seeded split)")
            q.add_argument("--seed", type=int, help="seeded split (no split files)")
            q.add_argument("--val-frac", type=float)
            q.add_argument("--test-frac", type=float)
        q.add_argument("--obs-length", type=int, default=BENCHMARK["obs_length"])
        q.add_argument("--tte", type=int, nargs=2, metavar=("MIN", "MAX"),
                       default=list(BENCHMARK["tte"]), help="frames from a window's last "
                       "frame to the event (default 30 60)")
        q.add_argument("--overlap", type=float, default=BENCHMARK["overlap"][name],
                       help=f"window overlap (default {BENCHMARK['overlap'][name]})")
        q.add_argument("--cut-gaps", action="store_true",
                       help="leave out the windows that span a gap in a track's frame "
                       "numbers (default: windows by position, as the benchmark cuts them)")
        q.add_argument("--drop-first-frame", action="store_true",
                       help="store the last obs-1 frames of each window, what the "
                       "benchmark's models see (its normalize_boxes: True), and the "
                       "dropped frame's box as targets/box_reference")
        q.add_argument("--threshold", type=float, default=0.3)
        q.add_argument("--no-derive", action="store_true")
        q.add_argument("--stats", action="store_true",
                       help="print the share of missing joints over the imported windows")
        q.add_argument("--force", action="store_true")
        q.add_argument("--quiet", action="store_true")


def _run_benchmark(a) -> str:
    common = dict(openpose=a.openpose, poses=a.poses, threshold=a.threshold,
                  derive=not a.no_derive, obs_length=a.obs_length, tte=tuple(a.tte),
                  overlap=a.overlap, cut_gaps=a.cut_gaps, drop_first=a.drop_first_frame,
                  force=a.force)
    if a.format == "jaad":
        r = import_jaad(a.input, a.out, subset=a.subset, split_dir=a.split_dir, seed=a.seed,
                        val_frac=a.val_frac, test_frac=a.test_frac, **common)
    else:
        r = import_pie(a.input, a.out, **common)
    s = r["settings"]
    lines = [f"wrote {r['output']}: {r['rows']} pose frames, {r['tracks']} pedestrians; "
             "windows: " + ", ".join(_split_counts(k, n, r["class_counts"][k])
                                     for k, n in r["clips"].items()),
             f"split: {r['split_note']}; windows of {s['obs_length']} frames"
             + (" (the first dropped: the models' 15)" if s["first_frame_dropped"] else "")
             + f", every {s['stride']} frames (overlap {s['overlap']}); time to event "
             f"{r['tte_range'][0]}-{r['tte_range'][1]} positions (meta/tte), "
             f"{r['frames_to_event_range'][0]}-{r['frames_to_event_range'][1]} frame numbers "
             f"(meta/frames_to_event); {r['short_tracks']} pedestrians too short left out",
             f"windows across a gap in the frame numbers: {r['windows_across_gaps']}"
             + (" (left out: --cut-gaps)" if a.cut_gaps else "")
             + (f" ({', '.join(r['pedestrians_with_gaps'])})" if r["pedestrians_with_gaps"]
                else "")]
    if r["all_zero_poses"]:
        lines.append(f"poses with every value 0: {r['all_zero_poses']} (read as poses "
                     "without any joint: every joint missing)")
    lines += [f"WARNING: {w}" for w in r["warnings"]]
    if a.stats:
        lines += benchmark_stats(r)
    return "\n".join(lines)


def _frame_lines(notes: dict) -> list:
    """The reader's notes on tracks and frames (readers.track_notes) as summary lines."""
    if not notes:
        return []
    word = notes.get("frame_word", "frame")
    empty, gaps = notes["empty_frames"], notes["dropped_frames"]
    lines = [f"identity switches: {len(notes['identity_switches'])}; {word}s without a "
             f"person: {sum(empty.values())}; missing {word} numbers: "
             f"{sum(len(v) for v in gaps.values())}; other people not followed: "
             f"{notes['dropped_detections']}"]
    lines += [f"  identity switch: {s}" for s in notes["identity_switches"]]
    lines += [f"  video {v!r}: {n} {word}(s) without a person" for v, n in empty.items()]
    lines += [f"  video {v!r}: {word}s missing: " + _ranges(f) for v, f in gaps.items()]
    return lines


def _ranges(numbers) -> str:
    out, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ", ".join(out)


def _split_counts(split: str, clips: int, counts) -> str:
    """``train 32 clips (not-crossing 30, crossing 2)``."""
    return f"{split} {clips} clips (not-crossing {counts[0]}, crossing {counts[1]})"


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run_command("bsp-interop", _main, args)


def _main(args) -> int:
    with cli_wording():
        text = _run(args)
    if not getattr(args, "quiet", False):
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
